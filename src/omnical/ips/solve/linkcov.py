"""Systematic range errors learned from a whole recording, and the fix covariances they give.

:func:`learn_link_covariance` learns Σ, :func:`link_covariances` carries Σ and the
calibration's uncertainty Γ into each fix: docs/locate.md.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
from numpy.typing import NDArray

from omnical.ips.beacons import BeaconMap
from omnical.ips.solve._kernels import inverse_stack
from omnical.ips.solve.fixes import Fixes
from omnical.ips.solve.noise_model import NoiseModel
from omnical.ips.solve.selfcal import (
    MIN_CALIBRATION_FIXES,
    linearise,
    usable_rows,
)

__all__ = [
    "JACKKNIFE_BLOCKS",
    "SIGNIFICANCE",
    "learn_link_covariance",
    "link_covariances",
    "loewner_max",
]

Array = NDArray[np.float64]

JACKKNIFE_BLOCKS = 20
"""Contiguous blocks of fixes (in time) for the held-out test, the jackknives of the widening
and of the calibration."""
SIGNIFICANCE = 3.0
"""Standard errors by which the link covariance must widen the ellipses (on average), or
predict the held-out blocks' residuals better than independent errors do, to be applied."""
_PRIOR_SD = 1.0
"""Prior standard deviation of each element of Σ in units of σ_i σ_j (about diag(σ²))."""
_PRIOR_BIAS_SD_M = 0.5
_PRIOR_SCALE_SD = 0.1
"""Prior of the bias and scale in the calibration's jackknife (the self-calibration's own)."""


def _gains(jacobian: Array, weight: Array) -> Array:
    """``G = (JᵀWJ)⁻¹JᵀW`` per fix, shape (f, dims, m); NaN where JᵀWJ is singular."""
    wj_t = np.swapaxes(weight[:, :, None] * jacobian, 1, 2)  # (JW)ᵀ per fix: (f, dims, m)
    inverse, _ = inverse_stack(np.matmul(wj_t, jacobian), np.nan)
    gains: Array = np.matmul(inverse, wj_t)
    return gains


def _calibration_gains(gains: Array, rho: Array) -> Array:
    """``G H`` per fix, (f, dims, 2m): how the bias and scale errors ``(β, γ)`` of the links
    move the fix, the range errors being ``H (β, γ) = β + γ ρ``."""
    calibration: Array = np.concatenate([gains, gains * rho[:, None, :]], axis=2)
    return calibration


def _duplication(m: int) -> tuple[tuple[NDArray[np.intp], NDArray[np.intp]], Array]:
    """Upper-triangle indices of an m×m symmetric matrix and the matrix D with vec(S) = D s."""
    upper = np.triu_indices(m)
    dup = np.zeros((m * m, upper[0].size))
    k = np.arange(upper[0].size)
    dup[upper[0] * m + upper[1], k] = 1.0
    dup[upper[1] * m + upper[0], k] = 1.0
    return upper, dup


def _psd(matrix: Array) -> Array:
    """The nearest positive semi-definite matrices (negative eigenvalues set to 0), (..., m, m)."""
    values, vectors = np.linalg.eigh(0.5 * (matrix + np.swapaxes(matrix, -1, -2)))
    result: Array = (vectors * np.maximum(values, 0.0)[..., None, :]) @ np.swapaxes(vectors, -1, -2)
    return result


@dataclasses.dataclass(frozen=True, eq=False)
class _Moments:
    """Per block: normal matrix and right-hand side of vech(Σ̃) (standardised units) and of
    the links' bias and scale errors (positions eliminated)."""

    normals: list[Array]
    rhs: list[Array]
    upper: tuple[NDArray[np.intp], NDArray[np.intp]]
    gains_std: Array
    """Gains in standardised units, G·diag(σ), (f, dims, m)."""
    calibration_normals: list[Array]
    calibration_rhs: list[Array]
    calibration_gains: Array
    """``G H`` of the fixes, (f, dims, 2m); the calibration's only where the model has one."""


