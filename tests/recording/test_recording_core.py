"""Table, Recording and RecordingBuilder."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omnical.errors import RecordingError
from omnical.recording.recording import Recording, RecordingBuilder, Table


def _cmd(builder: RecordingBuilder, t_ns: int, vx: float) -> None:
    builder.add("/cmd_vel", t_ns, vx_mps=vx, vy_mps=0.0, wz_radps=0.5)


def test_table_is_read_only_and_names_missing_columns() -> None:
    table = Table(np.array([1, 2, 3]), {"a": np.array([1.0, 2.0, 3.0])})
    assert len(table) == 3
    assert table.t_ns.dtype == np.int64
    with pytest.raises(ValueError, match="read-only"):
        table["a"][0] = 9.0
    with pytest.raises(RecordingError, match="no column 'b'"):
        table["b"]


def test_table_rejects_bad_shapes_and_float_times() -> None:
    with pytest.raises(RecordingError, match="integer"):
        Table(np.array([0.5, 1.0]), {})
    with pytest.raises(RecordingError, match="column 'a'"):
        Table(np.array([1, 2]), {"a": np.zeros(3)})


def test_t_s_keeps_nanosecond_precision_far_from_epoch() -> None:
    t0 = 1_700_000_000_000_000_000
    table = Table(np.array([t0, t0 + 1, t0 + 1_500_000_000]), {})
    np.testing.assert_array_equal(table.t_s(), [0.0, 1e-9, 1.5])
    np.testing.assert_array_equal(table.t_s(t0 - 10**9), [1.0, 1.0 + 1e-9, 2.5])


def test_between_and_take_select_rows() -> None:
    table = Table(np.arange(10) * 10, {"v": np.arange(10.0)})
    window = table.between(20, 50)
    np.testing.assert_array_equal(window.t_ns, [20, 30, 40])
    np.testing.assert_array_equal(table.take(table["v"] > 7)["v"], [8.0, 9.0])


def test_builder_sorts_rows_by_time_stably_and_casts_dtypes() -> None:
    builder = RecordingBuilder()
    _cmd(builder, 30, 3.0)
    _cmd(builder, 10, 1.0)
    _cmd(builder, 30, 4.0)
    builder.add_many(
        "/cmd_vel", np.array([20, 30]), vx_mps=[2.0, 5.0], vy_mps=[0.0, 0.0], wz_radps=[0.5, 0.5]
    )
    builder.add("/hedge_quality", 5, address=7.0, quality_percent=95)
    rec = builder.build()
    cmd = rec.topic("/cmd_vel")
    np.testing.assert_array_equal(cmd.t_ns, [10, 20, 30, 30, 30])
    np.testing.assert_array_equal(cmd["vx_mps"], [1.0, 2.0, 3.0, 4.0, 5.0])
    quality = rec.topic("/hedge_quality")
    assert quality["address"].dtype == np.uint8
    assert int(quality["address"][0]) == 7
    assert len(builder) == 6


def test_builder_names_wrong_columns_and_lossy_values() -> None:
    builder = RecordingBuilder()
    with pytest.raises(RecordingError, match=r"/cmd_vel: columns missing \['wz_radps'\]"):
        builder.add("/cmd_vel", 1, vx_mps=0.0, vy_mps=0.0)
    with pytest.raises(RecordingError, match=r"unexpected \['vz_mps'\]"):
        builder.add_many("/cmd_vel", [1], vx_mps=[0], vy_mps=[0], wz_radps=[0], vz_mps=[0])
    builder.add("/hedge_quality", 1, address=300, quality_percent=1)
    with pytest.raises(RecordingError, match="out of range for uint8"):
        builder.build()
    other = RecordingBuilder()
    other.add("/hedge_quality", 1, address=1.5, quality_percent=1)
    with pytest.raises(RecordingError, match="must hold integers"):
        other.build()
    floats = RecordingBuilder()
    floats.add("/cmd_vel", 1.5, vx_mps=0.0, vy_mps=0.0, wz_radps=0.0)  # type: ignore[arg-type]
    with pytest.raises(RecordingError, match="integer nanoseconds"):
        floats.build()


def test_builder_accepts_other_topics_with_first_row_columns() -> None:
    builder = RecordingBuilder()
    builder.add("/wheels", 1, w1_radps=1.0, w2_radps=2.0)
    builder.add("/wheels", 2, w2_radps=3.0, w1_radps=4.0)
    table = builder.build().topic("/wheels")
    np.testing.assert_array_equal(table["w1_radps"], [1.0, 4.0])
    with pytest.raises(RecordingError, match="missing"):
        builder.add("/wheels", 3, w1_radps=1.0)


def test_recording_topic_names_missing_topic_and_bounds() -> None:
    builder = RecordingBuilder()
    _cmd(builder, 2_000_000_000, 0.1)
    builder.add("/hedge_quality", 500_000_000, address=1, quality_percent=90)
    rec = builder.build()
    with pytest.raises(RecordingError, match="no topic /odom"):
        rec.topic("/odom")
    assert rec.has("/cmd_vel")
    assert not rec.has("/odom")
    assert rec.start_ns == 500_000_000
    assert rec.end_ns == 2_000_000_000
    assert rec.duration_s == pytest.approx(1.5)
    with pytest.raises(RecordingError, match="empty"):
        Recording({}).duration_s  # noqa: B018


def test_without_and_merged() -> None:
    a, b = RecordingBuilder(), RecordingBuilder()
    _cmd(a, 10, 1.0)
    _cmd(a, 30, 3.0)
    _cmd(b, 20, 2.0)
    b.add("/hedge_quality", 5, address=1, quality_percent=90)
    merged = a.build().merged(b.build())
    np.testing.assert_array_equal(merged.topic("/cmd_vel")["vx_mps"], [1.0, 2.0, 3.0])
    assert merged.without("/cmd_vel").topics == ("/hedge_quality",)
    other = Recording({"/cmd_vel": Table(np.array([1]), {"x": np.array([1.0])})})
    with pytest.raises(RecordingError, match="cannot merge topic /cmd_vel"):
        merged.merged(other)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.integers(0, 10**12), min_size=1, max_size=60))
def test_build_sorts_any_order(times: list[int]) -> None:
    builder = RecordingBuilder()
    for i, t in enumerate(times):
        _cmd(builder, t, float(i))
    table = builder.build().topic("/cmd_vel")
    assert np.all(np.diff(table.t_ns) >= 0)
    assert sorted(table["vx_mps"].tolist()) == [float(i) for i in range(len(times))]
    # stability: equal times keep insertion order
    order = sorted(range(len(times)), key=lambda i: times[i])
    np.testing.assert_array_equal(table["vx_mps"], np.array(order, dtype=float))
