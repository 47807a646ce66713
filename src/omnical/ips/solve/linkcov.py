"""Correlated range errors between links, learned from a recording, and the fix covariances they give.

The solver's covariance ``σ̂² (JᵀWJ)⁻¹`` assumes that the errors of the ranges of one fix are
independent. Real UWB ranges are not: their errors are systematic and depend on where the tag
is (multipath, antenna pattern), so neighbouring links err together, and a part of the error
that looks like a shift of the position leaves no trace in a fix's residuals. On the CUHK-SZ
run the ok fixes' 95 % ellipses held the truth for 80 % of them.

A single fix cannot see such errors, but the whole run can: the residuals ``r = P e`` of a fix
see the link errors ``e`` through its projector ``P = I − J G`` (``G = (JᵀWJ)⁻¹JᵀW``), which
changes as the tag moves, so a constant m×m covariance ``Σ`` of the link errors is observable
from ``E[r rᵀ] = P Σ Pᵀ`` over the run (method of moments on the usable redundant fixes, in units
of the learned σ per link, with a weak prior: ``Σ`` = diag(σ²) ± 1 per standardised element).
The fix covariance is then the sandwich ``G Σ Gᵀ`` (times the fix's own residual variance
factor when above 1, as the solver does).

:func:`learn_link_covariance` applies it only when it significantly widens the ellipses: the
average ratio ``κ = tr(C_indep⁻¹ C_Σ) / dims`` must exceed 1 by :data:`SIGNIFICANCE` standard
errors of a block jackknife over the run (:data:`JACKKNIFE_BLOCKS` contiguous blocks in time,
which also respects errors correlated in time). With four beacons in 2D the correlations are
poorly observable and the estimate is mostly noise (on the digital twin, independent errors,
``κ`` 1.0–1.8 at 0.3–0.6 standard errors from 1): nothing is applied there. On the CUHK-SZ run
(8 anchors) ``κ`` ≈ 2.1 at 3.2 standard errors. :func:`link_covariances` never returns a
covariance tighter than the independent-noise one in any direction.
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
"""Contiguous blocks of fixes the standard error of the widening is estimated from."""
SIGNIFICANCE = 3.0
"""Standard errors by which the average widening ``κ`` must exceed 1 to be applied."""
_PRIOR_SD = 1.0
"""Prior standard deviation of each element of Σ in units of σ_i σ_j (about diag(σ²))."""


def _gains(jacobian: Array, weight: Array) -> Array:
    """``G = (JᵀWJ)⁻¹JᵀW`` per fix, shape (f, dims, m); NaN where JᵀWJ is singular."""
    wj_t = np.swapaxes(weight[:, :, None] * jacobian, 1, 2)  # (JW)ᵀ per fix: (f, dims, m)
    inverse, _ = inverse_stack(np.matmul(wj_t, jacobian), np.nan)
    gains: Array = np.matmul(inverse, wj_t)
    return gains


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
    """Per block: normal matrix and right-hand side of vech(Σ̃) (standardised units)."""

    normals: list[Array]
    rhs: list[Array]
    upper: tuple[NDArray[np.intp], NDArray[np.intp]]
    gains_std: Array
    """Gains in standardised units, G·diag(σ), (f, dims, m)."""


def _moments(fixes: Fixes, corrected_m: Array, beacons: BeaconMap, model: NoiseModel) -> _Moments:
    rows = usable_rows(fixes)
    lin = linearise(fixes, corrected_m, beacons, rows)
    sigma = model.sigma_m
    m = sigma.size
    used = lin.used
    weight = np.where(used, 1.0 / sigma**2, 0.0)
    gains = _gains(lin.jacobian, weight)
    keep = np.all(np.isfinite(gains), axis=(1, 2))
    gains, used, jacobian, residual = (
        gains[keep],
        used[keep],
        lin.jacobian[keep],
        lin.residual[keep],
    )
    del lin, weight
    upper, dup = _duplication(m)
    edges = np.linspace(0, gains.shape[0], JACKKNIFE_BLOCKS + 1).astype(np.intp)
    normals, rhs = [], []
    for lo, hi in itertools.pairwise(edges):  # a block at a time: (f, m, m) for one block only
        q, u = _block_moments(gains[lo:hi], used[lo:hi], jacobian[lo:hi], residual[lo:hi], sigma)
        block = q.reshape(-1, m * m)  # columns (i, k)
        n4 = (block.T @ block).reshape(m, m, m, m).transpose(0, 2, 1, 3).reshape(m * m, m * m)
        normals.append(dup.T @ n4 @ dup)
        rhs.append(dup.T @ (u.T @ u).reshape(-1))
    return _Moments(normals, rhs, upper, gains * sigma[None, None, :])


def _block_moments(
    gains: Array, used: NDArray[np.bool_], jacobian: Array, residual: Array, sigma: Array
) -> tuple[Array, Array]:
    """``P̃ᵀP̃`` (f, m, m) and ``P̃ᵀr̃`` (f, m) of some fixes (standardised units)."""
    m = sigma.size
    projector = -np.matmul(jacobian, gains)
    idx = np.arange(m)
    projector[:, idx, idx] += 1.0
    projector *= used[:, :, None] & used[:, None, :]
    # Standardised: r̃ = r/σ, P̃ = diag(σ)⁻¹ P diag(σ), Σ̃ = diag(σ)⁻¹ Σ diag(σ)⁻¹.
    p_std = projector * sigma[None, None, :] / sigma[None, :, None]
    r_std = np.where(used, residual, 0.0) / sigma
    q: Array = np.matmul(np.swapaxes(p_std, 1, 2), p_std)  # P̃ᵀP̃
    u: Array = np.matmul(r_std[:, None, :], p_std)[:, 0, :]  # P̃ᵀr̃
    return q, u


def _solve(normal: Array, rhs: Array, upper: tuple[NDArray[np.intp], NDArray[np.intp]]) -> Array:
    """Σ̃ (m×m, positive semi-definite) from the moments, with the prior diag(1) ± 1.

    Stacked: ``normal`` (..., p, p) and ``rhs`` (..., p) give (..., m, m); each matrix is
    solved by the same LAPACK calls as alone (the jackknife solves all its blocks at once).
    """
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


def _sensitivity(gains_std: Array) -> Array:
    """``A = Σ_f G_fᵀ C_indep,f⁻¹ G_f`` (m, m, standardised units), shared by every
    :func:`_widening` call: ``Σ_f tr(C_indep,f⁻¹ G_f Σ G_fᵀ) = Σ_mk Σ_mk A_km``, so each
    widening (21 per run: κ and the jackknife) costs O(m²) instead of a pass over the fixes."""
    inverse = np.linalg.inv(np.matmul(gains_std, np.swapaxes(gains_std, 1, 2)))
    sensitivity: Array = np.einsum("fim,fik->mk", np.matmul(inverse, gains_std), gains_std)
    return sensitivity


def _widening(sensitivity: Array, sigma_std: Array, count: int, dims: int) -> Array:
    """Average ``tr(C_indep⁻¹ C_Σ) / dims`` over the ``count`` fixes (standardised units), for
    one Σ̃ (m, m) or a stack of them (k, m, m)."""
    total: Array = np.sum(sigma_std * sensitivity.T, axis=(-2, -1))
    return total / count / dims


def learn_link_covariance(
    fixes: Fixes, corrected_m: Array, beacons: BeaconMap, model: NoiseModel
) -> NoiseModel:
    """Return ``model`` with the link-error covariance Σ when it significantly widens the ellipses.

    See the module docstring. ``model`` is returned with :attr:`NoiseModel.widening` (and its
    standard error) filled in whenever it could be measured, and with
    :attr:`NoiseModel.link_covariance_m2` only when the widening is significant.

    Args:
        fixes: The final solve of ``corrected_m`` with ``model``'s σ.
        corrected_m: The distances that were solved, (n, m), metres.
        beacons: The map.
        model: The learned model (σ per link).
    """
    if usable_rows(fixes).size < max(MIN_CALIBRATION_FIXES, 2 * JACKKNIFE_BLOCKS):
        return model
    moments = _moments(fixes, corrected_m, beacons, model)
    if moments.gains_std.shape[0] < max(MIN_CALIBRATION_FIXES, 2 * JACKKNIFE_BLOCKS):
        return model
    normal, rhs = sum(moments.normals), sum(moments.rhs)
    assert isinstance(normal, np.ndarray) and isinstance(rhs, np.ndarray)
    sigma_std = _solve(normal, rhs, moments.upper)
    sensitivity = _sensitivity(moments.gains_std)
    count, dims = moments.gains_std.shape[:2]
    kappa = float(_widening(sensitivity, sigma_std, count, dims))
    left_out = _solve(
        normal - np.stack(moments.normals), rhs - np.stack(moments.rhs), moments.upper
    )
    leave_out = _widening(sensitivity, left_out, count, dims)
    k = JACKKNIFE_BLOCKS
    se = float(np.sqrt((k - 1) / k * np.sum((leave_out - leave_out.mean()) ** 2)))
    significant = kappa - 1.0 > SIGNIFICANCE * se
    covariance = sigma_std * np.outer(model.sigma_m, model.sigma_m) if significant else None
    return dataclasses.replace(model, link_covariance_m2=covariance, widening=kappa, widening_sd=se)


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
    """The horizontal covariance of each fix under the model's link covariance, (n, 2, 2), m².

    ``G Σ Gᵀ`` times the fix's residual variance factor ``max(1, Σ r²/σ² / dof)``, never
    tighter than the fix's own covariance; the fix's own covariance where the model has no
    link covariance or the fix has no finite position or covariance.
    """
    out: Array = fixes.covariance_xy_m2.copy()
    sigma_e = model.link_covariance_m2
    if sigma_e is None:
        return out
    position = fixes.positions_map_m
    finite = np.all(np.isfinite(position[:, :2]), axis=1) & np.all(
        np.isfinite(out.reshape(-1, 4)), axis=1
    )
    rows = np.flatnonzero(finite)
    for lo in range(0, rows.size, _CHUNK):  # each fix on its own: a chunk at a time
        _widen_rows(fixes, corrected_m, beacons, model, sigma_e, rows[lo : lo + _CHUNK], out)
    return out


_CHUNK = 8192
"""Fixes :func:`link_covariances` linearises at a time."""


def _widen_rows(
    fixes: Fixes,
    corrected_m: Array,
    beacons: BeaconMap,
    model: NoiseModel,
    sigma_e: Array,
    rows: NDArray[np.intp],
    out: Array,
) -> None:
    """:func:`link_covariances` of ``rows``, written into ``out``."""
    lin = linearise(fixes, corrected_m, beacons, rows)
    used = lin.used
    weight = np.where(used, 1.0 / model.sigma_m**2, 0.0)
    gains = _gains(lin.jacobian, weight)
    covariance = np.matmul(np.matmul(gains, sigma_e), np.swapaxes(gains, 1, 2))[:, :2, :2]
    dof = np.maximum(used.sum(axis=1) - fixes.dims, 1)
    factor = np.sum(np.where(used, lin.residual**2, 0.0) * weight, axis=1) / dof
    covariance *= np.maximum(factor, 1.0)[:, None, None]
    own = out[rows]
    good = np.all(np.isfinite(covariance.reshape(-1, 4)), axis=1)
    good &= (own[:, 0, 0] > 0.0) & (own[:, 0, 0] * own[:, 1, 1] - own[:, 0, 1] ** 2 > 0.0)
    out[rows[good]] = loewner_max(own[good], covariance[good])
