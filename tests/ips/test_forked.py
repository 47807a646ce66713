"""Work in a forked process (:mod:`omnical.ips.forked`): its result comes back, the files it
made (spills) come back open and outlive it, and a child that fails or is ended leaves
nothing behind (no process, no open descriptor)."""

from __future__ import annotations

import os
import signal
import tempfile
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


def _many_spills() -> list[Spill]:
    spills = [Spill(np.dtype("<i8")) for _ in range(20)]
    for k, spill in enumerate(spills):
        spill.append(np.array([k], dtype=np.int64))
    return spills


def test_more_files_than_a_message_carries_give_none() -> None:
    before = _descriptors()
    child = fork(_many_spills, shared=(Spill,))
    assert collect(child) is None
    reap(child)
    assert _descriptors() == before


class _Unrebuilt:
    """A shared object whose rebuilding fails here."""

    def __init__(self) -> None:
        self._file = tempfile.TemporaryFile()  # noqa: SIM115 - closed with the child

    def fileno(self) -> int:
        return self._file.fileno()

    def handover(self) -> None:
        return None

    @classmethod
    def adopt(cls, fd: int, state: object) -> _Unrebuilt:
        raise ValueError("cannot rebuild")


def _unrebuilt() -> tuple[Spill, _Unrebuilt]:
    spill = Spill(np.dtype("<i8"))
    spill.append(np.array([1], dtype=np.int64))
    return spill, _Unrebuilt()


def test_a_result_that_does_not_rebuild_gives_none_and_no_open_file() -> None:
    before = _descriptors()
    child = fork(_unrebuilt, shared=(Spill, _Unrebuilt))
    assert collect(child) is None
    reap(child)
    assert _descriptors() == before


def _one_spill_twice() -> tuple[Spill, Spill]:
    spill = Spill(np.dtype("<i8"))
    spill.append(np.array([5, 6], dtype=np.int64))
    return spill, spill


def test_one_spill_met_twice_comes_back_as_one() -> None:
    before = _descriptors()
    child = fork(_one_spill_twice, shared=(Spill,))
    first, second = collect(child)
    reap(child)
    assert first is second and first.read(0, 2).tolist() == [5, 6]
    assert not os.get_inheritable(first.fileno())
    first.close()
    assert _descriptors() == before


def _one_spill() -> Spill:
    spill = Spill(np.dtype(np.uint8))
    spill.append(np.frombuffer(b"alone", dtype=np.uint8))
    return spill


def test_a_spill_returned_alone_comes_back() -> None:
    """Nothing else holds it in the child: it stays open until sent (it had been freed,
    its file closed, once pickled)."""
    child = fork(_one_spill, shared=(Spill,))
    spill = collect(child)
    reap(child)
    assert isinstance(spill, Spill) and spill.read(0, spill.rows).tobytes() == b"alone"
    spill.close()
