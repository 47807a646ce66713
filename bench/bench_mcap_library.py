"""MCAP library benchmark (issue 24): omnical's own MCAP writer and index reader against Foxglove's
``mcap`` (its Writer and reader, fed and read by omnical's numpy CDR codec) and rosbags, on a
``--minutes`` twin tour: in-process writes and selective reads, then ``omnical simulate``,
``locate`` and ``evaluate`` in fresh processes with each. Prints every figure and its ratio.
Run: ``.venv/bin/python bench/bench_mcap_library.py [--minutes 60] [--repeats 3] [--commands 1]``
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Collection, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from mcap.reader import make_reader
from mcap.writer import CompressionType
from mcap.writer import Writer as LibraryWriter

from omnical import __version__
from omnical.bags import bag as bag_module
from omnical.bags import baginfo as baginfo_module
from omnical.bags.bag import read_bag, write_bag
from omnical.bags.mcapindex import McapSummary
from omnical.bags.mcapwrite import WINDOW
from omnical.bags.messages import encode_table
from omnical.bags.sink import (
    _by_time,
    _rosbag2_information,
    _rows,
    _yaml,
    checked_spec,
    chunk_compression,
)
from omnical.bags.typestores import typestore
from omnical.recording.recording import Recording, Table

LOCATE_TOPICS = ("/beacon_raw_distance", "/beacons_pos_a", "/hedge_pos_ang")
VARIANTS = ("own", "mcap", "rosbags")
READS = {"locate's 3 topics": LOCATE_TOPICS, "/odom": ("/odom",)}
BATCH = 4_096
"""Messages of one channel handed on at once by the library reader (omnical's: one chunk's)."""


# --- the library in omnical's place -----------------------------------------------------------


def library_write_ros2_bag(
    location: Path,
    tables: Mapping[str, Table],
    compression: str | None,
    custom_data: Mapping[str, str],
    **_: object,
) -> None:
    """``sink.write_ros2_bag`` through ``mcap``'s Writer: the same bag directory, schemas,
    channels, rosbag2 metadata and CDR payloads (omnical's codec, a window of messages at a
    time, as the own writer encodes), each message handed to ``Writer.add_message``."""
    chunk = chunk_compression(compression, 2, location)
    entries = []
    for rank, (topic, table) in enumerate(tables.items()):
        spec = checked_spec(topic, table, location)
        if len(table):
            ordered = _by_time(table)
            entries.append((int(ordered.t_ns[0]), rank, topic, spec, ordered))
    entries.sort(key=lambda e: e[:2])
    store = typestore(2)
    location.mkdir(mode=0o755, parents=True)
    storage = location / f"{location.name}.mcap"
    channels: dict[str, tuple[int, str, str]] = {}
    with storage.open("xb") as out:
        writer = LibraryWriter(
            out, compression=CompressionType.ZSTD if chunk == "zstd" else CompressionType.NONE
        )
        writer.start(profile="ros2", library=f"omnical-{__version__}")
        schemas: dict[str, int] = {}
        for _, _, topic, spec, _ in entries:
            msgtype = spec.ros2_type
            if msgtype not in schemas:
                msgdef, _ = store.generate_msgdef(msgtype, ros_version=2)
                idl = msgdef.startswith("=" * 80 + "\nIDL: ")
                schemas[msgtype] = writer.register_schema(
                    msgtype, "ros2idl" if idl else "ros2msg", msgdef.encode()
                )
            cid = writer.register_channel(
                topic, "cdr", schemas[msgtype], {"offered_qos_profiles": ""}
            )
            channels[topic] = (cid, msgtype, store.hash_rihs01(msgtype))
        times = np.concatenate([e[4].t_ns for e in entries]) if entries else np.zeros(0, np.int64)
        which = np.concatenate(
            [np.full(len(e[4]), k, dtype=np.int32) for k, e in enumerate(entries)]
        ) if entries else np.zeros(0, np.int32)  # fmt: skip
        order = np.argsort(times, kind="stable")
        times, which = times[order], which[order]
        done = [0] * len(entries)
        add = writer.add_message
        for w0 in range(0, times.shape[0], WINDOW):
            w_times, w_which = times[w0 : w0 + WINDOW], which[w0 : w0 + WINDOW]
            payloads: list[list[memoryview]] = [[] for _ in entries]
            for k, count in enumerate(np.bincount(w_which, minlength=len(entries)).tolist()):
                if count:
                    _, _, _, spec, table = entries[k]
                    payloads[k] = encode_table(spec, _rows(table, done[k], done[k] + count), 2)
            cursor = done[:]
            for t, k in zip(w_times.tolist(), w_which.tolist(), strict=True):
                row = cursor[k]
                add(channels[entries[k][2]][0], t, payloads[k][row - done[k]], t, row % (1 << 32))
                cursor[k] = row + 1
            done = cursor
        counts = {e[2]: len(e[4]) for e in entries}
        start = min((int(e[4].t_ns[0]) for e in entries), default=2**63 - 1)
        end = max((int(e[4].t_ns[-1]) for e in entries), default=0)
        info = _rosbag2_information(storage.name, channels, counts, start, end, custom_data)
        writer.add_metadata("rosbag2", {"serialized_metadata": _yaml(info).strip()})
        writer.finish()
    (location / "metadata.yaml").write_text(
        _yaml({"rosbag2_bagfile_information": info}), encoding="utf-8"
    )


def library_channel_messages(
    summary: McapSummary, channels: Collection[int]
) -> Iterator[tuple[int, np.ndarray[Any, Any], list[bytes]]]:
    """``mcapindex.channel_messages`` through ``mcap``'s reader, each channel's messages handed
    on :data:`BATCH` at a time. In log-time order (the default): ``log_time_order=False`` is
    about 20 % faster but inflates every chunk before it yields a message (holds them all)."""
    wanted = set(channels)
    with summary.path.open("rb") as stream:
        reader = make_reader(stream)
        library = reader.get_summary()
        topics = sorted({library.channels[c].topic for c in wanted if c in library.channels})
        times: dict[int, list[int]] = {c: [] for c in wanted}
        data: dict[int, list[bytes]] = {c: [] for c in wanted}
        for _, channel, message in reader.iter_messages(topics=topics):
            cid = channel.id
            if cid not in wanted:
                continue
            times[cid].append(message.log_time)
            data[cid].append(message.data)
            if len(data[cid]) >= BATCH:
                yield cid, np.array(times[cid], dtype=np.uint64), data[cid]
                times[cid], data[cid] = [], []
        for cid in sorted(wanted):
            if data[cid]:
                yield cid, np.array(times[cid], dtype=np.uint64), data[cid]


def rosbags_write_ros2_bag(
    location: Path,
    tables: Mapping[str, Table],
    compression: str | None,
    custom_data: Mapping[str, str],
    **_: object,
) -> None:
    """``sink.write_ros2_bag`` through rosbags' writer, message by message (``writer="rosbags"``)."""
    bag_module._write_with_rosbags(Recording(tables), location, 2, compression)  # type: ignore[arg-type]


