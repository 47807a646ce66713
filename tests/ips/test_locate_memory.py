"""locate's working memory is bounded by a chunk, not by the recording (issue "Scale" item 3)."""

from __future__ import annotations

import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from omnical.ips import from_recording
from omnical.ips.solve import _fit
from omnical.ips.solve import locate as locate_module


def _track(n: int, seed: int = 0) -> tuple[NDArray[np.float64], ...]:
    """A hedgehog's fixes: a walk with jumps, unusable fixes and gaps in time."""
    rng = np.random.default_rng(seed)
    xy = np.cumsum(rng.normal(0.0, 0.01, (n, 2)), axis=0)
    jumps = rng.random(n) < 0.02
    xy[jumps] += rng.normal(0.0, 0.5, (int(jumps.sum()), 2))
    xy[rng.random(n) < 0.01] = np.nan
    covariance = np.zeros((n, 2, 2))
    covariance[:, 0, 0] = covariance[:, 1, 1] = 1e-4 * (1.0 + rng.random(n))
    covariance[:, 0, 1] = covariance[:, 1, 0] = 2e-5 * rng.random(n)
    status = rng.choice(np.array([0, 1, 2, 3], dtype=np.uint8), n, p=[0.7, 0.1, 0.1, 0.1])
    step = np.where(rng.random(n) < 0.01, 3_000_000_000, 100_000_000)
    t_ns = np.cumsum(step).astype(np.int64)
    return xy, covariance, status, t_ns


def _peak(call: object, *args: object) -> int:
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        call(*args)  # type: ignore[operator]
        return tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()


def test_off_track_in_chunks_is_the_whole_run_at_once(monkeypatch: pytest.MonkeyPatch) -> None:
    xy, covariance, status, t_ns = _track(20_000)
    chunked = locate_module.off_track(xy, covariance, status.astype(np.uint8), t_ns)
    monkeypatch.setattr(locate_module, "_TRACK_CHUNK", 10**9)
    whole = locate_module.off_track(xy, covariance, status.astype(np.uint8), t_ns)
    monkeypatch.setattr(locate_module, "_TRACK_CHUNK", 7)
    tiny = locate_module.off_track(xy, covariance, status.astype(np.uint8), t_ns)
    assert whole.sum() > 50
    np.testing.assert_array_equal(chunked, whole)
    np.testing.assert_array_equal(tiny, whole)


def test_off_track_memory_does_not_grow_with_the_run() -> None:
    """The (n, 2, 11) windows of the whole run were ~0.5 kB a fix: 4× the fixes, 4× the peak."""
    small = _track(20_000)
    large = _track(80_000)
    peak_small = _peak(locate_module.off_track, *small)
    peak_large = _peak(locate_module.off_track, *large)
    assert peak_large < 2.0 * peak_small, (peak_small, peak_large)
    assert peak_large < 100 * 80_000  # well under 0.5 kB a fix


def test_one_hedgehog_is_not_copied_into_a_merged_result() -> None:
    from omnical.ips.beacons import default_beacon_map
    from omnical.ips.solve.locate import solve_fixes

    beacons = default_beacon_map()
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(1, 4, 50), rng.uniform(1, 3, 50), np.zeros(50)])
    distances = np.linalg.norm(points[:, None, :] - beacons.positions_m[None], axis=2)
    part = solve_fixes(distances, beacons, hedge_z_m=0.0)
    merged = locate_module.MergedFixes(50, len(beacons))
    merged.add(np.arange(50), part)
    assert merged.result().positions_map_m is part.positions_map_m


def test_chi2_table_is_scipy_bit_for_bit() -> None:
    from scipy.special import chdtri

    for alpha, known in _fit._CHI2_KNOWN.items():
        expected = chdtri(np.arange(1, len(known) + 1), alpha)
        got = np.array([float.fromhex(h) for h in known])
        np.testing.assert_array_equal(got, expected)
        dof = np.arange(0, len(known) + 1)
        np.testing.assert_array_equal(_fit.chi2_threshold(dof, alpha)[1:], expected)
    assert _fit.chi2_quantile(2, 0.001) == float(chdtri(2, 0.001))
    # Beyond the table: scipy.
    assert _fit.chi2_threshold(np.array([40]), 0.01)[0] == float(chdtri(40, 0.01))


