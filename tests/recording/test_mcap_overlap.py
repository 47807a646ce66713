"""Overlapping MCAP chunks, as a live recording writes them (late topics in with every topic's
tail): no channel is "out of time order" unless its own messages go back in time."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from recording_samples import T0_NS, column_values

from omnical.bags.bag import BagStream, read_bag
from omnical.bags.mcapindex import channel_messages, read_summary
from omnical.bags.sink import BagSink
from omnical.recording.recording import Table
from omnical.recording.topics import CMD_VEL, GROUND_TRUTH, ODOM, spec_of

_STEP_NS = 10_000_000


def _table(topic: str, t_ns: np.ndarray, seed: int) -> Table:
    spec = spec_of(topic)
    assert spec is not None
    times = np.asarray(t_ns, dtype=np.int64)
    return Table(times, column_values(spec, times.size, np.random.default_rng(seed)))


def _live_bag(location: Path, odom_ns: list[np.ndarray], late: dict[str, np.ndarray]) -> Path:
    """What a live run writes through :class:`BagSink`: /odom a flushed chunk at a time, then
    ``late`` topics (``/cmd_vel``, events: written at the end, stamped from early in the run) in
    the last chunk with /odom's last part."""
    sink = BagSink(location, 2)
    sink.open()
    for k, t_ns in enumerate(odom_ns[:-1]):
        sink.write_table(ODOM, _table(ODOM, t_ns, k))
        sink.flush()
    sink.write_table(ODOM, _table(ODOM, odom_ns[-1], 99))
    for topic, t_ns in late.items():
        sink.write_table(topic, _table(topic, t_ns, 100))
    sink.close()
    return location


def _real_case(tmp_path: Path) -> tuple[Path, np.ndarray, np.ndarray]:
    odom = T0_NS + np.arange(500, dtype=np.int64) * _STEP_NS  # 5 s
    cmd = T0_NS + 2_880_000_000 + np.arange(100, dtype=np.int64) * 2 * _STEP_NS
    bag = _live_bag(tmp_path / "live", np.split(odom, 5), {CMD_VEL: cmd})
    return bag, odom, cmd


def test_the_live_layout_has_overlapping_chunks(tmp_path: Path) -> None:
    """The reproduction holds: the last chunk (by offset) starts before the one before it."""
    bag, _, _ = _real_case(tmp_path)
    summary = read_summary(next(bag.glob("*.mcap")))
    assert summary is not None
    by_offset = sorted(summary.chunks, key=lambda c: c.offset)
    assert by_offset[-1].start_ns < by_offset[-2].start_ns < by_offset[-1].end_ns


def test_overlapping_chunks_give_each_channel_in_time_order(tmp_path: Path) -> None:
    bag, odom, cmd = _real_case(tmp_path)
    summary = read_summary(next(bag.glob("*.mcap")))
    assert summary is not None
    ids = {ch.topic: cid for cid, ch in summary.channels.items()}
    got: dict[int, list[np.ndarray]] = {}
    for cid, t_ns, _ in channel_messages(summary, ids.values()):
        got.setdefault(cid, []).append(t_ns.astype(np.int64))
    assert np.array_equal(np.concatenate(got[ids[ODOM]]), odom)
    assert np.array_equal(np.concatenate(got[ids[CMD_VEL]]), cmd)

    recording = read_bag(bag)
    assert recording.notes == ()
    assert np.array_equal(recording.topic(ODOM).t_ns, odom)
    assert np.array_equal(recording.topic(CMD_VEL).t_ns, cmd)
    expected = _table(ODOM, odom[400:], 99)
    assert np.array_equal(recording.topic(ODOM)["x_m"][400:], expected["x_m"])

    stream = BagStream(bag, batch=64)
    parts = [p for p in stream.parts() if p.topic == ODOM]
    assert stream.whole == [] and stream.notes == ()
    assert np.array_equal(np.concatenate([p.table.t_ns for p in parts]), odom)