@contextlib.contextmanager
def using(variant: str) -> Iterator[None]:
    """omnical's bag I/O with the ``own`` MCAP code, the ``mcap`` library in its place, or
    ``rosbags`` (no index: rosbags' writer message by message, its AnyReader for reading)."""
    saved = (
        bag_module.write_ros2_bag,
        bag_module.channel_messages,
        bag_module.indexed_mcap,
        baginfo_module.indexed_mcap,
    )
    if variant == "mcap":
        bag_module.write_ros2_bag = library_write_ros2_bag  # type: ignore[assignment]
        bag_module.channel_messages = library_channel_messages  # type: ignore[assignment]
    elif variant == "rosbags":
        bag_module.write_ros2_bag = rosbags_write_ros2_bag  # type: ignore[assignment]
        bag_module.indexed_mcap = lambda *_a, **_k: None  # type: ignore[assignment]
        baginfo_module.indexed_mcap = lambda *_a, **_k: None  # type: ignore[assignment]
    try:
        yield
    finally:
        (
            bag_module.write_ros2_bag,
            bag_module.channel_messages,
            bag_module.indexed_mcap,
            baginfo_module.indexed_mcap,
        ) = saved


# --- the recording ----------------------------------------------------------------------------


def write_tour(path: Path, minutes: float) -> float:
    """The built-in tour repeated to ``minutes`` as a script file (no YAML aliases: user files
    refuse them); returns its robot time in seconds."""
    from omnical.experiment.library import builtin_script_data
    from omnical.experiment.script import parse_script
    from omnical.robot.loader import load_robot

    limits = load_robot("rosy-mecanum").limits
    steps = builtin_script_data("tour")["steps"]
    once = parse_script({"name": "tour", "steps": steps}, limits).duration_s
    repeats = max(1, round(60.0 * minutes / once))
    data = {"name": f"tour-{minutes:g}min", "steps": [copy.deepcopy(s) for s in steps * repeats]}
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return parse_script(data, limits).duration_s


