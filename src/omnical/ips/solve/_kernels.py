"""Vectorised Gauss–Newton kernels for range multilateration.

Internal to the solvers: :class:`RangeProblem`, :func:`linearise`, :func:`linear_init` and
closed-form small symmetric solves. Layout and range model: docs/locate.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
Vector = tuple[Array, ...]
Sym = tuple[Array, ...]  # 2D: (a00, a01, a11); 3D: (a00, a01, a02, a11, a12, a22)

_PAIRS = {2: ((0, 0), (0, 1), (1, 1)), 3: ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))}


@dataclass(frozen=True, eq=False)
class RangeProblem:
    """Distances of n fixes to m beacons, in beacon-major layout.

    Attributes:
        beacon: Beacon coordinate per solved axis, each of shape (m, 1), metres.
        distance: Measured distance, shape (m, n), metres; 0 where missing.
        offset_sq: Known squared offset along the unsolved axes, (m, 1) or (m, n), m².
        precision: Relative weight of each beacon's range, ``(σ_ref/σ_i)²``, shape (m, 1);
            None when all ranges have the reference σ.
    """

    beacon: Vector
    distance: Array
    offset_sq: Array
    precision: Array | None = None

    def weight(self, used: NDArray[np.bool_]) -> Array | None:
        """Return the weight matrix (m, n) for the beacons ``used``; None if all ones."""
        if self.precision is None:
            return None if used.all() else used.astype(np.float64)
        return used * self.precision

    @property
    def dims(self) -> int:
        """Number of solved axes (2 or 3)."""
        return len(self.beacon)

    def take(self, columns: NDArray[np.intp]) -> RangeProblem:
        """Return the sub-problem of the fixes ``columns``."""
        offset = self.offset_sq if self.offset_sq.shape[1] == 1 else self.offset_sq[:, columns]
        return RangeProblem(self.beacon, self.distance[:, columns], offset, self.precision)


def weighted_sum(weight: Array, values: Array) -> Array:
    """Return ``Σ_i weight_i · values_i`` over beacons, shape (n,)."""
    result: Array = np.einsum("mn,mn->n", weight, values)
    return result


def _entry(sym: Sym, dims: int, row: int, col: int) -> Array:
    row, col = min(row, col), max(row, col)
    return sym[_PAIRS[dims].index((row, col))]


def det_sym(sym: Sym) -> Array:
    """Return the determinant of symmetric 2×2 or 3×3 matrices given by their entries."""
    if len(sym) == 3:
        a, b, c = sym
        return a * c - b * b
    a, b, c, d, e, f = sym
    return a * (d * f - e * e) - b * (b * f - c * e) + c * (b * e - c * d)


def inverse_sym(sym: Sym) -> tuple[Sym, Array]:
    """Return the entries of the inverses of symmetric matrices and their determinants."""
    det = det_sym(sym)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_det = 1.0 / det
        if len(sym) == 3:
            a, b, c = sym
            return (c * inv_det, -b * inv_det, a * inv_det), det
        a, b, c, d, e, f = sym
        return (
            (d * f - e * e) * inv_det,
            (c * e - b * f) * inv_det,
            (b * e - c * d) * inv_det,
            (a * f - c * c) * inv_det,
            (b * c - a * e) * inv_det,
            (a * d - b * b) * inv_det,
        ), det


def inverse_stack(normal: Array, fill: float) -> tuple[Array, NDArray[np.bool_]]:
    """The inverses of a stack of symmetric 2×2 or 3×3 matrices (f, k, k) in closed form
    (:func:`inverse_sym`), ``fill`` where one is singular (``|det| ≤ 1e-12``), and where
    each is regular."""
    k = normal.shape[1]
    rows, columns = np.triu_indices(k)
    entries, det = inverse_sym(tuple(normal[:, i, j] for i, j in zip(rows, columns, strict=True)))
    good: NDArray[np.bool_] = np.abs(det) > 1e-12
    inverse = np.empty_like(normal)
    for i, j, entry in zip(rows, columns, entries, strict=True):
        inverse[:, i, j] = inverse[:, j, i] = np.where(good, entry, fill)
    return inverse, good


def solve_sym(sym: Sym, rhs: Vector) -> tuple[Vector, Array]:
    """Solve symmetric 2×2 or 3×3 systems; return the solutions and the determinants."""
    inverse, det = inverse_sym(sym)
    dims = len(rhs)
    with np.errstate(invalid="ignore", over="ignore"):
        solution = tuple(
            sum((_entry(inverse, dims, k, col) * rhs[col] for col in range(dims)), np.zeros(1))
            for k in range(dims)
        )
    return solution, det


def flatness(sym: Sym) -> Array:
    """Return ``det(A) / (tr(A)/dims)^dims`` in [0, 1]: 0 when the matrix is singular."""
    dims = 2 if len(sym) == 3 else 3
    trace = sum(_entry(sym, dims, k, k) for k in range(dims))
    with np.errstate(divide="ignore", invalid="ignore"):
        result: Array = det_sym(sym) / (trace / dims) ** dims
    return result


def linear_init(problem: RangeProblem, weight: Array | None) -> tuple[Vector, Array]:
    """Closed-form linearised solution (differences of squared ranges about the centroid).

    ``‖p − b_i‖² = d_i² − c_i`` minus its weighted mean over beacons removes ``‖p‖²`` and
    leaves ``−2 (b_i − b̄)·p = q_i − q̄`` with ``q_i = d_i² − c_i − ‖b_i‖²``, solved by
    weighted least squares. With ``weight`` None (every beacon used, weights
    ``problem.precision``) the system matrix is the same for all fixes and the solution is
    one matrix product.

    Returns:
        The solution per axis, each (n,), and the flatness of the beacon spread (0 when the
        beacons used are collinear in 2D or coplanar in 3D).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        if weight is None:
            return _linear_init_shared(problem)
        return _linear_init(problem, weight)