def _moments(fixes: Fixes, corrected_m: Array, beacons: BeaconMap, model: NoiseModel) -> _Moments:
    rows = usable_rows(fixes)
    lin = linearise(fixes, corrected_m, beacons, rows)
    sigma = model.sigma_m
    m = sigma.size
    used = lin.used
    weight = np.where(used, 1.0 / sigma**2, 0.0)
    gains = _gains(lin.jacobian, weight)
    keep = np.all(np.isfinite(gains), axis=(1, 2))
    gains, used, jacobian, residual, weight = (
        gains[keep],
        used[keep],
        lin.jacobian[keep],
        lin.residual[keep],
        weight[keep],
    )
    rho = np.where(used, lin.rho[keep], 0.0)
    del lin
    upper, dup = _duplication(m)
    edges = np.linspace(0, gains.shape[0], JACKKNIFE_BLOCKS + 1).astype(np.intp)
    normals, rhs, cal_normals, cal_rhs = [], [], [], []
    for lo, hi in itertools.pairwise(edges):  # a block at a time: (f, m, m) for one block only
        block = slice(lo, hi)
        projector = _projector(gains[block], used[block], jacobian[block])
        q, u = _block_moments(projector, residual[block], sigma)
        flat = q.reshape(-1, m * m)  # columns (i, k)
        n4 = (flat.T @ flat).reshape(m, m, m, m).transpose(0, 2, 1, 3).reshape(m * m, m * m)
        normals.append(dup.T @ n4 @ dup)
        rhs.append(dup.T @ (u.T @ u).reshape(-1))
        if model.calibrated:  # the calibration's jackknife: only of what the run learned
            normal, right = _calibration_equations(
                projector, weight[block], residual[block], rho[block]
            )
            cal_normals.append(normal)
            cal_rhs.append(right)
    return _Moments(
        normals,
        rhs,
        upper,
        gains * sigma[None, None, :],
        cal_normals,
        cal_rhs,
        _calibration_gains(gains, rho) if model.calibrated else np.zeros((0, 0, 0)),
    )


def _projector(gains: Array, used: NDArray[np.bool_], jacobian: Array) -> Array:
    """``P = I − J G`` of some fixes (f, m, m), zero in the rows and columns of unused links."""
    m = used.shape[1]
    projector: Array = -np.matmul(jacobian, gains)
    idx = np.arange(m)
    projector[:, idx, idx] += 1.0
    projector *= used[:, :, None] & used[:, None, :]
    return projector


def _block_moments(projector: Array, residual: Array, sigma: Array) -> tuple[Array, Array]:
    """``P̃ᵀP̃`` (f, m, m) and ``P̃ᵀr̃`` (f, m) of some fixes (standardised units)."""
    # Standardised: r̃ = r/σ, P̃ = diag(σ)⁻¹ P diag(σ), Σ̃ = diag(σ)⁻¹ Σ diag(σ)⁻¹.
    p_std = projector * sigma[None, None, :] / sigma[None, :, None]
    r_std = residual / sigma
    q: Array = np.matmul(np.swapaxes(p_std, 1, 2), p_std)  # P̃ᵀP̃
    u: Array = np.matmul(r_std[:, None, :], p_std)[:, 0, :]  # P̃ᵀr̃
    return q, u


def _calibration_equations(
    projector: Array, weight: Array, residual: Array, rho: Array
) -> tuple[Array, Array]:
    """Normal matrix (2m, 2m) and right-hand side (2m,) of the links' bias and scale errors
    ``d − ρ = β + γ ρ`` with each fix's position eliminated: ``Σ Hᵀ M H`` and ``Σ Hᵀ M (−r)``,
    ``M = W P`` (the self-calibration's joint equations, at the learned calibration)."""
    weighted = weight[:, :, None] * projector  # W P: symmetric
    error = -np.einsum("fmk,fk->fm", weighted, residual)
    g_bb = weighted.sum(axis=0)
    g_bs = np.einsum("fmk,fk->mk", weighted, rho)
    g_ss = np.einsum("fmk,fm,fk->mk", weighted, rho, rho)
    normal = np.block([[g_bb, g_bs], [g_bs.T, g_ss]])
    right = np.concatenate([error.sum(axis=0), (rho * error).sum(axis=0)])
    return normal, right


def _solve(normal: Array, rhs: Array, upper: tuple[NDArray[np.intp], NDArray[np.intp]]) -> Array:
    """Σ̃ (m×m, positive semi-definite) from the moments, with the prior diag(1) ± 1; stacked:
    ``normal`` (..., p, p) and ``rhs`` (..., p) give (..., m, m)."""
    m = int(upper[0].max()) + 1
    prior = np.eye(m)[upper]
    regular = normal + np.eye(prior.size) / _PRIOR_SD**2
    s = prior + np.linalg.solve(regular, (rhs - normal @ prior)[..., None])[..., 0]
    matrix = np.zeros((*s.shape[:-1], m, m))
    matrix[..., upper[0], upper[1]] = s
    diagonal = np.diagonal(matrix, axis1=-2, axis2=-1)
    full = matrix + np.swapaxes(matrix, -1, -2)
    full[..., np.arange(m), np.arange(m)] -= diagonal
    return _psd(full)


