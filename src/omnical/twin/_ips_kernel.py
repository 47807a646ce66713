"""The simulated vendor's solve and track filter compiled with numba, row by row.

The arithmetic of :mod:`omnical.twin.ips_vendor`'s numpy reference (``engine="python"``), per
measurement as ``@njit(cache=True)`` kernels: both engines give bit-identical fixes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["jump_filter_kernel", "solve_vendor_kernel"]

_F = TypeVar("_F", bound=Callable[..., object])
_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]
_B = NDArray[np.bool_]

_OPTIONS: dict[str, Any] = {"cache": True, "error_model": "numpy"}

# the same constants as the reference (omnical.twin.ips_vendor)
_GAUSS_NEWTON_ITERATIONS = 8
_MIN_RANGE_M = 1e-6
_SINGULAR = 1e-9


def _jit(func: _F) -> _F:
    return cast(_F, numba.njit(**_OPTIONS)(func))


def _jit_inline(func: _F) -> _F:
    return cast(_F, numba.njit(inline="always", **_OPTIONS)(func))


@_jit_inline
def _maximum(a: float, b: float) -> float:
    """``np.maximum`` of two floats: ``a`` if a >= b or a is NaN, else ``b``."""
    return a if (a >= b or a != a) else b


@_jit_inline
def _solve_2x2(
    a00: float, a01: float, a10: float, a11: float, b0: float, b1: float
) -> tuple[float, float, bool]:
    """One 2×2 solve as the reference's batched ``_solve_2x2``: (x0, x1, good), 0 if singular."""
    det = a00 * a11 - a01 * a10
    scale = abs(a00) + abs(a11)
    good = np.isfinite(det) and abs(det) > _SINGULAR * scale * scale and scale > 0.0
    if not good:
        return 0.0, 0.0, False
    return (a11 * b0 - a01 * b1) / det, (a00 * b1 - a10 * b0) / det, True


@_jit_inline
def _normal_equations(
    x: float, y: float, bxy: _F64, dz2: _F64, d: _F64, w: _F64
) -> tuple[float, float, float, float, float, float, float]:
    """JᵀWJ (4 entries), JᵀW·res (2) and Σ w·res² of the 3D ranges at (x, y)."""
    j00 = 0.0
    j01 = 0.0
    j10 = 0.0
    j11 = 0.0
    r0 = 0.0
    r1 = 0.0
    ss = 0.0
    for k in range(w.shape[0]):
        dx = x - bxy[k, 0]
        dy = y - bxy[k, 1]
        rho = np.sqrt((dx * dx + dy * dy) + dz2[k])
        den = _maximum(rho, _MIN_RANGE_M)
        jx = dx / den
        jy = dy / den
        res = rho - d[k]
        wk = w[k]
        j00 += (wk * jx) * jx
        j01 += (wk * jx) * jy
        j10 += (wk * jy) * jx
        j11 += (wk * jy) * jy
        r0 += (wk * jx) * res
        r1 += (wk * jy) * res
        rw = res * wk
        ss += rw * rw
    return j00, j01, j10, j11, r0, r1, ss


@_jit_inline
def _solve_row(
    bxy: _F64,
    dz2: _F64,
    dist: _F64,
    used: _B,
    skip: int,
    min_beacons: int,
    w: _F64,
    d: _F64,
    c: _F64,
) -> tuple[float, float, bool, int, float, float]:
    """The reference's ``_solve_plain`` for one measurement, slot ``skip`` left out (-1: none).

    Returns x, y (NaN if no fix), ok, distances used, RMS residual (NaN if no fix), HDOP (inf if
    no fix). ``w``, ``d``, ``c`` are (K,) scratch.
    """
    n_slots = w.shape[0]
    n_used = 0
    wsum = 0.0
    for k in range(n_slots):
        u = used[k] and k != skip
        w[k] = 1.0 if u else 0.0
        d[k] = dist[k] if u else 0.0
        n_used += 1 if u else 0
        wsum += w[k]
    wsum = _maximum(wsum, 1.0)
    # linear start: 2(b_i - b̄)·p = c_i - c̄, c_i = |b_i|² - max(d_i² - dz_i², 0)
    sbx = 0.0
    sby = 0.0
    sc = 0.0
    for k in range(n_slots):
        bx = bxy[k, 0]
        by = bxy[k, 1]
        c[k] = (bx * bx + by * by) - _maximum(d[k] * d[k] - dz2[k], 0.0)
        sbx += w[k] * bx
        sby += w[k] * by
        sc += w[k] * c[k]
    mx = sbx / wsum
    my = sby / wsum
    mc = sc / wsum
    a00 = 0.0
    a01 = 0.0
    a10 = 0.0
    a11 = 0.0
    y0 = 0.0
    y1 = 0.0
    for k in range(n_slots):
        ax = 2.0 * (bxy[k, 0] - mx)
        ay = 2.0 * (bxy[k, 1] - my)
        yk = c[k] - mc
        wk = w[k]
        a00 += (wk * ax) * ax
        a01 += (wk * ax) * ay
        a10 += (wk * ay) * ax
        a11 += (wk * ay) * ay
        y0 += (wk * ax) * yk
        y1 += (wk * ay) * yk
    x, y, ok = _solve_2x2(a00, a01, a10, a11, y0, y1)
    ok = ok and n_used >= min_beacons
    if ok:
        for _ in range(_GAUSS_NEWTON_ITERATIONS):
            j00, j01, j10, j11, r0, r1, _ss = _normal_equations(x, y, bxy, dz2, d, w)
            sx, sy, good = _solve_2x2(j00, j01, j10, j11, r0, r1)
            if not good:
                ok = False
                break
            x = x - sx
            y = y - sy
        ok = ok and np.isfinite(x) and np.isfinite(y)
    if not ok:
        return np.nan, np.nan, False, n_used, np.nan, np.inf
    j00, j01, _j10, j11, _r0, _r1, ss = _normal_equations(x, y, bxy, dz2, d, w)
    rms = np.sqrt(ss / max(n_used, 1))
    det = j00 * j11 - j01 * j01
    hdop = np.sqrt((j00 + j11) / det)
    if not (np.isfinite(hdop) and det > 0.0):
        hdop = np.inf
    return x, y, True, n_used, rms, hdop


