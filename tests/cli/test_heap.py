"""The C heap's policies of :mod:`omnical.cli.heap`, seen in a process's resident memory."""

from __future__ import annotations

import subprocess
import sys

import pytest

_RESIDENT_AFTER_FREE = """
import os, sys
import numpy as np
from omnical.cli import heap
getattr(heap, sys.argv[1])(*map(int, sys.argv[2:]))
page = os.sysconf("SC_PAGE_SIZE")
def resident():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * page
before = resident()
block = np.ones(20 * 2**20 // 8)  # 20 MB, every page touched
del block
print((resident() - before) / 2**20)
"""


def _kept_mb(policy: str, *args: int) -> float:
    done = subprocess.run(
        [sys.executable, "-c", _RESIDENT_AFTER_FREE, policy, *map(str, args)],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    return float(done.stdout)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's heap, /proc")
def test_freed_memory_kept_or_given_back() -> None:
    """``keep_freed_memory``: a 20 MB array freed stays resident for the next one; mapped
    on its own (``map_large_blocks``), it goes back to the system when freed."""
    assert _kept_mb("keep_freed_memory") > 15.0
    assert _kept_mb("map_large_blocks", 2 * 2**20) < 5.0