def _sensitivity(gains_std: Array) -> tuple[Array, Array]:
    """``A = Σ_f G_fᵀ C_indep,f⁻¹ G_f`` (m, m, standardised units), shared by every
    :func:`_widening` call (``Σ_f tr(C_indep,f⁻¹ G_f Σ G_fᵀ) = Σ_mk Σ_mk A_km``: O(m²) each),
    and the ``C_indep,f⁻¹`` (f, dims, dims)."""
    inverse = np.linalg.inv(np.matmul(gains_std, np.swapaxes(gains_std, 1, 2)))
    sensitivity: Array = np.einsum("fim,fik->mk", np.matmul(inverse, gains_std), gains_std)
    return sensitivity, inverse


def _widening(sensitivity: Array, sigma_std: Array, count: int, dims: int) -> Array:
    """Average ``tr(C_indep⁻¹ C_Σ) / dims`` over the ``count`` fixes (standardised units), for
    one Σ̃ (m, m) or a stack of them (k, m, m)."""
    total: Array = np.sum(sigma_std * sensitivity.T, axis=(-2, -1))
    return total / count / dims


def _held_out_z(moments: _Moments, left_out: Array) -> float:
    """How many standard errors better the Σ̃ learned without each block predicts that block's
    residual moments than independent errors (Σ̃ = I) do (blocked cross-validation of the
    moment fit ``Σ_f ‖P̃ᵀ(r̃r̃ᵀ − P̃Σ̃P̃ᵀ)P̃‖²``); 0 when it cannot be told."""
    m = left_out.shape[-1]
    upper = moments.upper
    normals, rhs = np.stack(moments.normals), np.stack(moments.rhs)
    learned = left_out[:, upper[0], upper[1]]
    independent = np.broadcast_to(np.eye(m)[upper], learned.shape)

    def loss(s: Array) -> Array:
        quadratic: Array = np.einsum("bi,bij,bj->b", s, normals, s) - 2.0 * np.sum(s * rhs, -1)
        return quadratic

    gain = loss(independent) - loss(learned)
    spread = float(np.std(gain, ddof=1))
    if not spread > 0.0:
        return 0.0
    return float(np.mean(gain) / (spread / np.sqrt(gain.size)))


def _calibration_covariance(moments: _Moments) -> Array:
    """Γ: the block jackknife covariance (2m, 2m) of the links' bias and scale errors, each
    estimate leaving one block of the run out (positions eliminated, the self-calibration's
    prior)."""
    m = moments.gains_std.shape[2]
    prior = np.diag(
        np.concatenate([np.full(m, _PRIOR_BIAS_SD_M**-2), np.full(m, _PRIOR_SCALE_SD**-2)])
    )
    normals, rhs = np.stack(moments.calibration_normals), np.stack(moments.calibration_rhs)
    left_out = np.linalg.solve(
        normals.sum(axis=0) - normals + prior, (rhs.sum(axis=0) - rhs)[..., None]
    )[..., 0]
    k = left_out.shape[0]
    deviation = left_out - left_out.mean(axis=0)
    covariance: Array = (k - 1) / k * (deviation.T @ deviation)
    return covariance


def learn_link_covariance(
    fixes: Fixes, corrected_m: Array, beacons: BeaconMap, model: NoiseModel
) -> NoiseModel:
    """Return ``model`` with the link-error covariance Σ (when the link errors are found not
    independent) and the covariance Γ of its self-calibration (when it has one).

    Method: docs/locate.md. ``widening`` (and its standard error), ``link_covariance_z``,
    ``calibration_covariance`` and ``calibration_widening`` are filled in when measurable;
    ``link_covariance_m2`` only when Σ widens the ellipses by :data:`SIGNIFICANCE` jackknife
    standard errors on average, or predicts held-out blocks that much better than
    independent errors.

    Args:
        fixes: The final solve of ``corrected_m`` with ``model``'s σ.
        corrected_m: The distances that were solved, (n, m), metres.
        beacons: The map.
        model: The learned model (σ, bias and scale per link).
    """
    if usable_rows(fixes).size < max(MIN_CALIBRATION_FIXES, 2 * JACKKNIFE_BLOCKS):
        return model
    moments = _moments(fixes, corrected_m, beacons, model)
    if moments.gains_std.shape[0] < max(MIN_CALIBRATION_FIXES, 2 * JACKKNIFE_BLOCKS):
        return model
    normal, rhs = sum(moments.normals), sum(moments.rhs)
    assert isinstance(normal, np.ndarray) and isinstance(rhs, np.ndarray)
    sigma_std = _solve(normal, rhs, moments.upper)
    sensitivity, inverse = _sensitivity(moments.gains_std)
    count, dims = moments.gains_std.shape[:2]
    kappa = float(_widening(sensitivity, sigma_std, count, dims))
    left_out = _solve(
        normal - np.stack(moments.normals), rhs - np.stack(moments.rhs), moments.upper
    )
    leave_out = _widening(sensitivity, left_out, count, dims)
    k = JACKKNIFE_BLOCKS
    se = float(np.sqrt((k - 1) / k * np.sum((leave_out - leave_out.mean()) ** 2)))
    z = _held_out_z(moments, left_out)
    significant = kappa - 1.0 > SIGNIFICANCE * se or z > SIGNIFICANCE
    covariance = sigma_std * np.outer(model.sigma_m, model.sigma_m) if significant else None
    gamma, calibration_widening = None, float("nan")
    if model.calibrated:  # ranges corrected by what the run learned: that is uncertain
        gamma = _calibration_covariance(moments)
        gains = moments.calibration_gains
        spread = np.matmul(np.matmul(gains, gamma), np.swapaxes(gains, 1, 2))
        calibration_widening = float(np.mean(np.einsum("fij,fji->f", inverse, spread)) / dims)
    return dataclasses.replace(
        model,
        link_covariance_m2=covariance,
        widening=kappa,
        widening_sd=se,
        link_covariance_z=z,
        calibration_covariance=gamma,
        calibration_widening=calibration_widening,
    )


