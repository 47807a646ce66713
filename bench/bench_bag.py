"""Bag benchmark: write and read ~250,000 mixed messages (about 10 minutes of a robot run).

Figures, all measured in this process on the same recording:

* omnical ``write_bag`` / ``read_bag`` (bulk numpy CDR codec), ROS 2 MCAP and ROS 1, in
  messages per second; ROS 2 MCAP written by omnical's bulk MCAP writer (the default: whole
  Message records from numpy, a chunk at a time) and, in the same run, by rosbags' writer
  message by message (``write_bag(..., writer="rosbags")``, what it was before), zstd chunks
  and uncompressed;
* the baseline: rosbags' per-message path into the same MCAP writer, i.e. ``serialize_cdr``
  of each message object (objects prebuilt, not timed, which favours the baseline) for
  writing, and ``AnyReader.deserialize`` of each message for reading;
* the ratios omnical / baseline.

``--scale`` (issue "Scale") instead measures, on synthetic bags of 1, 10 and 60 minutes at the
twin's topic rates (values random, so compression is a lower bound for real runs):

* bag size and write time, zstd-compressed (the default) vs uncompressed MCAP, and the write
  time of rosbags' per-message writer on the same recording;
* ``omnical info`` (:func:`summarize_bag`: the MCAP index and the travel the writer tallied in
  ``custom_data``): time and peak memory, each in a fresh process, against the whole-bag read
  it replaces (``summarize(read_bag(...))`` through rosbags' AnyReader, as before the change)
  and against decoding /odom and /ground_truth for the travel;
* ``read_bag`` of locate's three topics and of /odom vs the full read, against rosbags'
  AnyReader merely iterating the same topics' raw messages (no decoding).

Run: ``.venv/bin/python bench/bench_bag.py`` (codec) or ``... bench/bench_bag.py --scale``.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer

from omnical.bags.bag import read_bag, write_bag
from omnical.bags.messages import encode_table
from omnical.bags.typestores import typestore
from omnical.recording.recording import Recording, RecordingBuilder
from omnical.recording.topics import TOPICS

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
LOCATE_TOPICS = ("/beacon_raw_distance", "/beacons_pos_a", "/hedge_pos_ang")


def mixed_recording(rng: np.random.Generator, duration_s: float = DURATION_S) -> Recording:
    """Every high-rate topic at its usual rate, random values, 1.7e9 s epoch."""
    builder = RecordingBuilder()
    for topic, rate in RATES_HZ.items():
        n = int(rate * duration_s)
        t_ns = 1_700_000_000 * 10**9 + (np.arange(n) * (1e9 / rate)).astype(np.int64)
        columns = {}
        for column in TOPICS[topic].columns:
            if column.name == "distance_m":  # a range: reading drops negative ones
                columns[column.name] = rng.uniform(0.0, 30.0, n)
            elif column.dtype == "float64":
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
        for writer in ("bulk", "rosbags"):  # warm up: type store, first-call costs
            warm = mixed_recording(np.random.default_rng(1), 1.0)
            write_bag(warm, root / f"warm-{writer}.mcap", writer=writer)  # type: ignore[arg-type]
        for label, compression in (("zstd", "auto"), ("uncompressed", None)):
            for writer in ("bulk", "rosbags"):
                start = time.perf_counter()
                write_bag(
                    recording,
                    root / f"{writer}-{label}.mcap",
                    compression=compression,  # type: ignore[arg-type]
                    writer=writer,  # type: ignore[arg-type]
                )
                rates[f"{writer} {label}"] = timed(
                    f"write_bag MCAP {label}, {writer} writer", n, time.perf_counter() - start
                )
            ratio = rates[f"bulk {label}"] / rates[f"rosbags {label}"]
            print(f"ratio write MCAP {label}: bulk writer / rosbags writer {ratio:.1f}x")
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


def _child(kind: str, path: str) -> None:
    """One measurement in this fresh process: prints seconds and peak RSS (MB)."""
    from omnical.bags import bag as bag_module
    from omnical.bags.baginfo import summarize_bag
    from omnical.recording.summary import summarize

    start = time.perf_counter()
    if kind == "info":
        summarize_bag(path)
    elif kind == "info-decoded":  # the travel decoded from /odom and /ground_truth, not stored
        from omnical.bags import baginfo

        baginfo._stored_travel = lambda *_a, **_k: {}  # type: ignore[assignment]
        summarize_bag(path)
    elif kind == "info-old":  # the whole-bag read of before: every topic through AnyReader
        bag_module.indexed_mcap = lambda *_a, **_k: None  # type: ignore[assignment]
        summarize(read_bag(path))
    elif kind == "full":
        read_bag(path)
    elif kind in {"locate", "odom"}:
        read_bag(path, LOCATE_TOPICS if kind == "locate" else ("/odom",))
    elif kind in {"raw-locate", "raw-odom"}:
        topics = LOCATE_TOPICS if kind == "raw-locate" else ("/odom",)
        with AnyReader([Path(path)]) as reader:
            conns = [c for c in reader.connections if c.topic in topics]
            sum(1 for _ in reader.messages(connections=conns))
    seconds = time.perf_counter() - start
    # VmHWM, not ru_maxrss: the latter keeps the parent's peak across fork + exec.
    status = Path("/proc/self/status").read_text().splitlines()
    peak_kb = next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))
    print(f"{seconds} {peak_kb / 1024}")


def _measure(kind: str, path: Path) -> tuple[float, float]:
    out = subprocess.run(
        [sys.executable, __file__, "--child", kind, str(path)],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    return float(out[0]), float(out[1])


def scale() -> None:
    """Size, write time, info and selective reads on 1, 10 and 60-minute bags."""
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for minutes in (1, 10, 60):
            recording = mixed_recording(np.random.default_rng(minutes), 60.0 * minutes)
            n = recording.message_count
            print(f"--- {minutes} min: {n:,} messages")
            start = time.perf_counter()
            plain = write_bag(recording, root / f"plain{minutes}", compression=None)
            plain_s = time.perf_counter() - start
            start = time.perf_counter()
            packed = write_bag(recording, root / f"zstd{minutes}")
            packed_s = time.perf_counter() - start
            start = time.perf_counter()
            write_bag(recording, root / f"rosbags{minutes}", writer="rosbags")
            rosbags_s = time.perf_counter() - start
            del recording
            size_plain = sum(f.stat().st_size for f in plain.iterdir())
            size_packed = sum(f.stat().st_size for f in packed.iterdir())
            print(
                f"size   uncompressed {size_plain / 1e6:8.1f} MB  zstd {size_packed / 1e6:7.1f} MB"
                f"  ratio {size_plain / size_packed:.1f}x smaller"
            )
            print(
                f"write  uncompressed {plain_s:6.2f} s  zstd {packed_s:6.2f} s"
                f"  ratio {packed_s / plain_s:.2f}x the time"
            )
            print(
                f"write  zstd, rosbags' writer {rosbags_s:6.2f} s   ratio bulk writer "
                f"{rosbags_s / packed_s:.1f}x faster ({n / packed_s:,.0f} vs "
                f"{n / rosbags_s:,.0f} msg/s)"
            )
            old_s, old_mb = _measure("info-old", packed)
            info_s, info_mb = _measure("info", packed)
            dec_s, dec_mb = _measure("info-decoded", packed)
            print(
                f"info   travel decoded instead of the writer's tally {dec_s:6.3f} s "
                f"{dec_mb:6.0f} MB peak   ratio {dec_s / info_s:.0f}x"
            )
            print(
                f"info   {info_s:6.3f} s {info_mb:6.0f} MB peak   whole-bag read before "
                f"{old_s:6.2f} s {old_mb:6.0f} MB   ratio {old_s / info_s:.0f}x faster, "
                f"{old_mb / info_mb:.1f}x less memory"
            )
            full_s, full_mb = _measure("full", packed)
            print(f"read_bag full          {full_s:6.2f} s {full_mb:6.0f} MB peak")
            for kind in ("locate", "odom"):
                sel_s, sel_mb = _measure(kind, packed)
                raw_s, _ = _measure(f"raw-{kind}", packed)
                print(
                    f"read_bag {kind:<6} topics {sel_s:6.2f} s {sel_mb:6.0f} MB peak   "
                    f"vs full {full_s / sel_s:.1f}x faster; rosbags AnyReader iterating them "
                    f"(no decode) {raw_s:6.2f} s, ratio {raw_s / sel_s:.1f}x"
                )


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        _child(sys.argv[2], sys.argv[3])
    elif len(sys.argv) > 1 and sys.argv[1] == "--scale":
        scale()
    else:
        main()
