"""Learn a recording's range noise model from its own residuals (no ground truth).

Used by :func:`omnical.ips.solve.locate.solve_self_calibrated` between passes: :func:`learn_sigma`
(σ per link), :func:`learn_links` (bias and scale per link). Method: docs/locate.md.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from omnical.ips.beacons import BeaconMap
from omnical.ips.solve._kernels import inverse_stack
from omnical.ips.solve.fixes import Fixes, FixStatus
from omnical.ips.solve.noise_model import NoiseModel, NoiseSource

__all__ = ["MAX_LEARNING_FIXES", "MIN_SCALE_SPREAD_M", "learn_links", "learn_sigma"]

Array = NDArray[np.float64]

MIN_SCALE_SPREAD_M = 1.0
"""Spread (10th to 90th percentile) of a link's ranges needed to estimate its scale, m."""
MIN_SIGMA_M = 0.002
"""Floor of a learned σ, metres (ranges are quantised to 1 mm–1 cm)."""
MIN_RESIDUALS = 30
"""Fewest residuals a link needs for its own σ (else it takes the pooled σ)."""
MIN_CALIBRATION_FIXES = 50
"""Fewest redundant usable fixes needed to learn anything."""
MAX_LEARNING_FIXES = 4_096
"""Most usable fixes of a hedgehog the learning reads (evenly spread over the run)."""
_MAX_FIXES = MAX_LEARNING_FIXES
_MAX_LEVERAGE = 0.9
_PRIOR_BIAS_SD_M = 0.5
_PRIOR_SCALE_SD = 0.1
_OBSERVABLE_FRACTION = 1.0 / 3.0
SIGNIFICANCE = 3.0
"""A bias or scale is applied only when it differs from none by this many standard deviations
(of the estimate with the fix positions free) and exceeds :data:`MIN_BIAS_M` or
:data:`MIN_SCALE_ERROR`."""
MIN_BIAS_M = 0.005
"""Smallest bias applied, metres (a quarter of a typical σ)."""
MIN_SCALE_ERROR = 0.001
"""Smallest scale error ``|scale − 1|`` applied."""
_HUBER_K = 2.0
_TRIM_K = 3.0
_MAD = 1.482602218505602


@dataclasses.dataclass(frozen=True, eq=False)
class _Linearised:
    """Residuals and Jacobians of the usable redundant fixes, (f, m) and (f, m, dims)."""

    residual: Array
    rho: Array
    jacobian: Array
    used: NDArray[np.bool_]


def usable_rows(fixes: Fixes) -> NDArray[np.intp]:
    """Rows of the usable fixes with more ranges than unknowns (at most MAX_LEARNING_FIXES, evenly spread)."""
    usable = (fixes.status <= FixStatus.DEGRADED) & np.all(
        np.isfinite(fixes.positions_map_m[:, :2]), axis=1
    )
    usable &= fixes.n_used > fixes.dims
    rows = np.flatnonzero(usable)
    if rows.size > _MAX_FIXES:
        rows = rows[np.linspace(0, rows.size - 1, _MAX_FIXES).astype(np.intp)]
    return rows


def linearise(
    fixes: Fixes, corrected_m: Array, beacons: BeaconMap, rows: NDArray[np.intp]
) -> _Linearised:
    """Residuals ``ρ(p) − d`` and range Jacobians of ``rows`` at their solved positions."""
    dims = fixes.dims
    p = fixes.positions_map_m[rows]
    b = beacons.positions_m
    delta = p[:, None, :] - b[None, :, :]  # (f, m, 3); in 2D z is the known hedge height
    rho = np.sqrt(np.sum(delta * delta, axis=2))
    with np.errstate(divide="ignore", invalid="ignore"):
        jacobian = delta[:, :, :dims] / rho[:, :, None]
        residual = rho - corrected_m[rows]
    used = fixes.used[rows] & np.isfinite(residual)
    return _Linearised(np.where(used, residual, 0.0), rho, np.nan_to_num(jacobian), used)


def linearised_usable(fixes: Fixes, corrected_m: Array, beacons: BeaconMap) -> _Linearised:
    """:func:`linearise` of the :func:`usable_rows` of ``fixes``."""
    return linearise(fixes, corrected_m, beacons, usable_rows(fixes))


def _weighted_gain(lin: _Linearised, weight: Array) -> tuple[Array, Array, NDArray[np.bool_]]:
    """``W J`` (f, m, dims), ``(JᵀWJ)⁻¹`` (0 where singular) and where it is regular (f,)."""
    j = lin.jacobian
    wj = weight[:, :, None] * j
    normal = np.einsum("fmi,fmj->fij", wj, j)
    inverse, good = inverse_stack(normal, 0.0)
    return wj, inverse, good


def _projector(lin: _Linearised, weight: Array) -> Array:
    """``M = W − W J (JᵀWJ)⁻¹ JᵀW`` per fix (f, m, m); 0 where ``JᵀWJ`` is singular."""
    wj, inverse, good = _weighted_gain(lin, weight)
    projector: Array = -np.matmul(np.matmul(wj, inverse), np.swapaxes(wj, 1, 2))
    idx = np.arange(weight.shape[1])
    projector[:, idx, idx] += weight
    projector[~good] = 0.0
    return projector


