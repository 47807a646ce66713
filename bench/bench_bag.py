"""Bag benchmark: write and read ~250,000 mixed messages (about 10 minutes of a robot run).

Figures, all measured in this process on the same recording:

* omnical ``write_bag`` / ``read_bag`` (bulk numpy CDR codec), ROS 2 MCAP and ROS 1, in
  messages per second;
* the baseline: rosbags' per-message path into the same MCAP writer, i.e. ``serialize_cdr``
  of each message object (objects prebuilt, not timed, which favours the baseline) for
  writing, and ``AnyReader.deserialize`` of each message for reading;
* the ratios omnical / baseline.

Run: ``.venv/bin/python bench/bench_bag.py``.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer

from omnical.recording import TOPICS, Recording, RecordingBuilder, read_bag, write_bag
from omnical.recording.messages import encode_table
from omnical.recording.typestores import typestore

RATES_HZ = {
    "/cmd_vel": 50.0,
    "/odom": 50.0,
    "/ground_truth": 50.0,
    "/imu": 200.0,
    "/hedge_pos_ang": 16.0,
    "/beacon_raw_distance": 64.0,
    "/hedge_quality": 16.0,
}
DURATION_S = 560.0  # 446 messages/s → 249,760 messages


def mixed_recording(rng: np.random.Generator) -> Recording:
    """Every high-rate topic at its usual rate, random values, 1.7e9 s epoch."""
    builder = RecordingBuilder()
    for topic, rate in RATES_HZ.items():
        n = int(rate * DURATION_S)
        t_ns = 1_700_000_000 * 10**9 + (np.arange(n) * (1e9 / rate)).astype(np.int64)
        columns = {}
        for column in TOPICS[topic].columns:
            if column.dtype == "float64":
                columns[column.name] = rng.normal(0.0, 1.0, n)
            else:
                columns[column.name] = rng.integers(0, 100, n)
        builder.add_many(topic, t_ns, **columns)
    return builder.build()


def baseline_write(recording: Recording, path: Path) -> tuple[float, float]:
    """rosbags per message: serialize_cdr, then Writer.write in time order.

    Returns:
        Seconds for serialising alone, and for serialising + writing the bag.
    """
    store = typestore(2)
    objects = []
    for topic, table in recording.tables.items():
        msgtype = TOPICS[topic].ros2_type
        payloads = encode_table(TOPICS[topic], table, 2)
        objects += [
            (int(t), topic, store.deserialize_cdr(p, msgtype))
            for t, p in zip(table.t_ns.tolist(), payloads, strict=True)
        ]
    objects.sort(key=lambda x: x[0])
    start = time.perf_counter()
    data = [store.serialize_cdr(m, TOPICS[topic].ros2_type) for _, topic, m in objects]
    serialize_s = time.perf_counter() - start
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {
            t: writer.add_connection(t, TOPICS[t].ros2_type, typestore=store)
            for t in recording.tables
        }
        for (t_ns, topic, _), payload in zip(objects, data, strict=True):
            writer.write(conns[topic], t_ns, payload)
    return serialize_s, time.perf_counter() - start


def bulk_encode(recording: Recording) -> float:
    """omnical's bulk CDR encoding of every topic alone. Returns seconds."""
    start = time.perf_counter()
    for topic, table in recording.tables.items():
        encode_table(TOPICS[topic], table, 2)
    return time.perf_counter() - start


def baseline_read(path: Path) -> float:
    """rosbags per message: AnyReader + deserialize. Returns seconds."""
    start = time.perf_counter()
    with AnyReader([path]) as reader:
        count = sum(1 for c, _, raw in reader.messages() if reader.deserialize(raw, c.msgtype))
    assert count > 0
    return time.perf_counter() - start


def timed(label: str, n: int, seconds: float) -> float:
    rate = n / seconds
    print(f"{label:<44} {seconds:6.2f} s  {rate:>10,.0f} msg/s")
    return rate


def main() -> None:
    recording = mixed_recording(np.random.default_rng(0))
    n = recording.message_count
    print(f"{n:,} messages on {len(recording.tables)} topics")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        rates = {}
        for name in ("run.mcap", "run.bag"):
            start = time.perf_counter()
            location = write_bag(recording, root / name)
            rates[f"write {name}"] = timed(
                f"omnical write_bag ({name})", n, time.perf_counter() - start
            )
            start = time.perf_counter()
            back = read_bag(location)
            rates[f"read {name}"] = timed(
                f"omnical read_bag ({name})", n, time.perf_counter() - start
            )
            assert back.message_count == n
        serialize_s, base_write_s = baseline_write(recording, root / "base")
        base_write = timed("baseline rosbags serialize_cdr + write", n, base_write_s)
        base_codec = timed("  of which serialize_cdr alone", n, serialize_s)
        bulk_codec = timed("omnical bulk CDR encode alone", n, bulk_encode(recording))
        base_read = timed("baseline rosbags AnyReader.deserialize", n, baseline_read(root / "base"))
    print(f"ratio write (MCAP) omnical / baseline: {rates['write run.mcap'] / base_write:.1f}x")
    print(f"ratio read  (MCAP) omnical / baseline: {rates['read run.mcap'] / base_read:.1f}x")
    print(f"ratio encode alone omnical / serialize_cdr: {bulk_codec / base_codec:.1f}x")


if __name__ == "__main__":
    main()