def _linear_init_shared(problem: RangeProblem) -> tuple[Vector, Array]:
    dims = problem.dims
    beacons = np.hstack(problem.beacon)  # (m, dims)
    m = beacons.shape[0]
    weight = np.ones(m) if problem.precision is None else problem.precision[:, 0]
    centred = beacons - weight @ beacons / weight.sum()
    spread = (centred * weight[:, None]).T @ centred
    n = problem.distance.shape[1]
    entries = tuple(np.full(n, spread[k, j]) for k, j in _PAIRS[dims])
    if not abs(np.linalg.det(spread)) > 0.0:
        return tuple(np.full(n, np.nan) for _ in range(dims)), flatness(entries)
    projector = np.linalg.solve(spread, -0.5 * (centred * weight[:, None]).T)  # (dims, m)
    constant = problem.offset_sq + np.sum(beacons * beacons, axis=1)[:, None]
    q = problem.distance * problem.distance - constant
    solution = projector @ q
    return tuple(solution), flatness(entries)


def _linear_init(problem: RangeProblem, weight: Array) -> tuple[Vector, Array]:
    dims = problem.dims
    total = weight.sum(axis=0)
    inv_total = 1.0 / total
    centred = [b - (b[:, 0] @ weight) * inv_total for b in problem.beacon]
    q = problem.distance * problem.distance - problem.offset_sq
    for b in problem.beacon:
        q = q - b * b
    wq = weight * q
    spread = tuple(weighted_sum(weight * centred[k], centred[j]) for k, j in _PAIRS[dims])
    rhs = tuple(-0.5 * weighted_sum(wq, centred[k]) for k in range(dims))
    solution, _ = solve_sym(spread, rhs)
    return solution, flatness(spread)


def positive_definite(sym: Sym) -> NDArray[np.bool_]:
    """Return whether symmetric 2×2 / 3×3 matrices are positive definite (leading minors)."""
    with np.errstate(invalid="ignore"):
        if len(sym) == 3:
            a, b, c = sym
            result: NDArray[np.bool_] = (a > 0.0) & (a * c - b * b > 0.0)
            return result
        a, b, _, d, _, _ = sym
        minors: NDArray[np.bool_] = (a > 0.0) & (a * d - b * b > 0.0) & (det_sym(sym) > 0.0)
        return minors


@dataclass(frozen=True, eq=False)
class Linearisation:
    """Residuals and normal equations of the weighted range problem at a point."""

    residual: Array
    """``ρ_i − d_i``, shape (m, n), metres."""
    normal: Sym
    """Entries of ``JᵀWJ``, each (n,)."""
    gradient: Vector
    """``JᵀWr``, each (n,)."""
    cost: Array
    """``rᵀWr``, shape (n,), m²."""
    hessian: Sym
    """Entries of the full Hessian of ``½ rᵀWr`` (only with ``newton=True``, else empty)."""
    curvature: tuple[Array, ...]
    """``(Σ w_i |r_i|/ρ_i, Σ w_i/ρ_i)``, each (n,) (only with ``bounds=True``, else empty)."""