def test_a_channel_going_back_across_overlapping_chunks_is_still_noted(tmp_path: Path) -> None:
    """/odom's second chunk starts half-way into its first: one step back, noted and sorted;
    /cmd_vel in the overlapping last chunk stays unremarked."""
    first = T0_NS + np.arange(100, dtype=np.int64) * _STEP_NS
    second = first + 50 * _STEP_NS + _STEP_NS // 2
    cmd = T0_NS + 20 * _STEP_NS + np.arange(10, dtype=np.int64) * _STEP_NS
    bag = _live_bag(tmp_path / "back", [first, second], {CMD_VEL: cmd})
    recording = read_bag(bag)
    assert recording.notes == (f"{ODOM}: 1 message(s) out of time order, sorted",)
    t_ns = recording.topic(ODOM).t_ns
    assert np.array_equal(t_ns, np.sort(np.concatenate([first, second])))
    stream = BagStream(bag, batch=64)
    list(stream.parts())
    assert stream.whole == [ODOM]
    assert stream.notes == recording.notes


def test_chunks_without_overlap_come_as_read(tmp_path: Path) -> None:
    """No overlap: every part at once, in chunk start order (as before the overlap fix)."""
    odom = T0_NS + np.arange(300, dtype=np.int64) * _STEP_NS
    cmd = odom[250:] + _STEP_NS // 2
    bag = _live_bag(tmp_path / "plain", np.split(odom, 3), {CMD_VEL: cmd})
    summary = read_summary(next(bag.glob("*.mcap")))
    assert summary is not None
    ids = {ch.topic: cid for cid, ch in summary.channels.items()}
    order = [(cid, int(t[0])) for cid, t, _ in channel_messages(summary, ids.values())]
    expected = [(ids[ODOM], int(odom[0])), (ids[ODOM], int(odom[100]))]
    expected += [(ids[ODOM], int(odom[200])), (ids[CMD_VEL], int(cmd[0]))]
    assert order == expected
    assert read_bag(bag).notes == ()


def test_equal_stamps_at_a_chunk_boundary_come_in_write_order(tmp_path: Path) -> None:
    """Review: /cmd_vel 36 in one chunk and 36, 41 in a later one that sorts first (it also
    holds an early /ground_truth): the later chunk's part came first, 36 41 36, a false note.
    Ties go in write order."""
    t = [T0_NS + k * _STEP_NS for k in (13, 18, 36, 41)]
    sink = BagSink(tmp_path / "ties", 2)
    sink.open()
    sink.write_table(ODOM, _table(ODOM, np.array(t[:2]), 0))
    sink.flush()
    sink.write_table(CMD_VEL, _table(CMD_VEL, np.array(t[2:3]), 1))
    sink.flush()
    sink.write_table(GROUND_TRUTH, _table(GROUND_TRUTH, np.array(t[:1]), 2))
    sink.write_table(CMD_VEL, _table(CMD_VEL, np.array(t[2:]), 3))
    sink.close()
    bag = tmp_path / "ties"
    summary = read_summary(next(bag.glob("*.mcap")))
    assert summary is not None
    by_offset = sorted(summary.chunks, key=lambda c: c.offset)
    assert len(by_offset) == 3 and by_offset[2].start_ns < by_offset[1].start_ns  # the layout
    ids = {ch.topic: cid for cid, ch in summary.channels.items()}
    cmd = [int(x) for cid, ts, _ in channel_messages(summary, ids.values()) for x in ts
           if cid == ids[CMD_VEL]]  # fmt: skip
    assert cmd == [t[2], t[2], t[3]]
    recording = read_bag(bag)
    assert recording.notes == ()
    assert np.array_equal(recording.topic(CMD_VEL).t_ns, [t[2], t[2], t[3]])
    first = _table(CMD_VEL, np.array(t[2:3]), 1)["vx_mps"][0]  # the first-written 36 first
    assert recording.topic(CMD_VEL)["vx_mps"][0] == first
