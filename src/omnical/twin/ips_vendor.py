"""The simulated vendor position solution and its quality percentage.

A 2D least-squares fit with the hedgehog height known, an outlier gate and a track filter, in
numpy or numba (``engine``, bit-identical). The model and quality law: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from omnical.twin.params import TwinEngine, compiled_engine

__all__ = [
    "VendorSolution",
    "average_fixes",
    "jump_filter",
    "quality_percent",
    "solve_vendor_2d",
]

_GAUSS_NEWTON_ITERATIONS = 8
_MIN_RANGE_M = 1e-6


@dataclass(frozen=True)
class VendorSolution:
    """Per-measurement 2D fix at known height.

    Attributes:
        xy_m: (M, 2) solved x, y in the map frame, m (NaN where ``ok`` is False).
        ok: (M,) a fix was found (enough distances, non-degenerate geometry).
        n_used: (M,) number of distances used.
        rms_residual_m: (M,) RMS of predicted minus measured distance, m (NaN if not ok).
        hdop: (M,) horizontal dilution of precision at the fix (inf if not ok).
    """

    xy_m: NDArray[np.float64]
    ok: NDArray[np.bool_]
    n_used: NDArray[np.int64]
    rms_residual_m: NDArray[np.float64]
    hdop: NDArray[np.float64]


def solve_vendor_2d(
    beacons_m: NDArray[np.float64],
    distances_m: NDArray[np.float64],
    used: NDArray[np.bool_],
    height_m: float,
    min_beacons: int = 3,
    outlier_rms_m: float | None = None,
    *,
    engine: TwinEngine = "python",
) -> VendorSolution:
    """Least-squares 2D position at a known height, with the vendor's outlier filter.

    Args:
        beacons_m: (M, K, 3) positions of the beacon in each slot, map frame, m.
        distances_m: (M, K) measured distances hedgehog→beacon, m (ignored where not used).
        used: (M, K) slots holding a distance.
        height_m: hedgehog z in the map frame, m.
        min_beacons: fewest distances the vendor accepts for a fix.
        outlier_rms_m: RMS residual above which a fix is filtered, m (None: no filter).
        engine: the numba kernel or the numpy reference (default; :data:`TwinEngine`); same
            result.

    Returns:
        The :class:`VendorSolution` (``n_used`` counts the distances kept).

    Raises:
        ConfigError: an unknown engine.
    """
    beacons_m = np.asarray(beacons_m, dtype=np.float64)  # float64 arithmetic on either engine
    distances_m = np.asarray(distances_m, dtype=np.float64)
    used = np.asarray(used, dtype=np.bool_)
    if compiled_engine(engine, "vendor"):
        return _solve_compiled(beacons_m, distances_m, used, height_m, min_beacons, outlier_rms_m)
    solution = _solve_plain(beacons_m, distances_m, used, height_m, min_beacons)
    if outlier_rms_m is None:
        return solution
    bad = solution.ok & (solution.rms_residual_m > outlier_rms_m)
    rows = np.flatnonzero(bad & (solution.n_used > min_beacons))
    best_rms = np.full(rows.size, np.inf)
    best_xy = np.full((rows.size, 2), np.nan)
    best_hdop = np.full(rows.size, np.inf)
    best_n = np.zeros(rows.size, dtype=np.int64)
    for k in range(used.shape[1]):
        subset = used[rows].copy()
        subset[:, k] = False
        trial = _solve_plain(beacons_m[rows], distances_m[rows], subset, height_m, min_beacons)
        better = trial.ok & used[rows, k] & (trial.rms_residual_m < best_rms)
        best_rms = np.where(better, trial.rms_residual_m, best_rms)
        best_xy = np.where(better[:, None], trial.xy_m, best_xy)
        best_hdop = np.where(better, trial.hdop, best_hdop)
        best_n = np.where(better, trial.n_used, best_n)
    fixed = best_rms <= outlier_rms_m
    xy = solution.xy_m.copy()
    rms = solution.rms_residual_m.copy()
    hdop = solution.hdop.copy()
    n_used = solution.n_used.copy()
    xy[rows[fixed]] = best_xy[fixed]
    rms[rows[fixed]] = best_rms[fixed]
    hdop[rows[fixed]] = best_hdop[fixed]
    n_used[rows[fixed]] = best_n[fixed]
    ok = solution.ok.copy()
    ok[bad] = False
    ok[rows[fixed]] = True
    return VendorSolution(
        xy_m=np.where(ok[:, None], xy, np.nan),
        ok=ok,
        n_used=n_used,
        rms_residual_m=np.where(ok, rms, np.nan),
        hdop=np.where(ok, hdop, np.inf),
    )


def _solve_compiled(
    beacons_m: NDArray[np.float64],
    distances_m: NDArray[np.float64],
    used: NDArray[np.bool_],
    height_m: float,
    min_beacons: int,
    outlier_rms_m: float | None,
) -> VendorSolution:
    """:func:`solve_vendor_2d` by the numba kernel (the same arithmetic, row by row)."""
    from omnical.twin._ips_kernel import solve_vendor_kernel

    mask = np.ascontiguousarray(used, dtype=np.bool_)
    m, k = mask.shape
    beacons = np.ascontiguousarray(beacons_m, dtype=np.float64).reshape(m, k, 3)
    distances = np.ascontiguousarray(distances_m, dtype=np.float64).reshape(m, k)
    xy = np.empty((m, 2))
    ok = np.empty(m, dtype=np.bool_)
    n_used = np.empty(m, dtype=np.int64)
    rms = np.empty(m)
    hdop = np.empty(m)
    threshold = math.nan if outlier_rms_m is None else float(outlier_rms_m)
    solve_vendor_kernel(
        beacons, distances, mask, float(height_m), int(min_beacons), threshold,
        xy, ok, n_used, rms, hdop,
    )  # fmt: skip
    return VendorSolution(xy_m=xy, ok=ok, n_used=n_used, rms_residual_m=rms, hdop=hdop)


def _solve_plain(
    beacons_m: NDArray[np.float64],
    distances_m: NDArray[np.float64],
    used: NDArray[np.bool_],
    height_m: float,
    min_beacons: int = 3,
) -> VendorSolution:
    """Least-squares 2D position at a known height, without outlier rejection.

    A linear solve (range equations minus their mean) gives the start; Gauss–Newton on the 3D
    ranges refines it. Fewer than ``min_beacons`` distances, or collinear beacons, give no fix.

    Args:
        beacons_m: (M, K, 3) positions of the beacon in each slot, map frame, m.
        distances_m: (M, K) measured distances hedgehog→beacon, m (ignored where not used).
        used: (M, K) slots holding a distance.
        height_m: hedgehog z in the map frame, m.
        min_beacons: fewest distances the vendor accepts for a fix.

    Returns:
        The :class:`VendorSolution`.
    """
    w = used.astype(np.float64)
    n_used = used.sum(axis=1).astype(np.int64)
    b_xy = beacons_m[..., :2]
    dz2 = (height_m - beacons_m[..., 2]) ** 2
    d = np.where(used, distances_m, 0.0)

    xy, ok = _linear_start(b_xy, np.maximum(d * d - dz2, 0.0), w)
    ok &= n_used >= min_beacons
    for _ in range(_GAUSS_NEWTON_ITERATIONS):
        jac, rho = _jacobian(xy, b_xy, dz2)
        res = rho - d
        jtj = np.einsum("mk,mki,mkj->mij", w, jac, jac)
        jtr = np.einsum("mk,mki,mk->mi", w, jac, res)
        step, good = _solve_2x2(jtj, jtr)
        ok &= good
        xy = xy - np.where(ok[:, None], step, 0.0)
    ok &= np.all(np.isfinite(xy), axis=1)

    jac, rho = _jacobian(np.where(ok[:, None], xy, 0.0), b_xy, dz2)
    res = (rho - d) * w
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt((res * res).sum(axis=1) / np.maximum(n_used, 1))
        jtj = np.einsum("mk,mki,mkj->mij", w, jac, jac)
        det = jtj[:, 0, 0] * jtj[:, 1, 1] - jtj[:, 0, 1] ** 2
        hdop = np.sqrt((jtj[:, 0, 0] + jtj[:, 1, 1]) / det)
    hdop = np.where(ok & np.isfinite(hdop) & (det > 0.0), hdop, np.inf)
    return VendorSolution(
        xy_m=np.where(ok[:, None], xy, np.nan),
        ok=ok,
        n_used=n_used,
        rms_residual_m=np.where(ok, rms, np.nan),
        hdop=hdop,
    )


def quality_percent(
    solution: VendorSolution,
    n_submap: NDArray[np.int64],
    residual_scale_m: float,
    hdop_good: float,
) -> NDArray[np.uint8]:
    """Quality 0–100 of each fix (the law: docs/DESIGN-NOTES.md).

    Args:
        solution: the vendor fixes.
        n_submap: (M,) beacons of the serving submap (the distances expected).
        residual_scale_m: RMS residual that multiplies the quality by e^-1, m.
        hdop_good: HDOP at and below which geometry costs nothing.

    Returns:
        (M,) quality percentage as uint8; 0 where there is no fix.
    """
    ok = solution.ok
    rms = np.where(ok, solution.rms_residual_m, 0.0)
    f_res = np.exp(-((rms / residual_scale_m) ** 2))
    f_count = solution.n_used / np.maximum(n_submap, 1)
    f_geom = np.minimum(1.0, hdop_good / np.where(ok, solution.hdop, np.inf))
    q = np.where(ok, np.rint(100.0 * f_res * f_count * f_geom), 0.0)
    return np.clip(q, 0.0, 100.0).astype(np.uint8)


def _linear_start(
    b_xy: NDArray[np.float64], r2: NDArray[np.float64], w: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Solve 2(b_i - b̄)·p = c_i - c̄ with c_i = |b_i|² - r_i², weighted means over used slots."""
    wsum = np.maximum(w.sum(axis=1), 1.0)
    c = (b_xy * b_xy).sum(axis=-1) - r2
    b_mean = (w[..., None] * b_xy).sum(axis=1) / wsum[:, None]
    c_mean = (w * c).sum(axis=1) / wsum
    a = 2.0 * (b_xy - b_mean[:, None, :])
    y = c - c_mean[:, None]
    ata = np.einsum("mk,mki,mkj->mij", w, a, a)
    aty = np.einsum("mk,mki,mk->mi", w, a, y)
    xy, ok = _solve_2x2(ata, aty)
    return np.where(ok[:, None], xy, 0.0), ok