def test_csv_in_chunks_is_the_same_bytes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from ips_synthetic import locate_recording

    from omnical.ips.beacons import default_beacon_map

    beacons = default_beacon_map()
    rng = np.random.default_rng(2)
    n = 300
    points = np.column_stack([rng.uniform(1, 4, n), rng.uniform(1, 3, n), np.full(n, 0.4)])
    distances = np.linalg.norm(points[:, None, :] - beacons.positions_m[None], axis=2)
    distances += rng.normal(0.0, 0.02, distances.shape)
    distances[rng.random(distances.shape) < 0.2] = np.nan
    m = len(beacons)
    t_ns = (np.repeat(np.arange(n), m) * 100_000_000 + np.tile(np.arange(m), n)).astype(np.int64)
    fixes = locate_recording(
        t_ns,
        np.full(n * m, 7),
        np.tile(beacons.addresses, n),
        distances.reshape(-1),
        beacons,
        hedge_z_m=0.4,
    )
    whole = from_recording.write_fixes_csv(fixes, tmp_path / "whole.csv").read_bytes()
    monkeypatch.setattr(from_recording, "_CSV_CHUNK", 7)
    chunked = from_recording.write_fixes_csv(fixes, tmp_path / "chunked.csv").read_bytes()
    assert chunked == whole
    assert whole.count(b"\n") == n + 1


def _reference_line(fixes: object, i: int) -> str:
    """One CSV line as ``write_fixes_csv`` wrote it before the chunk-wide formatting."""
    from omnical.ips.solve.fixes import FixStatus

    f: Any = fixes
    c = f.covariance_xy_m2[i]
    numbers = [
        *f.positions_map_m[i].tolist(),
        float(c[0, 0]),
        float(c[0, 1]),
        float(c[1, 1]),
        float(f.hdop[i]),
        float(f.residual_rms_m[i]),
        float(f.error_eq4_m[i]),
    ]
    used = ";".join(str(a) for a in f.beacon_addresses[f.used[i]])
    status = FixStatus(int(f.status[i])).name.lower()
    reason = from_recording.reason_text(int(f.reason[i]))
    if all(np.isnan(numbers)):
        return f"{int(f.t_ns[i])}," + ",".join(["nan"] * 9) + f",{used},{status},{reason}"
    row: list[object] = [int(f.t_ns[i]), *numbers, used, status, reason]
    line = "{},{:.4f},{:.4f},{:.4f},{:.6e},{:.6e},{:.6e},{:.4f},{:.5f},{:.6f},{},{},{}".format
    return line(*row)


def test_csv_text_is_str_format_of_each_value(tmp_path: Path) -> None:
    """Hostile numbers (NaN, infinities, −0, huge, subnormal, rounding ties) write as before."""
    import dataclasses

    from omnical.ips.beacons import default_beacon_map
    from omnical.ips.solve.locate import solve_fixes

    beacons = default_beacon_map()
    rng = np.random.default_rng(5)
    n = 400
    points = np.column_stack([rng.uniform(1, 4, n), rng.uniform(1, 3, n), np.zeros(n)])
    distances = np.linalg.norm(points[:, None, :] - beacons.positions_m[None], axis=2)
    distances[rng.random(distances.shape) < 0.3] = np.nan
    fixes = solve_fixes(distances + rng.normal(0, 0.02, distances.shape), beacons, hedge_z_m=0.0)
    hostile = np.array(
        [np.nan, np.inf, -np.inf, -0.0, 0.0, 1e300, -1e300, 5e-324, 0.00005, 1.00005, 2.5e-5,
         -2.5e-5, 0.125, 123456789012.34567, 9.9999995e-5, 1.0e-3]
    )  # fmt: skip
    solved = np.isfinite(fixes.positions_map_m[:, 0])  # the degenerate fixes stay all NaN
    positions = fixes.positions_map_m.copy()
    covariance = fixes.covariance_xy_m2.copy()
    positions[solved, 0] = rng.choice(hostile, int(solved.sum()))
    covariance[solved, 0, 1] = rng.choice(hostile, int(solved.sum()))
    hdop = np.where(solved & (rng.random(n) < 0.5), rng.choice(hostile, n), fixes.hdop)
    fixes = dataclasses.replace(
        fixes,
        positions_map_m=positions,
        covariance_xy_m2=covariance,
        hdop=hdop,
        t_ns=np.arange(n, dtype=np.int64) * 10**8 + 1_700_000_000 * 10**9,
    )
    text = from_recording.write_fixes_csv(fixes, tmp_path / "f.csv").read_text(encoding="utf-8")
    lines = text.splitlines()
    assert lines[0] == from_recording.FIXES_CSV_HEADER
    assert lines[1:] == [_reference_line(fixes, i) for i in range(n)]
    assert any(line.split(",")[1] == "-0.0000" for line in lines[1:])
    assert any(",nan,nan,nan,nan,nan,nan,nan,nan,nan," in line for line in lines[1:])
