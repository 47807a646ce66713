"""Work in a forked process (:mod:`omnical.ips.forked`): its result comes back, the files it
made (spills) come back open and outlive it, and a child that fails or is ended leaves
nothing behind (no process, no open descriptor)."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np

from omnical.ips.forked import collect, fork, reap
from omnical.ips.windowed import Spill

_RECORDS = np.dtype([("t", "<i8"), ("d", "<f8")])


def _descriptors() -> set[str]:
    return {p.name for p in Path("/proc/self/fd").iterdir()}


def _gone(pid: int) -> bool:
    return not Path(f"/proc/{pid}").exists()


def _spills_made_there() -> tuple[str, Spill, Spill, int]:
    """In the child: two spills on temporary files made there, and the child's pid."""
    first, second = Spill(_RECORDS), Spill(np.dtype("<i8"))
    records = np.zeros(5, dtype=_RECORDS)
    records["t"] = np.arange(5)
    records["d"] = np.arange(5) * 0.5
    first.append(records)
    second.append(np.array([7, 8, 9], dtype=np.int64))
    return "made", first, second, os.getpid()


def test_a_result_and_the_spills_made_in_the_child_come_back() -> None:
    before = _descriptors()
    child = fork(_spills_made_there, shared=(Spill,))
    pid = child.pid
    word, first, second, where = collect(child)
    reap(child)
    assert word == "made" and where == pid != os.getpid() and _gone(pid)
    # the child has ended: its temporary files live on through the descriptors it sent
    got = first.read(0, first.rows)
    assert first.rows == 5 and got["t"].tolist() == [0, 1, 2, 3, 4]
    assert got["d"].tolist() == [0.0, 0.5, 1.0, 1.5, 2.0]
    assert second.read(0, second.rows).tolist() == [7, 8, 9]
    first.append(np.zeros(1, dtype=_RECORDS))  # ours now: written as any spill
    assert first.rows == 6
    first.close()
    second.close()
    assert _descriptors() == before


def _fails() -> None:
    raise RuntimeError("the work failed")


def test_work_that_fails_gives_none_and_leaves_nothing() -> None:
    before = _descriptors()
    child = fork(_fails)
    pid = child.pid
    assert collect(child) is None
    reap(child)
    assert _gone(pid)
    assert _descriptors() == before


def _sleeps() -> None:
    time.sleep(60.0)


def test_a_child_still_at_work_is_ended_by_reap() -> None:
    """Interrupted while the child works (Ctrl-C, an error here): reap ends it at once."""
    before = _descriptors()
    child = fork(_sleeps)
    pid = child.pid
    start = time.monotonic()
    reap(child)
    assert time.monotonic() - start < 5.0
    assert child.pid == 0 and _gone(pid)
    assert _descriptors() == before


def test_a_child_killed_gives_none() -> None:
    """Out of memory, a stray signal: the caller is told, and does the work itself."""
    child = fork(_sleeps)
    os.kill(child.pid, signal.SIGKILL)
    assert collect(child) is None
    reap(child)


def _large() -> bytes:
    return bytes(range(256)) * 16_384  # 4 MB: more than a socket's buffer


def test_a_large_result_comes_back_whole() -> None:
    child = fork(_large)
    try:
        assert collect(child) == bytes(range(256)) * 16_384
    finally:
        reap(child)
