"""Shared pieces of the solvers: options, per-chunk solution, Gauss–Newton fit, chi-square test."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from functools import lru_cache
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from omnical.errors import ConfigError
from omnical.ips.solve._kernels import (
    Array,
    GaussNewtonResult,
    RangeProblem,
    Sym,
    Vector,
    flatness,
    gauss_newton,
    linear_init,
    safeguarded_steps,
)
from omnical.ips.solve.fixes import FixReason

SINGULAR_FLATNESS = 1e-10
"""Beacon spreads or normal matrices flatter than this are treated as singular."""


@dataclass(frozen=True)
class SolverOptions:
    """Numerical options shared by the solvers.

    Use it to tune the residual test, the iteration budget or the grid; the defaults suit
    Marvelmind-like ranges (σ ≈ 2 cm).

    Attributes:
        range_sigma_m: Prior range noise σ, metres: the floor of the σ̂ used for covariances
            and the scale of the chi-square residual test.
        alpha: Significance of the chi-square residual test (false-alarm rate on clean fixes).
        min_outlier_sigmas: The robust method drops a beacon only if its measured distance
            exceeds the one predicted by the other beacons by more than this many σ.
        iterations: Gauss–Newton iterations run on every fix (after the closed-form start).
        max_iterations: Iterations allowed to fixes that have not converged after that.
        tolerance_m: A fix has converged when the bound on its distance to the minimum
            (from the last step and the residuals) is below this, metres.
        grid_margin_m: The grid method searches the beacons' bounding box grown by this, m.
        grid_coarse_step_m: First grid step of the grid method, metres (refined by 10× to 1 mm).
        engine: Gauss–Newton engine: ``"compiled"`` (numba, :mod:`._compiled`), ``"numpy"``
            (the vectorised reference, :mod:`._kernels`) or ``"auto"`` (compiled when numba
            is already imported, see :func:`use_compiled`). Both give the same fixes.
    """

    range_sigma_m: float = 0.02
    alpha: float = 0.01
    min_outlier_sigmas: float = 3.0
    iterations: int = 2
    max_iterations: int = 20
    tolerance_m: float = 1e-5
    grid_margin_m: float = 2.0
    grid_coarse_step_m: float = 0.1
    engine: Literal["auto", "compiled", "numpy"] = "auto"

    def __post_init__(self) -> None:
        checks = {
            "range_sigma_m": self.range_sigma_m > 0.0,
            "alpha": 0.0 < self.alpha < 1.0,
            "min_outlier_sigmas": self.min_outlier_sigmas >= 0.0,
            "iterations": self.iterations >= 1,
            "max_iterations": self.max_iterations >= self.iterations,
            "tolerance_m": self.tolerance_m > 0.0,
            "grid_margin_m": self.grid_margin_m >= 0.0,
            "grid_coarse_step_m": self.grid_coarse_step_m >= 0.001,
            "engine": self.engine in ("auto", "compiled", "numpy"),
        }
        for name, ok in checks.items():
            if not ok:
                msg = f"SolverOptions: {name} out of range: {getattr(self, name)!r}"
                raise ConfigError(msg)


@dataclass(frozen=True, eq=False)
class Solution:
    """What a method returns for a chunk of n fixes (m beacons)."""

    point: Vector
    """Solved coordinates per axis, each (n,), metres."""
    used: NDArray[np.bool_]
    """Beacons used, shape (m, n)."""
    reason: NDArray[np.uint16]
    """:class:`FixReason` flags set by the method, shape (n,)."""
    rejected: NDArray[np.bool_]
    """Fixes the method found untrustworthy, shape (n,)."""
    normal: Sym
    """``JᵀJ`` over the beacons used, at ``point``, each (n,)."""
    cost: Array
    """Residual sum of squares over the beacons used, at ``point``, (n,), m²."""


@lru_cache(maxsize=64)
def _chi2_table(alpha: float, size: int) -> Array:
    # imported here: scipy.special costs ~0.2 s, and importing omnical.ips must stay cheap
    from scipy.special import chdtri

    table = np.full(size + 1, np.inf)
    table[1:] = chdtri(np.arange(1, size + 1), alpha)  # = scipy.stats.chi2.isf(alpha, dof)
    return table


def chi2_threshold(dof: NDArray[np.int64], alpha: float) -> Array:
    """Return the chi-square ``1 − alpha`` quantile for each dof (inf where dof ≤ 0)."""
    table = _chi2_table(alpha, int(max(int(dof.max(initial=0)), 1)))
    result: Array = table[np.clip(dof, 0, None)]
    return result


@dataclass(frozen=True, eq=False)
class Fit:
    """Least-squares fit of n fixes over given beacons."""

    point: Vector
    """Coordinates per axis, each (n,), metres."""
    reason: NDArray[np.uint16]
    """``SINGULAR_GEOMETRY`` / ``NOT_CONVERGED`` flags, (n,)."""
    normal: Sym
    """``JᵀJ`` over the beacons used at the final point, each (n,)."""
    cost: Array
    """Residual sum of squares at the final point, (n,), m²."""


def fit(
    problem: RangeProblem,
    used: NDArray[np.bool_],
    options: SolverOptions,
    start: Vector | None = None,
) -> Fit:
    """Fit positions by Gauss–Newton least squares over the beacons ``used``.

    Starts from the closed-form linearised solution unless ``start`` is given; fixes that
    have not converged after ``options.iterations`` get up to ``options.max_iterations``
    (safeguarded Newton, see :func:`gauss_newton`).
    """
    weight = problem.weight(used)
    n = used.shape[1]
    reason = np.zeros(n, dtype=np.uint16)
    if start is None:
        every = bool(used.all())
        start, spread = linear_init(problem, None if every else weight)
        with np.errstate(invalid="ignore"):
            singular = ~(spread > SINGULAR_FLATNESS)
        start = tuple(np.where(singular, 0.0, s) for s in start)
    else:
        singular = np.zeros(n, dtype=bool)
    result = _run_gauss_newton(problem, weight, start, options)
    with np.errstate(invalid="ignore"):
        if result.normal:
            singular |= ~(flatness(result.normal) > SINGULAR_FLATNESS)
        else:
            singular[:] = True
    reason[singular] |= np.uint16(FixReason.SINGULAR_GEOMETRY)
    not_converged = ~(result.error_m < options.tolerance_m) & ~singular
    reason[not_converged] |= np.uint16(FixReason.NOT_CONVERGED)
    return Fit(result.point, reason, result.normal, result.cost)


@lru_cache(maxsize=1)
def compiled_available() -> bool:
    """True if the compiled Gauss–Newton can run (numba imports)."""
    try:
        import omnical.ips.solve._compiled  # noqa: F401
    except ImportError:
        return False
    return True


def use_compiled(engine: str) -> bool:
    """Whether ``engine`` runs the compiled Gauss–Newton.

    ``"auto"`` takes it only when numba is already imported in this process: importing numba
    and initialising its compiler costs about 0.5 s of CPU (it imports ``scipy.linalg``),
    which a single ``omnical locate`` does not earn back (on the 60-minute synthetic bag the
    compiled solver saves 0.6–0.8 s, on a one-hedgehog 80-minute run nothing; see
    :mod:`omnical.ips.solve._compiled`), while a process that already runs numba (the twin, a
    test session, a notebook) gets the faster solver for free.
    """
    if engine == "numpy":
        return False
    if engine == "compiled":
        if not compiled_available():
            msg = "SolverOptions: engine='compiled' needs numba; install it or use engine='numpy'"
            raise ConfigError(msg)
        return True
    return "numba" in sys.modules and compiled_available()


def _run_gauss_newton(
    problem: RangeProblem, weight: Array | None, start: Vector, options: SolverOptions
) -> GaussNewtonResult:
    # A single fix stays with numpy: its einsum sums one column over the beacons in another
    # order (SIMD lanes) than for two or more, and the compiled kernel follows the latter.
    if problem.distance.shape[1] < 2 or not use_compiled(options.engine):
        return gauss_newton(
            problem,
            weight,
            start,
            iterations=options.iterations,
            max_iterations=options.max_iterations,
            tolerance_m=options.tolerance_m,
        )
    # imported here: numba costs ~0.4 s to import, and importing omnical.ips must stay cheap
    from omnical.ips.solve._compiled import gauss_newton_arrays

    m, n = problem.distance.shape
    weight_given = weight
    if weight is None:
        weight = np.ones((m, 1))  # products by 1 are exact: the same sums as without weights
    point, error_m, normal, cost, single = gauss_newton_arrays(
        np.hstack(problem.beacon).T,
        problem.distance,
        problem.offset_sq,
        weight,
        np.vstack([np.broadcast_to(s, (n,)) for s in start]),
        iterations=options.iterations,
        max_iterations=options.max_iterations,
        tolerance_m=options.tolerance_m,
    )
    if single.size:
        sub = safeguarded_steps(
            problem.take(single),
            None if weight_given is None else weight_given[:, single],
            tuple(p[single] for p in point),
            options.max_iterations - options.iterations,
            options.tolerance_m,
        )
        for target, source in zip(
            (*point, *normal, error_m, cost),
            (*sub.point, *sub.normal, sub.error_m, sub.cost),
            strict=True,
        ):
            target[single] = source
    return GaussNewtonResult(tuple(point), error_m, tuple(normal), cost)