def linearise(
    problem: RangeProblem,
    weight: Array | None,
    point: Vector,
    *,
    newton: bool = False,
    bounds: bool = False,
) -> Linearisation:
    """Return residuals, weighted normal equations and cost at ``point``.

    ``weight`` None means all ones (skips the products). With ``newton`` also the full
    Hessian ``JᵀWJ + Σ w_i r_i ∇²ρ_i`` where ``∇²ρ_i = (I − u_i u_iᵀ)/ρ_i`` for the unit
    vector ``u_i = ∂ρ_i/∂p``. With ``bounds`` also the sums that bound the second-order
    term, for :func:`error_bound`.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        return _linearise(problem, weight, point, newton, bounds)


def _linearise(
    problem: RangeProblem, weight: Array | None, point: Vector, newton: bool, bounds: bool
) -> Linearisation:
    diff = [p - b for p, b in zip(point, problem.beacon, strict=True)]
    rho_sq = problem.offset_sq + diff[0] * diff[0]
    for d in diff[1:]:
        rho_sq += d * d
    rho = np.sqrt(rho_sq)
    inv_rho = np.reciprocal(rho, out=rho_sq)
    residual = rho - problem.distance
    if weight is None:
        weighted_residual = residual
        unit = [d * inv_rho for d in diff]
        weighted_unit = unit
    else:
        weighted_residual = weight * residual
        weighted_inv = weight * inv_rho
        unit = [d * inv_rho for d in diff]
        weighted_unit = [d * weighted_inv for d in diff]
    dims = len(unit)
    normal = tuple(weighted_sum(weighted_unit[k], unit[j]) for k, j in _PAIRS[dims])
    gradient = tuple(weighted_sum(weighted_unit[k], residual) for k in range(dims))
    cost = weighted_sum(weighted_residual, residual)
    hessian: Sym = ()
    if newton:
        ratio = weighted_residual * inv_rho
        shrink = [wu - ratio * u for wu, u in zip(weighted_unit, unit, strict=True)]
        trace = ratio.sum(axis=0)
        hessian = tuple(
            weighted_sum(shrink[k], unit[j]) + (trace if k == j else 0.0) for k, j in _PAIRS[dims]
        )
    curvature: tuple[Array, ...] = ()
    if bounds:
        weighted_inv = inv_rho if weight is None else weight * inv_rho
        curvature = (weighted_sum(weighted_inv, np.abs(residual)), weighted_inv.sum(axis=0))
    return Linearisation(residual, normal, gradient, cost, hessian, curvature)


def inverse_trace(sym: Sym) -> Array:
    """Return the trace of the inverses of symmetric 2×2 / 3×3 matrices (≥ largest eigenvalue)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        if len(sym) == 3:
            a, _, c = sym
            result: Array = (a + c) / det_sym(sym)
            return result
        a, b, c, d, e, f = sym
        trace: Array = (d * f - e * e + a * f - c * c + a * d - b * b) / det_sym(sym)
        return trace


def error_bound(lin: Linearisation, step_m: Array) -> Array:
    """Bound the distance to the minimum after a Gauss–Newton step of length ``step_m``.

    With ``e`` the error before the step (≈ the step), the error after it is at most
    ``‖N⁻¹‖ Σ_i w_i (|r_i| e + e²)/ρ_i`` (the Hessian of ρ_i has norm 1/ρ_i): linear in
    ``e`` with the residuals, quadratic without. ``‖N⁻¹‖`` is bounded by its trace.
    """
    weighted_abs_residual, weighted_inverse = lin.curvature[0], lin.curvature[1]
    result: Array = (
        inverse_trace(lin.normal) * step_m * (weighted_abs_residual + weighted_inverse * step_m)
    )
    return result


def weighted_cost(
    problem: RangeProblem, weight: Array | NDArray[np.bool_] | None, point: Vector
) -> Array:
    """Return ``Σ_i w_i (ρ_i − d_i)²`` at ``point``, shape (n,), m²."""
    rho_sq = problem.offset_sq
    for p, b in zip(point, problem.beacon, strict=True):
        rho_sq = rho_sq + (p - b) ** 2
    residual = np.sqrt(rho_sq) - problem.distance
    return weighted_sum(residual if weight is None else weight * residual, residual)


@dataclass(frozen=True, eq=False)
class GaussNewtonResult:
    """Outcome of :func:`gauss_newton` for n fixes."""

    point: Vector
    """Final coordinates per axis, each (n,), metres."""
    error_m: Array
    """Bound on the remaining error (or the last step's length), (n,), metres; NaN where
    the system was singular."""
    normal: Sym
    """``JᵀWJ`` at the final point (to first order in the last step), each (n,)."""
    cost: Array
    """``rᵀWr`` at the final point (to second order in the last step), (n,), m²."""