def loewner_max(a: Array, b: Array) -> Array:
    """Per row a 2×2 covariance at least ``a`` and at least ``b`` in every direction, (n, 2, 2).

    ``b`` is whitened by ``a`` (Cholesky), its eigenvalues raised to at least 1, and the result
    coloured back: the smallest such matrix sharing the whitened eigenvectors of ``b``.
    """
    lower = np.linalg.cholesky(a)
    inverse = np.linalg.inv(lower)
    whitened = inverse @ b @ np.swapaxes(inverse, 1, 2)
    values, vectors = np.linalg.eigh(whitened)
    raised = (vectors * np.maximum(values, 1.0)[:, None, :]) @ np.swapaxes(vectors, 1, 2)
    result: Array = lower @ raised @ np.swapaxes(lower, 1, 2)
    return result


def link_covariances(
    fixes: Fixes, corrected_m: Array, beacons: BeaconMap, model: NoiseModel
) -> Array:
    """The horizontal covariance of each fix under the model's systematic errors, (n, 2, 2), m².

    ``G Σ Gᵀ`` (Σ the link covariance, else diag(σ²)) times the fix's residual variance factor
    ``max(1, Σ r²/σ² / dof)``, plus ``(GH) Γ (GH)ᵀ`` (the calibration's uncertainty), never
    tighter than the fix's own covariance; the fix's own covariance where the model has
    neither or the fix has no finite position or covariance.
    """
    out: Array = fixes.covariance_xy_m2.copy()
    if model.link_covariance_m2 is None and model.calibration_covariance is None:
        return out
    position = fixes.positions_map_m
    finite = np.all(np.isfinite(position[:, :2]), axis=1) & np.all(
        np.isfinite(out.reshape(-1, 4)), axis=1
    )
    rows = np.flatnonzero(finite)
    for lo in range(0, rows.size, _CHUNK):  # each fix on its own: a chunk at a time
        _widen_rows(fixes, corrected_m, beacons, model, rows[lo : lo + _CHUNK], out)
    return out


_CHUNK = 8192
"""Fixes :func:`link_covariances` linearises at a time."""


def _widen_rows(
    fixes: Fixes,
    corrected_m: Array,
    beacons: BeaconMap,
    model: NoiseModel,
    rows: NDArray[np.intp],
    out: Array,
) -> None:
    """:func:`link_covariances` of ``rows``, written into ``out``."""
    lin = linearise(fixes, corrected_m, beacons, rows)
    used = lin.used
    weight = np.where(used, 1.0 / model.sigma_m**2, 0.0)
    gains = _gains(lin.jacobian, weight)
    sigma_e = model.link_covariance_m2
    if sigma_e is None:
        sigma_e = np.diag(model.sigma_m**2)
    covariance = np.matmul(np.matmul(gains, sigma_e), np.swapaxes(gains, 1, 2))
    dof = np.maximum(used.sum(axis=1) - fixes.dims, 1)
    factor = np.sum(np.where(used, lin.residual**2, 0.0) * weight, axis=1) / dof
    covariance *= np.maximum(factor, 1.0)[:, None, None]
    gamma = model.calibration_covariance
    if gamma is not None:
        calibration = _calibration_gains(gains, np.where(used, lin.rho, 0.0))
        covariance += np.matmul(np.matmul(calibration, gamma), np.swapaxes(calibration, 1, 2))
    covariance = covariance[:, :2, :2]
    own = out[rows]
    good = np.all(np.isfinite(covariance.reshape(-1, 4)), axis=1)
    good &= (own[:, 0, 0] > 0.0) & (own[:, 0, 0] * own[:, 1, 1] - own[:, 0, 1] ** 2 > 0.0)
    out[rows[good]] = loewner_max(own[good], covariance[good])
