"""The grid method of seed 000, §4.1: search the position that minimises Eq. 4 at 1 mm.

:func:`solve_grid` (2D, known hedgehog height) runs :func:`search_grid` over
:func:`grid_objective`, coarse to fine; details in docs/locate.md.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from omnical.errors import ConfigError
from omnical.ips.solve._fit import SINGULAR_FLATNESS, Solution, SolverOptions
from omnical.ips.solve._kernels import Array, RangeProblem, flatness, linear_init, linearise
from omnical.ips.solve.fixes import FixReason

__all__ = ["grid_objective", "solve_grid"]

_WINDOW_STEPS = 3
_MAX_CELLS = 1 << 21


def grid_objective(
    problem: RangeProblem,
    used: NDArray[np.bool_],
    x_mm: NDArray[np.int64],
    y_mm: NDArray[np.int64],
) -> Array:
    """Return ``Σ_used w_i (ρ_i − d_i)²`` at candidate points, shape (n, g), m².

    ``w_i`` is the problem's relative precision (1 unless per-beacon σ were given).

    Args:
        problem: Distances of n fixes to m beacons (2D, beacon-major).
        used: Beacons used, shape (m, n).
        x_mm: Candidate x in whole millimetres, shape (n, g) or (1, g).
        y_mm: Candidate y in whole millimetres, same shape as ``x_mm``.
    """
    x = x_mm * 1e-3
    y = y_mm * 1e-3
    total = np.zeros(np.broadcast_shapes(x.shape, (used.shape[1], 1)))
    for i in range(used.shape[0]):
        bx = problem.beacon[0][i, 0]
        by = problem.beacon[1][i, 0]
        offset = (
            problem.offset_sq[i][:, None]
            if problem.offset_sq.shape[1] > 1
            else (problem.offset_sq[i, 0])
        )
        residual = np.sqrt((x - bx) ** 2 + (y - by) ** 2 + offset) - problem.distance[i][:, None]
        weight = 1.0 if problem.precision is None else problem.precision[i, 0]
        total += np.where(used[i][:, None], weight * residual * residual, 0.0)
    return total


def _best_on(
    problem: RangeProblem,
    used: NDArray[np.bool_],
    x_mm: NDArray[np.int64],
    y_mm: NDArray[np.int64],
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Return the best candidate per fix, evaluating in chunks of fixes to bound memory."""
    n = used.shape[1]
    per_fix = max(x_mm.shape[1] * used.shape[0], 1)
    chunk = max(1, _MAX_CELLS // per_fix)
    best_x = np.empty(n, dtype=np.int64)
    best_y = np.empty(n, dtype=np.int64)
    for start in range(0, n, chunk):
        part = np.arange(start, min(start + chunk, n))
        xs = x_mm if x_mm.shape[0] == 1 else x_mm[part]
        ys = y_mm if y_mm.shape[0] == 1 else y_mm[part]
        cost = grid_objective(problem.take(part), used[:, part], xs, ys)
        pick = np.argmin(cost, axis=1)
        best_x[part] = np.take_along_axis(np.broadcast_to(xs, cost.shape), pick[:, None], 1)[:, 0]
        best_y[part] = np.take_along_axis(np.broadcast_to(ys, cost.shape), pick[:, None], 1)[:, 0]
    return best_x, best_y


def search_grid(
    problem: RangeProblem, used: NDArray[np.bool_], options: SolverOptions
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Coarse-to-fine search; return the best 1 mm lattice point per fix (x, y in mm)."""
    coarse_mm = round(options.grid_coarse_step_m * 1000.0)
    if coarse_mm < 1 or (coarse_mm % 10 and coarse_mm != 1):
        msg = f"grid_coarse_step_m must be 1 mm times a power of ten, got {coarse_mm} mm"
        raise ConfigError(msg)
    low, high = [], []
    for b in problem.beacon:
        low.append(int(np.floor((b.min() - options.grid_margin_m) * 1000 / coarse_mm)))
        high.append(int(np.ceil((b.max() + options.grid_margin_m) * 1000 / coarse_mm)))
    gx, gy = np.meshgrid(
        np.arange(low[0], high[0] + 1) * coarse_mm, np.arange(low[1], high[1] + 1) * coarse_mm
    )
    best_x, best_y = _best_on(problem, used, gx.reshape(1, -1), gy.reshape(1, -1))
    step_mm = coarse_mm
    while step_mm > 1:
        span = _WINDOW_STEPS * step_mm
        step_mm //= 10
        offsets = np.arange(-span, span + 1, step_mm)
        ox, oy = (o.reshape(1, -1) for o in np.meshgrid(offsets, offsets))
        best_x, best_y = _best_on(problem, used, best_x[:, None] + ox, best_y[:, None] + oy)
    return best_x, best_y


def solve_grid(problem: RangeProblem, valid: NDArray[np.bool_], options: SolverOptions) -> Solution:
    """Solve every fix by the 1 mm grid search of seed 000 over all its valid distances.

    Args:
        problem: Distances of n fixes to m beacons (2D, beacon-major).
        valid: Which distances are valid, shape (m, n).
        options: Numerical options (``grid_margin_m``, ``grid_coarse_step_m``).

    Returns:
        The solution (positions on the 1 mm lattice).

    Raises:
        ConfigError: If the problem is not 2D or the coarse step is not a power-of-ten mm.
    """
    if problem.dims != 2:
        msg = "method 'grid' solves 2D fixes only (dims=2, known hedgehog height)"
        raise ConfigError(msg)
    n = valid.shape[1]
    weight = problem.weight(valid)
    _, spread = linear_init(problem, None if valid.all() else weight)
    reason = np.zeros(n, dtype=np.uint16)
    best_x, best_y = search_grid(problem, valid, options)
    point = (best_x.astype(np.float64) * 1e-3, best_y.astype(np.float64) * 1e-3)
    lin = linearise(problem, weight, point)
    with np.errstate(invalid="ignore"):
        singular = ~(spread > SINGULAR_FLATNESS) | ~(flatness(lin.normal) > SINGULAR_FLATNESS)
    reason[singular] |= np.uint16(FixReason.SINGULAR_GEOMETRY)
    rejected = np.zeros(n, dtype=bool)
    return Solution(point, valid, reason, rejected, lin.normal, lin.cost)