def _plain_steps(
    problem: RangeProblem,
    weight: Array | None,
    point: Vector,
    iterations: int,
    tolerance_m: float,
) -> GaussNewtonResult:
    """Plain Gauss–Newton steps on all fixes, stopping early once all have converged.

    A fix has converged when the last step is shorter than ``tolerance_m``, or, from the
    second step on, when :func:`error_bound` says the point is within ``tolerance_m`` of
    the minimum (so a fix with small residuals needs two steps, not three). The cost after
    a full step is predicted as ``rᵀWr − gᵀs`` (exact for the linearised problem), so no
    extra evaluation is needed at the final point.
    """
    n = problem.distance.shape[1]
    error_m = np.full(n, np.inf)
    normal: Sym = ()
    cost = np.full(n, np.inf)
    for iteration in range(iterations):
        lin = linearise(problem, weight, point, bounds=iteration >= 1)
        step, _ = solve_sym(lin.normal, lin.gradient)
        point = tuple(p - s for p, s in zip(point, step, strict=True))
        step_m = np.sqrt(sum((s * s for s in step), np.zeros(1)))
        error_m = error_bound(lin, step_m) if lin.curvature else step_m
        decrease = sum((g * s for g, s in zip(lin.gradient, step, strict=True)), np.zeros(1))
        normal, cost = lin.normal, lin.cost - decrease
        if not np.any(error_m >= tolerance_m):
            break
    return GaussNewtonResult(point, error_m, normal, cost)


def safeguarded_steps(
    problem: RangeProblem,
    weight: Array | None,
    point: Vector,
    iterations: int,
    tolerance_m: float,
) -> GaussNewtonResult:
    """Newton steps where the Hessian is positive definite, else Gauss–Newton; backtracking.

    Large residuals (an NLOS range) make plain Gauss–Newton converge linearly or oscillate;
    the full Hessian restores fast convergence near the minimum. A step that does not lower
    the cost is halved (up to 5 times).
    """
    step_m = np.full(problem.distance.shape[1], np.inf)
    for _ in range(iterations):
        lin = linearise(problem, weight, point, newton=True)
        newton_step, _ = solve_sym(lin.hessian, lin.gradient)
        gn_step, _ = solve_sym(lin.normal, lin.gradient)
        use_newton = positive_definite(lin.hessian)
        step = tuple(np.where(use_newton, a, b) for a, b in zip(newton_step, gn_step, strict=True))
        for _ in range(5):
            trial = tuple(p - s for p, s in zip(point, step, strict=True))
            with np.errstate(invalid="ignore"):
                worse = weighted_cost(problem, weight, trial) > lin.cost
            if not np.any(worse):
                break
            step = tuple(np.where(worse, 0.5 * s, s) for s in step)
        point = tuple(p - s for p, s in zip(point, step, strict=True))
        step_m = np.sqrt(sum((s * s for s in step), np.zeros(1)))
        if not np.any(step_m >= tolerance_m):
            break
    final = linearise(problem, weight, point)
    return GaussNewtonResult(point, step_m, final.normal, final.cost)


def gauss_newton(
    problem: RangeProblem,
    weight: Array | None,
    point: Vector,
    *,
    iterations: int,
    max_iterations: int,
    tolerance_m: float,
) -> GaussNewtonResult:
    """Minimise ``rᵀWr`` from ``point``.

    All fixes get up to ``iterations`` plain Gauss–Newton steps. Those whose last step is
    still not below ``tolerance_m`` go on alone with safeguarded Newton steps, up to
    ``max_iterations`` steps in all.
    """
    result = _plain_steps(problem, weight, point, iterations, tolerance_m)
    slow = np.flatnonzero(result.error_m >= tolerance_m)  # NaN (singular) is not retried
    if slow.size == 0 or max_iterations <= iterations or not result.normal:
        return result
    sub = safeguarded_steps(
        problem.take(slow),
        None if weight is None else weight[:, slow],
        tuple(p[slow] for p in result.point),
        max_iterations - iterations,
        tolerance_m,
    )
    merged = [a.copy() for a in (*result.point, *result.normal, result.error_m, result.cost)]
    for target, source in zip(
        merged, (*sub.point, *sub.normal, sub.error_m, sub.cost), strict=True
    ):
        target[slow] = source
    dims = len(point)
    return GaussNewtonResult(tuple(merged[:dims]), merged[-2], tuple(merged[dims:-2]), merged[-1])
