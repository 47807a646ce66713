"""Shared pieces of the solvers: options, per-chunk solution, Gauss–Newton fit, chi-square test."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from omnical.errors import ConfigError
from omnical.ips.solve._kernels import (
    Array,
    RangeProblem,
    Sym,
    Vector,
    flatness,
    gauss_newton,
    linear_init,
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
    """

    range_sigma_m: float = 0.02
    alpha: float = 0.01
    min_outlier_sigmas: float = 3.0
    iterations: int = 2
    max_iterations: int = 20
    tolerance_m: float = 1e-5
    grid_margin_m: float = 2.0
    grid_coarse_step_m: float = 0.1

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


_CHI2_KNOWN_DOF = 32
_CHI2_KNOWN: dict[float, tuple[str, ...]] = {
    0.01: (
        "0x1.a8a2255a6e927p+2",
        "0x1.26bb1bbb55515p+3",
        "0x1.6b0925f3ee5a4p+3",
        "0x1.a8dac2a1d7836p+3",
        "0x1.e2c2be7b5244ap+3",
        "0x1.0cfd84626b0b9p+4",
        "0x1.279adb6a3558dp+4",
        "0x1.41719a4955b70p+4",
        "0x1.5aa7e9ac98a51p+4",
        "0x1.735917be45becp+4",
        "0x1.8b997a781aed6p+4",
        "0x1.a378b2b5993e7p+4",
        "0x1.bb031206065d4p+4",
        "0x1.d24282815268dp+4",
        "0x1.e93f22eceb2c7p+4",
        "0x1.ffffb35bbc066p+4",
        "0x1.0b44f16c947b8p+5",
        "0x1.167144220eb75p+5",
        "0x1.2186e664e03f3p+5",
        "0x1.2c87a61a934c0p+5",
        "0x1.377516f3af68ap+5",
        "0x1.42509c3481c66p+5",
        "0x1.4d1b70791299dp+5",
        "0x1.57d6abf0f3d1dp+5",
        "0x1.6283496d8632bp+5",
        "0x1.6d222a8590c52p+5",
        "0x1.77b41b002dfc6p+5",
        "0x1.8239d3acf0a8dp+5",
        "0x1.8cb3fcc64769ap+5",
        "0x1.97232ff4988bdp+5",
        "0x1.a187fa03a9763p+5",
        "0x1.abe2dc582f970p+5",
    ),
    0.001: (
        "0x1.5a7b6c0cc8b77p+3",
        "0x1.ba18a998fffa0p+3",
        "0x1.044280e2bdaadp+4",
        "0x1.27781f89f9c47p+4",
        "0x1.483d769127450p+4",
        "0x1.6752ebe183fc7p+4",
        "0x1.8526724c912f6p+4",
        "0x1.a1fde05fe2e3fp+4",
        "0x1.be08de0833f3ep+4",
        "0x1.d969aba15e1dep+4",
        "0x1.f439e42ccb470p+4",
        "0x1.0746a2e81d1a4p+5",
        "0x1.1439b5e5fc0adp+5",
        "0x1.20fc76e94e240p+5",
        "0x1.2d9411169b1c3p+5",
        "0x1.3a04d296aab76p+5",
        "0x1.46525d2307318p+5",
        "0x1.527fc9a5dfa59p+5",
        "0x1.5e8fc2e6df4fdp+5",
        "0x1.6a8499dffb048p+5",
        "0x1.7660557b1163bp+5",
        "0x1.8224beed82d1dp+5",
        "0x1.8dd36b8b19ab8p+5",
        "0x1.996dc4abe7cb2p+5",
        "0x1.a4f50e166b84bp+5",
        "0x1.b06a6b41bc786p+5",
        "0x1.bbcee3ae7f497p+5",
        "0x1.c72366863937fp+5",
        "0x1.d268cda588bb2p+5",
        "0x1.dd9fe02d9417cp+5",
        "0x1.e8c954b2d9242p+5",
        "0x1.f3e5d31ae176ep+5",
    ),
}
"""``scipy.special.chdtri(dof, alpha)`` for dof 1–32 at the alphas ``locate`` uses, as exact
float hex (checked against scipy by ``tests/ips/test_chi2_quantiles.py``), to spare the import."""


@lru_cache(maxsize=64)
def _chi2_table(alpha: float, size: int) -> Array:
    table = np.full(size + 1, np.inf)
    known = _CHI2_KNOWN.get(alpha)
    if known is not None and size <= _CHI2_KNOWN_DOF:
        table[1:] = [float.fromhex(h) for h in known[:size]]
        return table
    # imported here: importing omnical.ips must stay cheap
    from scipy.special import chdtri

    table[1:] = chdtri(np.arange(1, size + 1), alpha)  # = scipy.stats.chi2.isf(alpha, dof)
    return table


def chi2_quantile(dof: int, alpha: float) -> float:
    """Return the chi-square ``1 − alpha`` quantile for one ``dof`` ≥ 1."""
    return float(_chi2_table(alpha, max(dof, 1))[dof])


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
    result = gauss_newton(
        problem,
        weight,
        start,
        iterations=options.iterations,
        max_iterations=options.max_iterations,
        tolerance_m=options.tolerance_m,
    )
    with np.errstate(invalid="ignore"):
        if result.normal:
            singular |= ~(flatness(result.normal) > SINGULAR_FLATNESS)
        else:
            singular[:] = True
    reason[singular] |= np.uint16(FixReason.SINGULAR_GEOMETRY)
    not_converged = ~(result.error_m < options.tolerance_m) & ~singular
    reason[not_converged] |= np.uint16(FixReason.NOT_CONVERGED)
    return Fit(result.point, reason, result.normal, result.cost)