def _jacobian(
    xy: NDArray[np.float64], b_xy: NDArray[np.float64], dz2: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(M, K, 2) derivative of each 3D range w.r.t. x, y, and the (M, K) ranges."""
    diff = xy[:, None, :] - b_xy
    rho = np.sqrt((diff * diff).sum(axis=-1) + dz2)
    return diff / np.maximum(rho, _MIN_RANGE_M)[..., None], rho


def _solve_2x2(
    a: NDArray[np.float64], b: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Batched 2×2 solve; rows whose matrix is (near) singular are flagged and give 0."""
    det = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]
    scale = np.abs(a[:, 0, 0]) + np.abs(a[:, 1, 1])
    good = np.isfinite(det) & (np.abs(det) > 1e-9 * scale * scale) & (scale > 0.0)
    safe = np.where(good, det, 1.0)
    x0 = (a[:, 1, 1] * b[:, 0] - a[:, 0, 1] * b[:, 1]) / safe
    x1 = (a[:, 0, 0] * b[:, 1] - a[:, 1, 0] * b[:, 0]) / safe
    out = np.stack([x0, x1], axis=1)
    return np.where(good[:, None], out, 0.0), good


def jump_filter(
    xy_m: NDArray[np.float64],
    ok: NDArray[np.bool_],
    max_jump_m: float,
    patience: int = 3,
    *,
    engine: TwinEngine = "python",
) -> NDArray[np.bool_]:
    """The vendor's track filter: drop fixes that jump from the last kept one (causal).

    A fix farther than ``max_jump_m`` from the last kept fix is dropped, unless ``patience``
    fixes in a row were dropped (the hedgehog really moved, e.g. after an outage).

    Args:
        xy_m: (M, 2) fixes in time order, m.
        ok: (M,) which fixes exist.
        max_jump_m: largest plausible move between two consecutive fixes, m.
        patience: consecutive drops after which the next fix is accepted anyway.
        engine: the numba kernel or the Python reference (default; :data:`TwinEngine`); same
            result.

    Returns:
        (M,) ``ok`` with the dropped fixes cleared.
    """
    kept = np.array(ok, dtype=np.bool_)
    if compiled_engine(engine, "vendor"):
        from omnical.twin._ips_kernel import jump_filter_kernel

        xy = np.ascontiguousarray(xy_m, dtype=np.float64).reshape(len(kept), 2)
        jump_filter_kernel(xy, kept, float(max_jump_m), int(patience), kept)
        return kept
    last: NDArray[np.float64] | None = None
    dropped = 0
    for i in np.flatnonzero(ok):
        if last is not None and dropped < patience and np.hypot(*(xy_m[i] - last)) > max_jump_m:
            kept[i] = False
            dropped += 1
            continue
        last = xy_m[i]
        dropped = 0
    return kept


def average_fixes(
    xy_m: NDArray[np.float64], ok: NDArray[np.bool_], n_fixes: int
) -> NDArray[np.float64]:
    """The vendor's location averaging: each fix replaced by the mean of the last ``n_fixes``.

    Causal: fix i is the mean of itself and the ``n_fixes − 1`` valid fixes before it (fewer
    at the start); noise about 1/√n, a delay of (n − 1)/2 measurement periods.

    Args:
        xy_m: (M, 2) fixes in time order, m (ignored where not ``ok``).
        ok: (M,) which fixes exist.
        n_fixes: fixes averaged, ≥ 1 (1: no averaging).

    Returns:
        (M, 2) averaged fixes, NaN where not ``ok``.
    """
    out = np.full_like(xy_m, np.nan)
    rows = np.flatnonzero(ok)
    if rows.size == 0:
        return out
    valid = xy_m[rows]
    total = np.concatenate([np.zeros((1, 2)), np.cumsum(valid, axis=0)])
    upper = np.arange(1, rows.size + 1)
    lower = np.maximum(upper - max(int(n_fixes), 1), 0)
    out[rows] = (total[upper] - total[lower]) / (upper - lower)[:, None]
    return out
