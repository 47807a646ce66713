"""read_bag's peak is the decoded tables plus a batch, not twice the tables (issue "Scale" 3)."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
from recording_samples import T0_NS, column_values

from omnical.bags.bag import read_bag, write_bag
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import spec_of


def _imu_bag(path: Path, n: int) -> Path:
    spec = spec_of("/imu")
    assert spec is not None
    rng = np.random.default_rng(n)
    t_ns = T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    return write_bag(Recording({"/imu": Table(t_ns, column_values(spec, n, rng))}), path)


def _overhead(bag: Path) -> tuple[int, int]:
    """Traced bytes of the tables read, and the peak above them while reading."""
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        recording = read_bag(bag, ("/imu",))
        current, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(recording.topic("/imu")) > 0
    return current - base, peak - current


def test_read_peak_grows_with_the_tables_only(tmp_path: Path) -> None:
    """Four times the messages: the memory above the tables stays about the same (it was a
    second copy of the tables, from joining the decoded parts, and the raw payloads of a
    16,384-message batch)."""
    small_tables, small_extra = _overhead(_imu_bag(tmp_path / "small", 40_000))
    large_tables, large_extra = _overhead(_imu_bag(tmp_path / "large", 160_000))
    assert large_tables > 3.5 * small_tables
    assert large_extra < large_tables, (large_tables, large_extra)
    assert large_extra < small_extra + 0.25 * (large_tables - small_tables), (
        small_extra,
        large_extra,
    )