def _leverage(lin: _Linearised, weight: Array) -> Array:
    """The leverages ``h_ii`` (f, m): the diagonal of ``W J (JᵀWJ)⁻¹ JᵀW`` over ``W``.

    1 where the range is unused or ``JᵀWJ`` is singular.
    """
    wj, inverse, good = _weighted_gain(lin, weight)
    diagonal = np.einsum("fmi,fij,fmj->fm", wj, inverse, wj)
    with np.errstate(divide="ignore", invalid="ignore"):
        leverage: Array = np.where(weight > 0.0, diagonal / weight, 1.0)
    leverage[~good] = 1.0
    return leverage


def _normal_equations(projector: Array, error: Array, rho: Array) -> tuple[Array, Array]:
    """Normal matrix (2m, 2m) and right-hand side (2m,) of the biases and scales."""
    me = np.einsum("fmk,fk->fm", projector, error)
    g_bb = projector.sum(axis=0)
    g_bs = np.einsum("fmk,fk->mk", projector, rho)
    g_ss = np.einsum("fmk,fk->mk", projector * rho[:, :, None], rho)
    normal = np.block([[g_bb, g_bs], [g_bs.T, g_ss]])
    rhs = np.concatenate([me.sum(axis=0), (rho * me).sum(axis=0)])
    return normal, rhs


def _held_normal_equations(weight: Array, error: Array, rho: Array) -> tuple[Array, Array]:
    """:func:`_normal_equations` with the positions held (projector ``diag(w)``, not built):
    the same sums in the same order."""
    me = weight * error
    normal = np.block(
        [
            [np.diag(weight.sum(axis=0)), np.diag((weight * rho).sum(axis=0))],
            [np.diag((weight * rho).sum(axis=0)), np.diag((weight * rho * rho).sum(axis=0))],
        ]
    )
    rhs = np.concatenate([me.sum(axis=0), (rho * me).sum(axis=0)])
    return normal, rhs


