"""Benchmark: MCAP chunks read and inflated one ahead by a worker thread (issue "Scale").

:func:`omnical.recording.mcapindex.channel_messages` hands the caller one chunk's messages
while a worker thread reads and inflates the next (file reads and zstd release the GIL). The
baseline, run in the same process on the same bag, is the sequential reader it replaced (read,
inflate, cut, one chunk after the other, all in the caller's thread), swapped in for
``BagStream``. Measured: what ``omnical locate`` reads of the bag (``_read_ranges``: ranges,
beacons, vendor heights), best of ``--repeats``, wall time and the main thread's CPU (the
critical path of a locate that forks its learning afterwards), and that both give the same
ranges.

Session 7 (2026-11-24), zstd60 (``bench_bag.py --scale``'s 60-minute bag, 534 zstd chunks,
560 MB inflated), shared 2-core machine with another job running: main-thread CPU
0.66–0.69 → 0.43–0.54 s.

Run: ``.venv/bin/python bench/bench_read_ahead.py BAG [--repeats N]``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Collection, Iterator
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

import omnical.recording.stream as stream_module
from omnical.cli.locate import _read_ranges
from omnical.recording import mcapindex


def sequential(
    summary: mcapindex.McapSummary, channels: Collection[int]
) -> Iterator[tuple[int, NDArray[np.uint64], list[bytes]]]:
    """The reader before the read-ahead: every step in the caller's thread."""
    wanted = set(channels)
    with summary.path.open("rb") as stream:
        size = stream.seek(0, 2)
        fd = stream.fileno()
        for chunk in summary.chunks:
            here = sorted(wanted.intersection(chunk.index_offsets))
            if not here:
                continue
            raw, block = mcapindex._load_chunk(fd, size, chunk)
            base = chunk.offset + chunk.length
            for cid in here:
                entries = mcapindex._index_entries(block, chunk.index_offsets[cid] - base, cid)
                yield cid, *mcapindex._cut(raw, entries, cid)


def measure(bag: Path, repeats: int) -> tuple[float, float, NDArray[np.generic]]:
    """Best wall and main-thread CPU of reading ``bag`` as locate does; the ranges read."""
    best_wall = best_cpu = float("inf")
    ranges: NDArray[np.generic] = np.zeros(0)
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.thread_time()
        run = _read_ranges(bag)
        best_wall = min(best_wall, time.perf_counter() - wall)
        best_cpu = min(best_cpu, time.thread_time() - cpu)
        ranges = run.raw.read(0, run.raw.rows).copy()
        run.close()
    return best_wall, best_cpu, ranges


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bag", type=Path)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    measure(args.bag, 1)  # imports, page cache
    ahead_wall, ahead_cpu, ahead = measure(args.bag, args.repeats)
    original = mcapindex.channel_messages  # the name BagStream calls
    setattr(stream_module, "channel_messages", sequential)  # noqa: B010 - not exported there
    try:
        base_wall, base_cpu, base = measure(args.bag, args.repeats)
    finally:
        setattr(stream_module, "channel_messages", original)  # noqa: B010
    assert np.array_equal(ahead, base), "the read-ahead changed what is read"
    print(f"{args.bag}: {ahead.size:,} ranges, best of {args.repeats}")
    print(f"  sequential (baseline): wall {base_wall:.3f} s, main-thread CPU {base_cpu:.3f} s")
    print(f"  read-ahead:            wall {ahead_wall:.3f} s, main-thread CPU {ahead_cpu:.3f} s")
    print(f"  ratio baseline / read-ahead: wall {base_wall / ahead_wall:.2f}×, "
          f"main-thread CPU {base_cpu / ahead_cpu:.2f}×")  # fmt: skip


if __name__ == "__main__":
    main()
