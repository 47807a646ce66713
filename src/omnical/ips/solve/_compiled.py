"""Gauss–Newton of :func:`omnical.ips.solve._kernels.gauss_newton`, compiled with numba.

Why: ``omnical locate`` on the 60-minute synthetic bag (random ranges from 100 hedgehog
addresses) solves 100 streams of ~1,150 sliding-window fixes, each five times (the
self-calibration passes), in 900 Gauss–Newton calls. The numpy kernels are vectorised across
fixes, so what was left was numpy's per-call cost: ~100 calls per step on arrays of ~1,200, and
the safeguarded Newton steps of the slow fixes (up to 18 steps, 5 halvings each) on subsets.
Here each fix is a loop over its beacons with scalars (2D: :func:`_gauss_newton2`; 3D: the
generic :func:`_gauss_newton`). On 300 Gauss–Newton calls captured from that bag: numpy
0.29 s, compiled 0.06 s (4.9×); the whole ``locate`` 2.5 → 1.7 s of CPU in one process.

Same result, bit for bit: the arithmetic is the numpy kernels', operation for operation and in
the same order (sums over beacons from 0 in beacon order, as ``einsum("mn,mn->n")`` and
``sum(axis=0)`` do for two or more fixes; no fused multiply–add: numba does not contract
without ``fastmath``), and so is the iteration schedule: the plain steps stop when *every* fix
of the chunk has converged, and so do the safeguarded steps of the slow ones. Letting each fix
stop on its own would save more but move converged fixes by up to the tolerance (1e-5 m), and
one fix's extra step is enough to move a whole chunk by 1e-8 m, so it was not done. Where numpy
sums in another order — a single column: ``einsum`` then adds SIMD lanes — the caller keeps
numpy (a one-fix chunk, or a single slow fix: :func:`gauss_newton_arrays` hands it back).
``tests/ips/test_ips_kernels_compiled.py`` checks the two engines on random problems with
missing, NaN, collinear and NLOS ranges, weights, per-fix heights, 2D and 3D.

Cost: ``cache=True`` keeps the machine code in ``__pycache__``. The first run in a fresh
environment compiles (measured: 2 s of CPU for the 2D kernel, 4.4 s more for the 3D one, once);
after that, importing numba and initialising its compiler costs ~0.35 s of CPU in each process
(numba imports ``scipy.linalg``) and ~100 MB of memory (LLVM). That is why the default engine
(``SolverOptions.engine="auto"``) only takes the kernel when numba is already imported, or when
:func:`omnical.ips.solve.locate_recording` has many streams to solve (the kernel saves ~7 ms per
stream of ~1,200 fixes; break-even near 50 streams); for a one-hedgehog 80-minute run numpy's
large chunks are as fast (0.9 s either way).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["gauss_newton_arrays"]

_Array = NDArray[np.float64]


@numba.njit(cache=True, error_model="numpy", nogil=True)
def _solve_into(sym: _Array, rhs: _Array, out: _Array, dims: int) -> None:  # pragma: no cover
    """``solve_sym`` of one fix: inverse from the cofactors times ``1/det``, then the product."""
    if dims == 2:
        a, b, c = sym[0], sym[1], sym[2]
        inv_det = 1.0 / (a * c - b * b)
        i00, i01, i11 = c * inv_det, -b * inv_det, a * inv_det
        out[0] = (0.0 + i00 * rhs[0]) + i01 * rhs[1]
        out[1] = (0.0 + i01 * rhs[0]) + i11 * rhs[1]
        return
    a, b, c, d, e, f = sym[0], sym[1], sym[2], sym[3], sym[4], sym[5]
    det = a * (d * f - e * e) - b * (b * f - c * e) + c * (b * e - c * d)
    inv_det = 1.0 / det
    i00 = (d * f - e * e) * inv_det
    i01 = (c * e - b * f) * inv_det
    i02 = (b * e - c * d) * inv_det
    i11 = (a * f - c * c) * inv_det
    i12 = (b * c - a * e) * inv_det
    i22 = (a * d - b * b) * inv_det
    out[0] = ((0.0 + i00 * rhs[0]) + i01 * rhs[1]) + i02 * rhs[2]
    out[1] = ((0.0 + i01 * rhs[0]) + i11 * rhs[1]) + i12 * rhs[2]
    out[2] = ((0.0 + i02 * rhs[0]) + i12 * rhs[1]) + i22 * rhs[2]


@numba.njit(cache=True, error_model="numpy", nogil=True)
def _inverse_trace(sym: _Array, dims: int) -> float:  # pragma: no cover
    a: float = sym[0]
    b: float = sym[1]
    c: float = sym[2]
    if dims == 2:
        trace2: float = (a + c) / (a * c - b * b)
        return trace2
    d, e, f = sym[3], sym[4], sym[5]
    det = a * (d * f - e * e) - b * (b * f - c * e) + c * (b * e - c * d)
    trace3: float = (d * f - e * e + a * f - c * c + a * d - b * b) / det
    return trace3


@numba.njit(cache=True, error_model="numpy", nogil=True)
def _positive_definite(sym: _Array, dims: int) -> bool:  # pragma: no cover
    a: float = sym[0]
    b: float = sym[1]
    c: float = sym[2]
    if dims == 2:
        definite2: bool = a > 0.0 and a * c - b * b > 0.0
        return definite2
    d, e, f = sym[3], sym[4], sym[5]
    det = a * (d * f - e * e) - b * (b * f - c * e) + c * (b * e - c * d)
    definite3: bool = a > 0.0 and a * d - b * b > 0.0 and det > 0.0
    return definite3


@numba.njit(cache=True, error_model="numpy", nogil=True)
def _linearise(  # pragma: no cover
    beacon: _Array,
    distance: _Array,
    offset_sq: _Array,
    weight: _Array,
    j: int,
    point: _Array,
    newton: bool,
    bounds: bool,
    normal: _Array,
    gradient: _Array,
    hessian: _Array,
    curvature: _Array,
    scratch: _Array,
) -> float:
    """``_kernels.linearise`` of fix ``j`` at ``point``: fills the sums, returns the cost."""
    dims = beacon.shape[0]
    m = distance.shape[0]
    oc = j if offset_sq.shape[1] > 1 else 0
    wc = j if weight.shape[1] > 1 else 0
    npairs = normal.shape[0]
    for q in range(npairs):
        normal[q] = 0.0
        hessian[q] = 0.0
    for k in range(dims):
        gradient[k] = 0.0
    cost = 0.0
    trace = 0.0
    c_abs = 0.0
    c_inv = 0.0
    diff = scratch[0:3]
    unit = scratch[3:6]
    wunit = scratch[6:9]
    for i in range(m):
        for k in range(dims):
            diff[k] = point[k] - beacon[k, i]
        rho_sq = offset_sq[i, oc] + diff[0] * diff[0]
        for k in range(1, dims):
            rho_sq += diff[k] * diff[k]
        rho = np.sqrt(rho_sq)
        inv_rho = 1.0 / rho
        residual = rho - distance[i, j]
        w = weight[i, wc]
        weighted_residual = w * residual
        weighted_inv = w * inv_rho
        for k in range(dims):
            unit[k] = diff[k] * inv_rho
            wunit[k] = diff[k] * weighted_inv
        q = 0
        for k in range(dims):
            for kk in range(k, dims):
                normal[q] += wunit[k] * unit[kk]
                q += 1
        for k in range(dims):
            gradient[k] += wunit[k] * residual
        cost += weighted_residual * residual
        if newton:
            ratio = weighted_residual * inv_rho
            trace += ratio
            q = 0
            for k in range(dims):
                shrink = wunit[k] - ratio * unit[k]
                for kk in range(k, dims):
                    hessian[q] += shrink * unit[kk]
                    q += 1
        if bounds:
            c_abs += weighted_inv * np.abs(residual)
            c_inv += weighted_inv
    if newton:
        q = 0
        for k in range(dims):
            for kk in range(k, dims):
                if k == kk:
                    hessian[q] = hessian[q] + trace
                q += 1
    if bounds:
        curvature[0] = c_abs
        curvature[1] = c_inv
    return cost


@numba.njit(cache=True, error_model="numpy", nogil=True)
def _weighted_cost(  # pragma: no cover
    beacon: _Array, distance: _Array, offset_sq: _Array, weight: _Array, j: int, trial: _Array
) -> float:
    dims = beacon.shape[0]
    oc = j if offset_sq.shape[1] > 1 else 0
    wc = j if weight.shape[1] > 1 else 0
    cost = 0.0
    for i in range(distance.shape[0]):
        rho_sq = offset_sq[i, oc]
        for k in range(dims):
            d = trial[k] - beacon[k, i]
            rho_sq = rho_sq + d * d
        residual = np.sqrt(rho_sq) - distance[i, j]
        cost += (weight[i, wc] * residual) * residual
    return cost


@numba.njit(cache=True, error_model="numpy", nogil=True)
def _gauss_newton(  # pragma: no cover
    beacon: _Array,
    distance: _Array,
    offset_sq: _Array,
    weight: _Array,
    point: _Array,
    iterations: int,
    max_iterations: int,
    tolerance_m: float,
    error_m: _Array,
    normal_out: _Array,
    cost_out: _Array,
    slow: NDArray[np.int64],
) -> None:
    """Plain steps on every fix (``slow`` empty), or safeguarded Newton steps on the fixes
    ``slow`` (``point`` and the outputs in place)."""
    dims = beacon.shape[0]
    n = distance.shape[1]
    npairs = normal_out.shape[0]
    normal = np.empty(npairs)
    hessian = np.empty(npairs)
    gradient = np.empty(3)
    curvature = np.zeros(2)
    step = np.zeros(3)
    gn_step = np.zeros(3)
    trial = np.zeros(3)
    scratch = np.zeros(9)
    p = np.zeros(3)
    if slow.size == 0:  # first call: plain steps on every fix
        for j in range(n):
            error_m[j] = np.inf
            cost_out[j] = np.inf
        # plain Gauss–Newton steps, all fixes, until all have converged
        for iteration in range(iterations):
            bounds = iteration >= 1
            pending = False
            for j in range(n):
                for k in range(dims):
                    p[k] = point[k, j]
                cost = _linearise(
                    beacon, distance, offset_sq, weight, j, p, False, bounds,
                    normal, gradient, hessian, curvature, scratch,
                )  # fmt: skip
                _solve_into(normal, gradient, step, dims)
                step_sq = 0.0
                decrease = 0.0
                for k in range(dims):
                    point[k, j] = p[k] - step[k]
                    step_sq = step_sq + step[k] * step[k]
                    decrease = decrease + gradient[k] * step[k]
                step_m = np.sqrt(step_sq)
                bound = _inverse_trace(normal, dims) * step_m
                error = bound * (curvature[0] + curvature[1] * step_m) if bounds else step_m
                error_m[j] = error
                for q in range(npairs):
                    normal_out[q, j] = normal[q]
                cost_out[j] = cost - decrease
                if error >= tolerance_m:
                    pending = True
            if not pending:
                break
        return
    # second call: safeguarded Newton steps on the slow fixes, until all have converged
    for j in slow:
        error_m[j] = np.inf
    for _ in range(max_iterations - iterations):
        pending = False
        for j in slow:
            for k in range(dims):
                p[k] = point[k, j]
            cost = _linearise(
                beacon, distance, offset_sq, weight, j, p, True, False,
                normal, gradient, hessian, curvature, scratch,
            )  # fmt: skip
            _solve_into(hessian, gradient, step, dims)
            if not _positive_definite(hessian, dims):
                _solve_into(normal, gradient, gn_step, dims)
                for k in range(dims):
                    step[k] = gn_step[k]
            for _halving in range(5):
                for k in range(dims):
                    trial[k] = p[k] - step[k]
                if not _weighted_cost(beacon, distance, offset_sq, weight, j, trial) > cost:
                    break
                for k in range(dims):
                    step[k] = 0.5 * step[k]
            step_sq = 0.0
            for k in range(dims):
                point[k, j] = p[k] - step[k]
                step_sq = step_sq + step[k] * step[k]
            error_m[j] = np.sqrt(step_sq)
            if error_m[j] >= tolerance_m:
                pending = True
        if not pending:
            break
    for j in slow:
        for k in range(dims):
            p[k] = point[k, j]
        cost = _linearise(
            beacon, distance, offset_sq, weight, j, p, False, False,
            normal, gradient, hessian, curvature, scratch,
        )  # fmt: skip
        for q in range(npairs):
            normal_out[q, j] = normal[q]
        cost_out[j] = cost


@numba.njit(cache=True, error_model="numpy", nogil=True, inline="always")
def _linearise2(  # pragma: no cover
    beacon: _Array,
    distance: _Array,
    offset_sq: _Array,
    weight: _Array,
    j: int,
    px: float,
    py: float,
    newton: bool,
    bounds: bool,
) -> tuple[float, float, float, float, float, float, float, float, float, float, float]:
    """:func:`_linearise` in 2D with scalars: ``(n00, n01, n11, g0, g1, cost, h00, h01, h11,
    Σ w|r|/ρ, Σ w/ρ)`` (the Hessian only with ``newton``, the last two only with ``bounds``)."""
    oc = j if offset_sq.shape[1] > 1 else 0
    wc = j if weight.shape[1] > 1 else 0
    n00 = n01 = n11 = g0 = g1 = cost = 0.0
    h00 = h01 = h11 = trace = c_abs = c_inv = 0.0
    for i in range(distance.shape[0]):
        dx = px - beacon[0, i]
        dy = py - beacon[1, i]
        rho_sq = offset_sq[i, oc] + dx * dx
        rho_sq += dy * dy
        rho = np.sqrt(rho_sq)
        inv_rho = 1.0 / rho
        residual = rho - distance[i, j]
        w = weight[i, wc]
        weighted_residual = w * residual
        weighted_inv = w * inv_rho
        ux = dx * inv_rho
        uy = dy * inv_rho
        wux = dx * weighted_inv
        wuy = dy * weighted_inv
        n00 += wux * ux
        n01 += wux * uy
        n11 += wuy * uy
        g0 += wux * residual
        g1 += wuy * residual
        cost += weighted_residual * residual
        if newton:
            ratio = weighted_residual * inv_rho
            trace += ratio
            sx = wux - ratio * ux
            sy = wuy - ratio * uy
            h00 += sx * ux
            h01 += sx * uy
            h11 += sy * uy
        if bounds:
            c_abs += weighted_inv * np.abs(residual)
            c_inv += weighted_inv
    if newton:
        h00 = h00 + trace
        h11 = h11 + trace
    return n00, n01, n11, g0, g1, cost, h00, h01, h11, c_abs, c_inv


@numba.njit(cache=True, error_model="numpy", nogil=True, inline="always")
def _weighted_cost2(  # pragma: no cover
    beacon: _Array, distance: _Array, offset_sq: _Array, weight: _Array, j: int, x: float, y: float
) -> float:
    oc = j if offset_sq.shape[1] > 1 else 0
    wc = j if weight.shape[1] > 1 else 0
    cost = 0.0
    for i in range(distance.shape[0]):
        dx = x - beacon[0, i]
        dy = y - beacon[1, i]
        residual = np.sqrt((offset_sq[i, oc] + dx * dx) + dy * dy) - distance[i, j]
        cost += (weight[i, wc] * residual) * residual
    return cost


@numba.njit(cache=True, error_model="numpy", nogil=True, inline="always")
def _solve2(
    a: float, b: float, c: float, r0: float, r1: float
) -> tuple[float, float]:  # pragma: no cover
    inv_det = 1.0 / (a * c - b * b)
    i00, i01, i11 = c * inv_det, -b * inv_det, a * inv_det
    return (0.0 + i00 * r0) + i01 * r1, (0.0 + i01 * r0) + i11 * r1


@numba.njit(cache=True, error_model="numpy", nogil=True)
def _gauss_newton2(  # pragma: no cover
    beacon: _Array,
    distance: _Array,
    offset_sq: _Array,
    weight: _Array,
    point: _Array,
    iterations: int,
    max_iterations: int,
    tolerance_m: float,
    error_m: _Array,
    normal_out: _Array,
    cost_out: _Array,
    slow: NDArray[np.int64],
) -> None:
    """:func:`_gauss_newton` in 2D, with scalars (the case ``omnical locate`` runs)."""
    n = distance.shape[1]
    if slow.size == 0:  # first call: plain steps on every fix
        for j in range(n):
            error_m[j] = np.inf
            cost_out[j] = np.inf
        for iteration in range(iterations):
            bounds = iteration >= 1
            pending = False
            for j in range(n):
                px = point[0, j]
                py = point[1, j]
                n00, n01, n11, g0, g1, cost, _, _, _, c_abs, c_inv = _linearise2(
                    beacon, distance, offset_sq, weight, j, px, py, False, bounds
                )
                s0, s1 = _solve2(n00, n01, n11, g0, g1)
                point[0, j] = px - s0
                point[1, j] = py - s1
                step_m = np.sqrt((0.0 + s0 * s0) + s1 * s1)
                if bounds:
                    inverse_trace = (n00 + n11) / (n00 * n11 - n01 * n01)
                    error = (inverse_trace * step_m) * (c_abs + c_inv * step_m)
                else:
                    error = step_m
                error_m[j] = error
                normal_out[0, j] = n00
                normal_out[1, j] = n01
                normal_out[2, j] = n11
                cost_out[j] = cost - ((0.0 + g0 * s0) + g1 * s1)
                if error >= tolerance_m:
                    pending = True
            if not pending:
                break
        return
    # second call: safeguarded Newton steps on the slow fixes, until all have converged
    for j in slow:
        error_m[j] = np.inf
    for _ in range(max_iterations - iterations):
        pending = False
        for j in slow:
            px = point[0, j]
            py = point[1, j]
            n00, n01, n11, g0, g1, cost, h00, h01, h11, _, _ = _linearise2(
                beacon, distance, offset_sq, weight, j, px, py, True, False
            )
            if h00 > 0.0 and h00 * h11 - h01 * h01 > 0.0:
                s0, s1 = _solve2(h00, h01, h11, g0, g1)
            else:
                s0, s1 = _solve2(n00, n01, n11, g0, g1)
            for _halving in range(5):
                trial_cost = _weighted_cost2(
                    beacon, distance, offset_sq, weight, j, px - s0, py - s1
                )
                if not trial_cost > cost:
                    break
                s0 = 0.5 * s0
                s1 = 0.5 * s1
            point[0, j] = px - s0
            point[1, j] = py - s1
            step_m = np.sqrt((0.0 + s0 * s0) + s1 * s1)
            error_m[j] = step_m
            if step_m >= tolerance_m:
                pending = True
        if not pending:
            break
    for j in slow:
        n00, n01, n11, _, _, cost, _, _, _, _, _ = _linearise2(
            beacon, distance, offset_sq, weight, j, point[0, j], point[1, j], False, False
        )
        normal_out[0, j] = n00
        normal_out[1, j] = n01
        normal_out[2, j] = n11
        cost_out[j] = cost


def gauss_newton_arrays(
    beacon: _Array,
    distance: _Array,
    offset_sq: _Array,
    weight: _Array,
    start: _Array,
    *,
    iterations: int,
    max_iterations: int,
    tolerance_m: float,
) -> tuple[_Array, _Array, _Array, _Array, NDArray[np.intp]]:
    """Run the compiled Gauss–Newton on n fixes.

    Args:
        beacon: Beacon coordinates, (dims, m).
        distance: Distances, (m, n).
        offset_sq: Known squared offsets, (m, 1) or (m, n).
        weight: Weights, (m, 1) or (m, n) (ones for the unweighted problem: the products by 1
            are exact, so the result is the numpy kernel's with ``weight`` None).
        start: Starting point, (dims, n).
        iterations: Plain steps for every fix.
        max_iterations: Steps in all for the fixes that have not converged after them.
        tolerance_m: Convergence tolerance, metres.

    Returns:
        Point (dims, n), error bound (n,), normal matrix entries (pairs, n), cost (n,), and
        the fix still to be iterated (safeguarded) when it is the only slow one, else empty:
        numpy's ``einsum`` sums a single column in another order than the kernel, so the
        caller runs the numpy steps on it to keep both engines identical.
    """
    dims = beacon.shape[0]
    n = distance.shape[1]
    point = np.array(start, dtype=np.float64, order="C", copy=True)
    error_m = np.empty(n)
    normal = np.empty((3 if dims == 2 else 6, n))
    cost = np.empty(n)
    kernel = _gauss_newton2 if dims == 2 else _gauss_newton
    arrays = (
        np.ascontiguousarray(beacon, dtype=np.float64),
        np.ascontiguousarray(distance, dtype=np.float64),
        np.ascontiguousarray(offset_sq, dtype=np.float64),
        np.ascontiguousarray(weight, dtype=np.float64),
        point,
    )
    outputs = (error_m, normal, cost)
    settings = (iterations, max_iterations, tolerance_m)
    kernel(*arrays, *settings, *outputs, np.zeros(0, dtype=np.int64))
    slow = np.flatnonzero(error_m >= tolerance_m)  # NaN (singular) is not retried
    if max_iterations <= iterations or slow.size == 0:
        return point, error_m, normal, cost, slow[:0]
    if slow.size == 1:  # numpy sums a single column in another order: left to the caller
        return point, error_m, normal, cost, slow
    kernel(*arrays, *settings, *outputs, slow.astype(np.int64))
    return point, error_m, normal, cost, slow[:0]
