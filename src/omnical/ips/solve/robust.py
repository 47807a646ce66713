"""Robust multilateration against non-line-of-sight (NLOS) range outliers.

:func:`solve_robust`: least squares, a chi-square test, then leave-one-out rejection of
too-long ranges while redundancy remains. Method and measurements: docs/locate.md.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from omnical.ips.solve._fit import Fit, Solution, SolverOptions, chi2_threshold, fit
from omnical.ips.solve._kernels import Array, RangeProblem, Vector
from omnical.ips.solve.fixes import FixReason

__all__ = ["solve_robust"]

_OUTLIER = np.uint16(FixReason.OUTLIER_REJECTED)
_AMBIGUOUS = np.uint16(FixReason.AMBIGUOUS_OUTLIER)
_SINGULAR = np.uint16(FixReason.SINGULAR_GEOMETRY)
_NOT_CONVERGED = np.uint16(FixReason.NOT_CONVERGED)
_FIT_FLAGS = _SINGULAR | _NOT_CONVERGED


def _predicted_distance(problem: RangeProblem, beacon: NDArray[np.intp], point: Vector) -> Array:
    columns = np.arange(beacon.size)
    rho_sq = np.broadcast_to(problem.offset_sq, problem.distance.shape)[beacon, columns]
    for p, b in zip(point, problem.beacon, strict=True):
        rho_sq = rho_sq + (p - b[beacon, 0]) ** 2
    result: Array = np.sqrt(rho_sq)
    return result


@dataclass(eq=False)
class _State:
    """Mutable working state of the robust solve of one chunk (arrays updated in place)."""

    point: list[Array]
    normal: list[Array]
    cost: Array
    reason: NDArray[np.uint16]
    used: NDArray[np.bool_]

    def store(self, fixes: NDArray[np.intp], result: Fit, keep: NDArray[np.bool_]) -> None:
        """Write ``result`` rows ``keep`` into ``fixes`` (point, normal, cost, fit flags)."""
        for target, source in zip(
            (*self.point, *self.normal, self.cost),
            (*result.point, *result.normal, result.cost),
            strict=True,
        ):
            target[fixes] = source[keep]
        self.reason[fixes] = (self.reason[fixes] & ~_FIT_FLAGS) | result.reason[keep]


def _leave_one_out(
    problem: RangeProblem,
    used: NDArray[np.bool_],
    point: Vector,
    score: Array,
    options: SolverOptions,
) -> tuple[NDArray[np.intp], Fit, NDArray[np.bool_]]:
    """Score "beacon j is NLOS" for every used beacon j of k fixes in one vectorised solve.

    The k fixes are replicated once per beacon (m·k columns), each copy without its beacon,
    and solved with two Gauss–Newton steps from ``point`` (enough to rank the hypotheses;
    the winner is refined afterwards).

    Returns:
        The best admissible beacon per fix (-1: none beats ``score``, the residual sum of
        squares / σ² of the current solution), the fit of each fix's best subset, and whether
        another admissible beacon would also have left a subset that passes the test.
    """
    m, k = used.shape
    columns = np.tile(np.arange(k), m)
    dropped = np.repeat(np.arange(m), k)
    hypothesis = np.arange(m * k)
    sub = problem.take(columns)
    sub_used = used[:, columns]
    sub_used[dropped, hypothesis] = False
    scoring = dataclasses.replace(options, iterations=2, max_iterations=2)
    result = fit(sub, sub_used, scoring, start=tuple(p[columns] for p in point))
    excess_m = sub.distance[dropped, hypothesis] - _predicted_distance(sub, dropped, result.point)
    min_excess_m = options.min_outlier_sigmas * options.range_sigma_m
    admissible = used[dropped, columns] & ((result.reason & _SINGULAR) == 0)
    admissible &= excess_m > min_excess_m
    table = np.where(admissible, result.cost / options.range_sigma_m**2, np.inf).reshape(m, k)
    best = np.argmin(table, axis=0)
    better = table[best, np.arange(k)] < score
    dof_after = used.sum(axis=0).astype(np.int64) - 1 - problem.dims
    runner_up = np.sort(table, axis=0)[1] if m > 1 else np.full(k, np.inf)
    ambiguous = runner_up <= chi2_threshold(dof_after, options.alpha)
    pick = best * k + np.arange(k)
    best_fit = Fit(
        tuple(p[pick] for p in result.point),
        result.reason[pick],
        tuple(a[pick] for a in result.normal),
        result.cost[pick],
    )
    return np.where(better, best, -1), best_fit, ambiguous


def solve_robust(
    problem: RangeProblem, valid: NDArray[np.bool_], options: SolverOptions
) -> Solution:
    """Solve every fix with NLOS outlier rejection (see the module docstring).

    Args:
        problem: Distances of n fixes to m beacons (beacon-major).
        valid: Which distances are valid, shape (m, n).
        options: Numerical options (``range_sigma_m`` and ``alpha`` set the test).

    Returns:
        The solution; ``used`` has the rejected beacons removed.
    """
    sigma_sq = options.range_sigma_m**2
    quick = dataclasses.replace(options, max_iterations=options.iterations)
    first = fit(problem, valid, quick)
    state = _State(
        [p.copy() for p in first.point],
        [a.copy() for a in first.normal],
        first.cost.copy(),
        first.reason.copy(),
        valid.copy(),
    )
    dof = valid.sum(axis=0).astype(np.int64) - problem.dims

    def settle(fixes: NDArray[np.intp]) -> NDArray[np.bool_]:
        """Test ``fixes``; converge those that pass; return which fail."""
        fails: NDArray[np.bool_] = ((state.reason[fixes] & _SINGULAR) == 0) & (
            state.cost[fixes] / sigma_sq > chi2_threshold(dof[fixes], options.alpha)
        )
        slow = fixes[~fails & ((state.reason[fixes] & _NOT_CONVERGED) != 0)]
        _refine(problem, state, slow, options)
        state.reason[fixes[fails]] &= ~_NOT_CONVERGED  # judged by consensus, not convergence
        return fails

    failing = settle(np.arange(valid.shape[1]))
    while True:
        candidates = np.flatnonzero(failing & (dof >= 2))
        if candidates.size == 0:
            break
        best, best_fit, ambiguous = _leave_one_out(
            problem.take(candidates),
            state.used[:, candidates],
            tuple(p[candidates] for p in state.point),
            state.cost[candidates] / sigma_sq,
            options,
        )
        dropped = best >= 0
        fixes = candidates[dropped]
        state.used[best[dropped], fixes] = False
        state.reason[fixes] |= _OUTLIER
        state.reason[fixes[ambiguous[dropped]]] |= _AMBIGUOUS
        dof[fixes] -= 1
        state.store(fixes, best_fit, dropped)
        _refine(problem, state, fixes, quick)
        failing[candidates[~dropped]] = False  # nothing better: stop, judged below
        failing[fixes] = settle(fixes)
    rejected = ((state.reason & _FIT_FLAGS) == 0) & (
        state.cost / sigma_sq > chi2_threshold(dof, options.alpha)
    )
    return Solution(
        tuple(state.point), state.used, state.reason, rejected, tuple(state.normal), state.cost
    )


def _refine(
    problem: RangeProblem, state: _State, fixes: NDArray[np.intp], options: SolverOptions
) -> None:
    """Iterate ``fixes`` over their used beacons (budget from ``options``), in place."""
    if fixes.size == 0:
        return
    result = fit(
        problem.take(fixes),
        state.used[:, fixes],
        options,
        start=tuple(p[fixes] for p in state.point),
    )
    state.store(fixes, result, np.ones(fixes.size, dtype=bool))