@_jit
def solve_vendor_kernel(
    beacons: _F64,
    distances: _F64,
    used: _B,
    height: float,
    min_beacons: int,
    outlier_rms: float,
    xy: _F64,
    ok: _B,
    n_used: _I64,
    rms: _F64,
    hdop: _F64,
) -> None:
    """``solve_vendor_2d`` of the reference into the output arrays (NaN ``outlier_rms``: no
    filter). Inputs (M, K, 3), (M, K), (M, K); outputs (M, 2), (M,) ×4."""
    n_rows, n_slots = used.shape
    bxy = np.empty((n_slots, 2))
    dz2 = np.empty(n_slots)
    w = np.empty(n_slots)
    d = np.empty(n_slots)
    c = np.empty(n_slots)
    filtered = not np.isnan(outlier_rms)
    for m in range(n_rows):
        for k in range(n_slots):
            bxy[k, 0] = beacons[m, k, 0]
            bxy[k, 1] = beacons[m, k, 1]
            dz = height - beacons[m, k, 2]
            dz2[k] = dz * dz
        # skip -1: the fix on every distance; then, if the vendor's filter rejects it and a
        # beacon can be spared, without each beacon in turn (one call site: inlined once)
        x, y, good, n, r, h = np.nan, np.nan, False, 0, np.nan, np.inf
        best_x, best_y, best_n, best_r, best_h = np.nan, np.nan, 0, np.inf, np.inf
        retry = False
        for skip in range(-1, n_slots):
            if skip >= 0 and not used[m, skip]:
                continue
            tx, ty, t_ok, tn, tr, th = _solve_row(
                bxy, dz2, distances[m], used[m], skip, min_beacons, w, d, c
            )
            if skip < 0:
                x, y, good, n, r, h = tx, ty, t_ok, tn, tr, th
                if not (filtered and good and r > outlier_rms):
                    break
                good = False  # filtered out, unless a subset is consistent
                retry = n > min_beacons
                if not retry:
                    break
            elif t_ok and tr < best_r:
                best_x, best_y, best_n, best_r, best_h = tx, ty, tn, tr, th
        if retry and best_r <= outlier_rms:
            x, y, n, r, h, good = best_x, best_y, best_n, best_r, best_h, True
        if good:
            xy[m, 0] = x
            xy[m, 1] = y
            rms[m] = r
            hdop[m] = h
        else:
            xy[m, 0] = np.nan
            xy[m, 1] = np.nan
            rms[m] = np.nan
            hdop[m] = np.inf
        ok[m] = good
        n_used[m] = n


@_jit
def jump_filter_kernel(xy: _F64, ok: _B, max_jump: float, patience: int, kept: _B) -> None:
    """The reference ``jump_filter``: clears ``kept`` (a copy of ``ok``) where a fix jumps."""
    have_last = False
    lx = 0.0
    ly = 0.0
    dropped = 0
    for i in range(ok.shape[0]):
        if not ok[i]:
            continue
        if have_last and dropped < patience and np.hypot(xy[i, 0] - lx, xy[i, 1] - ly) > max_jump:
            kept[i] = False
            dropped += 1
            continue
        lx = xy[i, 0]
        ly = xy[i, 1]
        have_last = True
        dropped = 0