def _column_medians(values: Array, mask: NDArray[np.bool_]) -> Array:
    """``np.median(values[mask[:, k], k])`` for every column k at once, by one sort (NaN where
    none; the mean of two middle values as ``np.median`` computes it, ``(a + b) / 2``)."""
    ordered = np.sort(np.where(mask, values, np.inf), axis=0)
    count = mask.sum(axis=0)
    columns = np.arange(values.shape[1])
    high = ordered[np.minimum(count // 2, values.shape[0] - 1), columns]
    low = ordered[np.maximum((count - 1) // 2, 0), columns]
    with np.errstate(invalid="ignore"):
        median: Array = np.where(count % 2 == 1, high, (low + high) / 2.0)
    return np.where(count > 0, median, np.nan)


def _column_spreads(values: Array, mask: NDArray[np.bool_]) -> Array:
    """90th minus 10th percentile (linear) of ``values[mask[:, k], k]`` per column (0 if none)."""
    ordered = np.sort(np.where(mask, values, np.inf), axis=0)
    count = mask.sum(axis=0)
    columns = np.arange(values.shape[1])

    def percentile(q: float) -> Array:
        virtual = q * np.maximum(count - 1, 0)
        below = np.floor(virtual).astype(np.intp)
        above = np.minimum(below + 1, np.maximum(count - 1, 0))
        t = virtual - below
        a = ordered[below, columns]
        b = ordered[above, columns]
        with np.errstate(invalid="ignore"):
            result: Array = np.where(t >= 0.5, b - (b - a) * (1.0 - t), a + (b - a) * t)
        return result

    spread = percentile(0.9) - percentile(0.1)
    result: Array = np.where(count > 0, spread, 0.0)
    return result


def learn_sigma(
    fixes: Fixes,
    corrected_m: Array,
    beacons: BeaconMap,
    model: NoiseModel,
    *,
    floor_m: float = MIN_SIGMA_M,
    linearised: _Linearised | None = None,
) -> NoiseModel:
    """Return ``model`` with σ per link learned from the residuals of ``fixes``.

    Args:
        fixes: A solve of ``corrected_m`` (usable redundant fixes are used).
        corrected_m: The distances that were solved, (n, m), metres.
        beacons: The map.
        model: The model whose σ is replaced (bias and scale are kept).
        floor_m: Smallest σ returned, metres.
        linearised: :func:`linearised_usable` of the same ``fixes`` and ``corrected_m``,
            when already computed (it does not depend on ``model``).

    Returns:
        ``model`` unchanged when fewer than :data:`MIN_CALIBRATION_FIXES` fixes are usable.
    """
    lin = linearised if linearised is not None else linearised_usable(fixes, corrected_m, beacons)
    if lin.used.shape[0] < MIN_CALIBRATION_FIXES:
        return model
    weight = np.where(lin.used, 1.0 / model.sigma_m**2, 0.0)
    leverage = _leverage(lin, weight)
    good = lin.used & (leverage < _MAX_LEVERAGE)
    with np.errstate(invalid="ignore", divide="ignore"):
        standard = np.abs(lin.residual) / np.sqrt(1.0 - leverage)
    counts = good.sum(axis=0)
    if counts.sum() < MIN_RESIDUALS:
        return model
    pooled = _MAD * float(np.median(standard[good]))
    own = counts >= MIN_RESIDUALS
    sigma = np.where(own, _MAD * _column_medians(standard, good), pooled)
    sigma = np.maximum(sigma, floor_m)
    return dataclasses.replace(
        model, sigma_m=sigma, n_residuals=counts.astype(np.int64), source=NoiseSource.LEARNED
    )


def learn_links(
    fixes: Fixes,
    corrected_m: Array,
    beacons: BeaconMap,
    model: NoiseModel,
    *,
    joint: bool,
    linearised: _Linearised | None = None,
) -> NoiseModel:
    """Return ``model`` with its per-link bias and scale refined from the residuals of ``fixes``.

    One Gauss–Newton step from ``model``'s bias and scale. ``joint``: biases only, every
    link at once with each fix's position eliminated (for large errors). Otherwise: bias and
    scale per link by a regression of its residuals on its ranges, positions held (for small
    errors). A parameter that is not significant (:data:`SIGNIFICANCE`) is set back to none:
    bias 0, scale 1, standard deviation NaN.

    Args:
        fixes: A solve of ``corrected_m = model.correct(raw)``.
        corrected_m: The distances that were solved, (n, m), metres.
        beacons: The map.
        model: The current model (its σ weights the residuals).
        linearised: :func:`linearised_usable` of the same ``fixes`` and ``corrected_m``,
            when already computed (it does not depend on ``model``).
    """
    lin = linearised if linearised is not None else linearised_usable(fixes, corrected_m, beacons)
    if lin.used.shape[0] < MIN_CALIBRATION_FIXES:
        return model
    m = beacons.positions_m.shape[0]
    sigma = model.sigma_m
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.abs(lin.residual) / sigma
        robust = np.where(z > _TRIM_K, 0.0, np.where(z > _HUBER_K, _HUBER_K / z, 1.0))
    weight = np.where(lin.used, robust / sigma**2, 0.0)
    projector = _projector(lin, weight)
    counts = lin.used.sum(axis=0)
    with_bias = counts >= MIN_RESIDUALS
    if joint:  # biases only: the spread of the ranges is not needed
        with_scale = np.zeros(m, dtype=bool)
    else:
        spread = _column_spreads(lin.rho, lin.used)
        with_scale = with_bias & (spread >= MIN_SCALE_SPREAD_M)
    # Model: −r = β + γ ρ + J δp per range (β, γ: relative increments of bias and scale).
    rho = np.where(lin.used, lin.rho, 0.0)
    normal, rhs = _normal_equations(projector, -lin.residual, rho)
    normal_step, rhs_step = (
        (normal, rhs) if joint else _held_normal_equations(weight, -lin.residual, rho)
    )
    prior_sd = np.concatenate([np.full(m, _PRIOR_BIAS_SD_M), np.full(m, _PRIOR_SCALE_SD)])
    # The step that takes each parameter back to no correction (bias 0, scale 1).
    null = np.concatenate([-model.bias_m / model.scale, 1.0 / model.scale - 1.0])
    minimum = np.concatenate([np.full(m, MIN_BIAS_M), np.full(m, MIN_SCALE_ERROR)]) / np.tile(
        model.scale, 2
    )
    active = np.concatenate([with_bias, with_scale])
    beta = null.copy()
    deviation = np.full(2 * m, np.nan)
    for _ in range(2 * m + 2):
        index = np.flatnonzero(active)
        if index.size == 0:
            break
        fixed = np.flatnonzero(~active)
        prior = np.diag(1.0 / prior_sd[index] ** 2)
        try:
            covariance = np.linalg.inv(normal[np.ix_(index, index)] + prior)
            covariance_step = np.linalg.inv(normal_step[np.ix_(index, index)] + prior)
        except np.linalg.LinAlgError:
            return model
        sd = np.sqrt(np.maximum(np.diag(covariance), 0.0))
        observable = sd < _OBSERVABLE_FRACTION * prior_sd[index]
        if not np.all(observable):
            active[index[~observable]] = False
            continue
        step = covariance_step @ (rhs_step[index] - normal_step[np.ix_(index, fixed)] @ null[fixed])
        size = np.abs(step - null[index])
        with np.errstate(divide="ignore", invalid="ignore"):  # sd = 0: exactly determined
            significance = size / sd
        weak = (significance < SIGNIFICANCE) | (size < minimum[index])
        if not np.any(weak):
            beta[index] = step
            deviation[index] = sd
            break
        active[index[np.argmin(np.where(weak, significance, np.inf))]] = False
    else:
        return model
    scale = model.scale * (1.0 + beta[m:])
    bias = model.bias_m + model.scale * beta[:m]
    return dataclasses.replace(
        model,
        bias_m=bias,
        scale=scale,
        bias_sd_m=np.where(active[:m], deviation[:m] * model.scale, np.nan),
        scale_sd=np.where(active[m:], deviation[m:] * model.scale, np.nan),
    )