def simulate(script: Path) -> Recording:
    from omnical.experiment.script import load_script
    from omnical.robot.loader import load_robot
    from omnical.twin.params import load_twin
    from omnical.twin.session import simulate_run

    robot = load_robot("rosy-mecanum")
    return simulate_run(load_script(script, robot.limits), robot, load_twin("default", robot))


# --- measuring --------------------------------------------------------------------------------


def best_of(
    repeats: int, variants: Collection[str], run: Callable[[str], None]
) -> dict[str, float]:
    """Best wall time of ``run(variant)`` over ``repeats`` rounds, the variants alternated."""
    best = dict.fromkeys(variants, float("inf"))
    for _ in range(repeats):
        for variant in variants:
            with using(variant):
                start = time.perf_counter()
                run(variant)
                best[variant] = min(best[variant], time.perf_counter() - start)
    return best


def report(what: str, seconds: Mapping[str, float], unit: str = "") -> None:
    own = seconds["own"]
    for variant, s in seconds.items():
        ratio = "" if variant == "own" else f"   {s / own:5.1f}x omnical's time"
        print(f"{what:<34} {variant:<8} {s:7.2f} s{unit}{ratio}")


def same_tables(a: Recording, b: Recording) -> bool:
    return a.tables.keys() == b.tables.keys() and all(
        np.array_equal(a.tables[t].t_ns, b.tables[t].t_ns)
        and all(
            np.array_equal(a.tables[t][c], b.tables[t][c], equal_nan=True)
            for c in a.tables[t].names
        )
        for t in a.tables
    )


def library_all_the_way(path: Path) -> None:
    """The locate topics decoded by the libraries alone (message objects, no tables built)."""
    file = next(path.glob("*.mcap"))
    store = typestore(2)
    start = time.perf_counter()
    with file.open("rb") as stream:
        reader = make_reader(stream)
        n = sum(
            1
            for schema, _, message in reader.iter_messages(LOCATE_TOPICS, log_time_order=False)
            if store.deserialize_cdr(message.data, schema.name) is not None
        )
    print(f"{'  mcap reader + rosbags deserialize_cdr':<43} {time.perf_counter() - start:7.2f} s"
          f"  ({n:,} message objects, no tables)")  # fmt: skip
    try:
        from mcap_ros2.decoder import DecoderFactory
    except ImportError:
        print("  mcap + mcap-ros2-support: not installed (pip install mcap-ros2-support)")
        return
    start = time.perf_counter()
    with file.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        n = sum(1 for _ in reader.iter_decoded_messages(LOCATE_TOPICS, log_time_order=False))
    print(f"{'  mcap reader + mcap-ros2-support decoder':<43} {time.perf_counter() - start:7.2f} s"
          f"  ({n:,} message objects, no tables)")  # fmt: skip


def _peak_mb() -> float:
    status = Path("/proc/self/status").read_text().splitlines()
    return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:")) / 1024


def _child(variant: str, argv: list[str]) -> None:
    """One ``omnical`` command in this fresh process with ``variant``'s bag I/O."""
    from omnical.cli.main import main as cli_main

    sys.argv = ["omnical", *argv]
    with using(variant):
        try:
            cli_main()
        except SystemExit as stop:
            if stop.code:
                raise
    print(json.dumps({"peak_mb": _peak_mb()}))


