"""Burst grouping of headerless raw-distance messages into fixes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from omnical.errors import ConfigError
from omnical.ips.beacons import BeaconMap, default_beacon_map
from omnical.ips.bursts import burst_starts, group_bursts

MS = 1_000_000


def reference_starts(
    t_ns: NDArray[np.int64], hedge: NDArray[np.int64], beacon: NDArray[np.int64], gap_ns: int
) -> NDArray[np.bool_]:
    """Obviously-correct sequential oracle of the burst rule."""
    starts = np.zeros(t_ns.size, dtype=bool)
    seen: set[int] = set()
    for i in range(t_ns.size):
        new = (
            i == 0
            or t_ns[i] - t_ns[i - 1] > gap_ns
            or hedge[i] != hedge[i - 1]
            or int(beacon[i]) in seen
        )
        if new:
            starts[i] = True
            seen = set()
        seen.add(int(beacon[i]))
    return starts


def test_gaps_split_measurements() -> None:
    # Three measurements of beacons 3..6, messages 3 ms apart, measurements 40 ms apart.
    t_ns = np.concatenate([start + np.arange(4) * 3 * MS for start in (0, 40 * MS, 80 * MS)])
    beacon = np.tile([3, 4, 5, 6], 3)
    distance = np.arange(12, dtype=float)
    bursts = group_bursts(t_ns, np.full(12, 10), beacon, distance, default_beacon_map())
    assert len(bursts) == 3
    assert bursts.t_ns.tolist() == [0, 40 * MS, 80 * MS]
    np.testing.assert_array_equal(bursts.distances_m, distance.reshape(3, 4))
    assert bursts.n_messages.tolist() == [4, 4, 4]
    assert bursts.n_valid.tolist() == [4, 4, 4]
    assert bursts.fix_of_message.tolist() == [0] * 4 + [1] * 4 + [2] * 4


def test_repeated_beacon_splits_a_gapless_stream() -> None:
    t_ns = np.arange(5) * 2 * MS
    beacon = np.array([5, 3, 4, 5, 3])
    bursts = group_bursts(
        t_ns, np.full(5, 10), beacon, [1.0, 2.0, 3.0, 4.0, 5.0], default_beacon_map()
    )
    assert bursts.t_ns.tolist() == [0, 6 * MS]
    np.testing.assert_array_equal(bursts.distances_m[0], [2.0, 3.0, 1.0, np.nan])
    np.testing.assert_array_equal(bursts.distances_m[1], [5.0, np.nan, 4.0, np.nan])


def test_hedge_change_splits() -> None:
    starts = burst_starts([0, 1, 2, 3], [10, 10, 11, 11], [3, 4, 3, 4])
    assert starts.tolist() == [True, False, True, False]


def test_unknown_and_invalid_distances_are_counted_not_used() -> None:
    t_ns = np.array([0, 1, 2, 3, 4]) * MS
    beacon = np.array([3, 99, 4, 5, 6])
    distance = np.array([1.0, 2.0, np.nan, -0.5, 4.0])
    bursts = group_bursts(t_ns, np.full(5, 10), beacon, distance, default_beacon_map())
    assert len(bursts) == 1
    assert bursts.n_unknown.tolist() == [1]
    assert bursts.n_invalid.tolist() == [2]
    np.testing.assert_array_equal(bursts.distances_m[0], [1.0, np.nan, np.nan, 4.0])


def test_any_number_of_beacons() -> None:
    addresses = np.arange(100, 130)
    beacons = BeaconMap(addresses, np.zeros((30, 3)) + np.arange(30)[:, None])
    rng = np.random.default_rng(7)
    order = np.concatenate([rng.permutation(addresses) for _ in range(3)])
    t_ns = np.arange(order.size) * MS + np.repeat([0, 100, 200], 30) * MS
    bursts = group_bursts(
        t_ns, np.zeros(order.size, dtype=int), order, order.astype(float), beacons
    )
    assert len(bursts) == 3
    np.testing.assert_array_equal(bursts.distances_m, np.tile(addresses.astype(float), (3, 1)))


def test_empty_input_gives_no_fixes() -> None:
    bursts = group_bursts([], [], [], [], default_beacon_map())
    assert len(bursts) == 0
    assert bursts.distances_m.shape == (0, 4)


def test_bad_arrays_raise() -> None:
    with pytest.raises(ConfigError, match="non-decreasing, message 2"):
        burst_starts([0, 5, 3], [1, 1, 1], [3, 4, 5])
    with pytest.raises(ConfigError, match="differ in length"):
        burst_starts([0, 5], [1], [3, 4])
    with pytest.raises(ConfigError, match="3 times but 2 distances"):
        group_bursts([0, 1, 2], [1, 1, 1], [3, 4, 5], [1.0, 2.0], default_beacon_map())


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(0, 30), st.integers(0, 1), st.integers(0, 5)),
        min_size=0,
        max_size=80,
    ),
    st.integers(0, 20),
)
def test_vectorised_grouping_matches_sequential_oracle(
    messages: list[tuple[int, int, int]], gap_ms: int
) -> None:
    gaps = np.array([m[0] for m in messages], dtype=np.int64) * MS
    t_ns = np.cumsum(gaps)
    hedge = np.array([m[1] for m in messages], dtype=np.int64)
    beacon = np.array([m[2] for m in messages], dtype=np.int64)
    got = burst_starts(t_ns, hedge, beacon, max_gap_ns=gap_ms * MS)
    np.testing.assert_array_equal(got, reference_starts(t_ns, hedge, beacon, gap_ms * MS))


def test_long_gapless_stream_matches_oracle() -> None:
    rng = np.random.default_rng(3)
    beacon = rng.integers(0, 4, 20_000)
    t_ns = np.arange(beacon.size, dtype=np.int64) * MS
    hedge = np.zeros(beacon.size, dtype=np.int64)
    got = burst_starts(t_ns, hedge, beacon, max_gap_ns=10 * MS)
    np.testing.assert_array_equal(got, reference_starts(t_ns, hedge, beacon, 10 * MS))
