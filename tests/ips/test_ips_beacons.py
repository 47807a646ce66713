"""Beacon map: seed 000 Table 3, lookups, YAML round trip and validation, /beacons_pos_a rows."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omnical.errors import ConfigError
from omnical.ips.beacons import (
    BeaconMap,
    beacon_map_from_rows,
    default_beacon_map,
    load_beacon_map,
    save_beacon_map,
)


def test_default_map_is_seed_000_table_3() -> None:
    beacons = default_beacon_map()
    assert beacons.addresses.tolist() == [3, 4, 5, 6]
    np.testing.assert_array_equal(
        beacons.positions_m,
        [[0.0, 0.0, 0.4], [5.767, 0.0, 0.4], [0.485, 4.809, 0.4], [5.445, 4.813, 0.4]],
    )
    assert beacons.hedge_height_m(10) == 0.4
    assert beacons.hedge_height_m(11) is None
    assert len(beacons) == 4


def test_lookup_by_address() -> None:
    beacons = default_beacon_map()
    assert beacons.index_of([6, 3, 99, 4]).tolist() == [3, 0, -1, 1]


def test_arrays_are_read_only() -> None:
    beacons = default_beacon_map()
    with pytest.raises(ValueError, match="read-only"):
        beacons.positions_m[0, 0] = 1.0


@pytest.mark.parametrize(
    ("addresses", "positions", "message"),
    [
        ([1, 2], [[0, 0, 0]], r"shape \(2, 3\)"),
        ([1, 1], [[0, 0, 0], [1, 0, 0]], r"unique, repeated: \[1\]"),
        ([1, 2], [[0, 0, 0], [np.nan, 0, 0]], r"beacons \[2\] are not finite"),
    ],
)
def test_invalid_maps_raise(
    addresses: list[int], positions: list[list[float]], message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        BeaconMap(np.array(addresses), np.array(positions, dtype=float))


maps = st.integers(min_value=1, max_value=12).flatmap(
    lambda n: st.tuples(
        st.lists(st.integers(1, 255), min_size=n, max_size=n, unique=True),
        st.lists(
            st.tuples(*[st.floats(-100, 100, allow_nan=False) for _ in range(3)]),
            min_size=n,
            max_size=n,
        ),
        st.dictionaries(st.integers(1, 255), st.floats(-5, 5, allow_nan=False), max_size=3),
    )
)


@settings(max_examples=40, deadline=None)
@given(maps)
def test_yaml_round_trip(
    tmp_path_factory: pytest.TempPathFactory,
    spec: tuple[list[int], list[tuple[float, float, float]], dict[int, float]],
) -> None:
    addresses, positions, hedges = spec
    beacons = BeaconMap(
        np.array(addresses),
        np.array(positions),
        np.array(list(hedges), dtype=np.int64),
        np.array(list(hedges.values()), dtype=float),
    )
    path = tmp_path_factory.mktemp("map") / "beacons.yaml"
    save_beacon_map(beacons, path)
    assert load_beacon_map(path) == beacons


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("beacons:\n  - {address: 3}\n", r"beacons\[0\]\.position_m: Field required"),
        (
            "beacons:\n  - {address: 3, position_m: [0, 0]}\n",
            r"beacons\[0\]\.position_m: Value error, expected 3 numbers",
        ),
        ("beacons:\n  - {address: x, position_m: [0, 0, 0]}\n", r"beacons\[0\]\.address"),
        ("beacons: []\n", r"beacons: List should have at least 1 item"),
        ("beacon: []\n", r"beacons: Field required"),
        (
            (
                "beacons:\n  - {address: 3, position_m: [0, 0, 0]}\n"
                "  - {address: 3, position_m: [1, 0, 0]}\n"
            ),
            r"addresses must be unique",
        ),
        (
            "beacons:\n  - {address: 3, position_m: [0, 0, 0]}\nhedges:\n  - {address: 10}\n",
            r"hedges\[0\]\.z_m: Field required",
        ),
        ("beacons: [\n", r"invalid YAML at line 2"),
        # A Marvelmind address is one byte, 0 the empty slot; a hedgehog's height as --hedge-z.
        (
            "beacons:\n  - {address: 100000, position_m: [0, 0, 0]}\n",
            r"beacons\[0\]\.address: a Marvelmind address is 1 to 255 .*got 100000$",
        ),
        (
            "beacons:\n  - {address: 0, position_m: [0, 0, 0]}\n",
            r"beacons\[0\]\.address: .* 1 to 255",
        ),
        (
            "beacons:\n  - {address: 3, position_m: [0, 0, 0]}\nhedges:\n  - {address: 256, z_m: 0.4}\n",
            r"hedges\[0\]\.address: a Marvelmind address is 1 to 255",
        ),
        (
            "beacons:\n  - {address: 3, position_m: [0, 0, 0]}\nhedges:\n  - {address: 10, z_m: 1e12}\n",
            r"hedges\[0\]\.z_m: the hedgehog's height must lie within ±100 m \(as --hedge-z\), got 1e\+12$",
        ),
    ],
)
def test_yaml_errors_name_file_field_and_reason(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad_map.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=message) as caught:
        load_beacon_map(path)
    assert str(caught.value).startswith(str(path))


def test_missing_yaml_file_raises(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nowhere\.yaml: cannot read"):
        load_beacon_map(tmp_path / "nowhere.yaml")


def test_rows_keep_the_latest_position_per_address() -> None:
    address = np.array([4, 3, 4, 5, 3])
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    beacons = beacon_map_from_rows(address, x, x + 10, x + 20, hedges=default_beacon_map())
    assert beacons.addresses.tolist() == [3, 4, 5]
    np.testing.assert_array_equal(beacons.positions_m[:, 0], [5.0, 3.0, 4.0])
    np.testing.assert_array_equal(beacons.positions_m[:, 2], [25.0, 23.0, 24.0])
    assert beacons.hedge_height_m(10) == 0.4


def test_rows_with_times_use_the_newest_time() -> None:
    address = np.array([3, 3, 3])
    x = np.array([1.0, 2.0, 3.0])
    t_ns = np.array([30, 10, 20])
    beacons = beacon_map_from_rows(address, x, x, x, t_ns=t_ns)
    assert beacons.positions_m[0, 0] == 1.0


def test_rows_of_different_length_raise() -> None:
    with pytest.raises(ConfigError, match="differ in length"):
        beacon_map_from_rows([1, 2], [0.0], [0.0, 1.0], [0.0, 1.0])