def command(variant: str, argv: list[str]) -> tuple[float, float, float]:
    """Wall s, CPU s (user + system) and peak MB of ``omnical ARGV`` with ``variant``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, __file__, "--child", variant, *argv],
        check=False,
        capture_output=True,
        text=True,
    )
    if done.returncode:
        sys.exit(f"omnical {' '.join(argv)} with {variant}: exit {done.returncode}\n{done.stderr}")
    out = done.stdout
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, json.loads(out.strip().splitlines()[-1])["peak_mb"]


def main(minutes: float, repeats: int, command_repeats: int) -> None:
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        script = root / "tour.yaml"
        robot_s = write_tour(script, minutes)
        recording = simulate(script)
        n = recording.message_count
        print(f"twin tour, {robot_s / 60:.0f} min of robot time: {n:,} messages")

        # writing: the same recording, the whole bag directory (staging, metadata.yaml)
        def write(variant: str, recording: Recording = recording) -> None:
            write_bag(recording, root / f"w-{variant}.mcap", overwrite=True)

        write_bag(recording, root / "warm.mcap")  # first calls: type store, compressor
        print("--- write_bag (zstd chunks)")
        report("write", best_of(repeats, VARIANTS, write))
        sizes = ", ".join(
            f"{v} {(root / f'w-{v}' / f'w-{v}.mcap').stat().st_size / 1e6:.1f} MB" for v in VARIANTS
        )
        print(f"{'size':<34} {sizes} (zstd levels -1, 3, 3)")
        bag = root / "w-own"
        check = read_bag(root / "w-mcap", ("/odom", "/hedge_pos_ang"))
        assert same_tables(check, read_bag(bag, ("/odom", "/hedge_pos_ang"))), "bags differ"
        del recording, check

        print("--- selective read_bag of the bag omnical wrote")
        for what, topics in READS.items():
            read = {v: read_bag(bag, topics) for v in ("own", "mcap")}
            assert same_tables(read["own"], read["mcap"]), f"{what}: reads differ"
            del read
            report(what, best_of(repeats, VARIANTS, lambda _v, t=topics: read_bag(bag, t)))  # type: ignore[misc]  # fmt: skip
        library_all_the_way(bag)

        print(f"--- commands in fresh processes (best of {command_repeats}: wall, CPU, peak)")
        commands = {  # info: the mcap library has no per-channel times (they are not in its summary)
            "simulate": (VARIANTS, ["simulate", str(script), "--out", str(root / "c.mcap"), "--overwrite"]),
            "info": (("own", "rosbags"), ["info", str(bag)]),
            "locate": (VARIANTS, ["locate", str(bag), "--out", str(root / "fixes.csv"), "--overwrite"]),
            "evaluate": (VARIANTS, ["evaluate", str(bag), "--out", str(root / "ev"), "--overwrite"]),
        }  # fmt: skip
        for name, (variants, argv) in commands.items():
            runs: dict[str, tuple[float, float, float]] = {}
            for _ in range(command_repeats):
                for variant in variants:
                    got = command(variant, argv)
                    if variant not in runs or got[0] < runs[variant][0]:
                        runs[variant] = got
            for variant, (wall, cpu, peak) in runs.items():
                ratio = (
                    ""
                    if variant == "own"
                    else f"   {wall / runs['own'][0]:4.1f}x wall, {cpu / runs['own'][1]:4.1f}x CPU"
                )
                print(
                    f"omnical {name:<26} {variant:<8} {wall:7.2f} s wall {cpu:6.2f} s CPU"
                    f" {peak:5.0f} MB{ratio}"
                )


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--child":
        _child(sys.argv[2], sys.argv[3:])
    else:
        parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
        parser.add_argument("--minutes", type=float, default=60.0)
        parser.add_argument("--repeats", type=int, default=3, help="in-process rounds (best of)")
        parser.add_argument("--commands", type=int, default=1, help="command rounds (best of)")
        args = parser.parse_args()
        main(args.minutes, args.repeats, args.commands)
