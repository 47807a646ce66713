"""Joint estimation of the seven factors, alignments, hedgehog offset and IPS latency.

``estimate_joint``: the odometry fitted to the IPS fixes, the noise model estimated from the
residuals, 1σ from a sandwich covariance. Design and measurements: docs/joint-calibration.md.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from omnical.calibration.joint.model import (
    MotionContent,
    hedge_track,
    interpolate_track,
    real_increments,
)
from omnical.calibration.joint.problem import (
    FACTOR_NAMES,
    LATENCY_NAME,
    N_SHARED,
    OFFSET_NAMES,
    Linearisation,
    NormalEquations,
    SparseJointProblem,
    Track,
    prepare_track,
    windowed_procrustes,
)
from omnical.calibration.procedures.geometry import LOSSES, robust_loss
from omnical.calibration.procedures.tracks import ODOM_YAW_DEADBAND_RADPS
from omnical.errors import CalibrationError
from omnical.estimation.se2 import integrate_increments
from omnical.ips.solve.fixes import Fixes
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import CROSSTALKS, Factor
from omnical.recording.recording import Recording

__all__ = [
    "DEFAULT_IPS_LATENCY_S",
    "FACTOR_NAMES",
    "MIN_ROTATION_RAD",
    "MIN_TRAVEL_M",
    "Alignment",
    "JointEstimate",
    "JointWarning",
    "ObservabilityWarning",
    "estimate_joint",
]

_Array = NDArray[np.float64]

DEFAULT_IPS_LATENCY_S = 0.05
"""Assumed delay from emission to the bag time of a fix: 10 ms + one period at 25 Hz."""

MIN_TRAVEL_M = 1.0
"""Least distance in a direction (m) for its cross-talk (and, per axis, its scaling) to count."""
MIN_ROTATION_RAD = math.pi
"""Least total rotation (rad) for the rotational scaling and the hedgehog offset to count."""

_MAX_SIGMA_DEFAULT = {"scale": 0.01, "crosstalk": 0.01, "offset": 0.02, "latency": 0.05}
_X_SCALE = {"scale": 0.01, "crosstalk": 0.005, "offset": 0.02, "latency": 0.01}
_ALIGN_X_SCALE = (0.05, 0.05, 0.01)
_OUTLIER_WHITENED = 5.0
_MAX_NFEV = 100
_MAX_LAG = 400
_MAX_HOLD_ROUNDS = 4
_NOISE_ROUNDS = 6  # most refits with the noise model rescaled
_NOISE_TOL = math.log(1.1)  # variance ratios within 10 % of 1: the noise model has converged
_MIN_REDUNDANCY = 1.0  # fewer redundant slip priors than this say nothing of the slip's size
_SLIP_VARIANCE_RANGE = (1e-4, 1e4)  # the slip's variance against the given densities (numerics)
_RANDOM_WALK_STEPS = 1.5  # a random walk's step variance over its neighbouring means' (_sandwich)

MAX_CLASS_CHI2 = 4.0
"""Normalised χ² of one motion class's fixes beyond which (and beyond
:data:`MAX_CLASS_CHI2_RATIO` × the overall one) its factor is inconsistent with the data."""
MAX_CLASS_CHI2_RATIO = 3.0
MIN_CLASS_FIXES = 50
"""Fewest fixes in a motion class for its χ² to count."""
_TOL = 1e-10  # ftol, xtol, gtol of the fit
_MU0 = 1e-3  # initial Levenberg–Marquardt damping, relative to the largest scaled curvature
_MU_SHRINK = 0.1  # most the damping shrinks after one good step
_EPS = float(np.finfo(np.float64).eps)


class JointWarning(UserWarning):
    """Something about a joint estimate the caller should know (see its ``warnings``)."""


class ObservabilityWarning(JointWarning):
    """A parameter the given motion cannot determine was held at its prior."""


@dataclass(frozen=True)
class Alignment:
    """Pose of a recording's odom frame in the map frame (map ← odom)."""

    x_m: float
    y_m: float
    yaw_rad: float


@dataclass(frozen=True)
class JointEstimate:
    """Result of :func:`estimate_joint`.

    Attributes:
        factors: the estimated truth (absolute factors, not residuals to the installed ones).
        sigma: one standard deviation per parameter: the factor field names,
            ``hedge_offset_x_m``, ``hedge_offset_y_m``, ``latency_s`` and ``alignment[i].x_m``,
            ``.y_m``, ``.yaw_rad`` per recording; NaN for a parameter held at its prior.
        alignments: map ← odom pose of each recording.
        hedge_offset_m: hedgehog (x, y) in base_link, m.
        latency_s: IPS latency used (estimated or assumed), s.
        residual_rms_m: RMS of the position residuals of the inlier fixes, m.
        warnings: one line per problem, each starting with the parameter name (observability,
            issued as :class:`ObservabilityWarning`) or ``fit:`` (no convergence).
        n_fixes_used: fixes in the fit (ok or degraded, during the odometry).
        n_outliers: fixes the robust loss discounted (whitened residual beyond 5).
        held: parameters held at their prior.
        held_reasons: parameter → why it was held (``not observable: …``, ``not separable:
            …``, ``inconsistent: …``).
        class_chi2: normalised χ² of the fix residuals per motion class (``forward`` …
            ``turning``, ``all``): (fixes, χ²/dof) at the solution.
        parameter_names: order of the rows and columns of :attr:`correlation`.
        correlation: correlation matrix of the named parameters (NaN rows/columns if held).
        content: motion content of all recordings together, as the odometry reported it.
        installed: the factors the recordings' odometry was compensated with (the prior).
        correlation_inflation: the largest variance factor the fixes' autocorrelation put on
            a named parameter's share of the fixes (≥ 1; per parameter, from its own scores).
        n_slip_parameters: slip perturbations the model carried.
        latency_from_fixes: with the latency held (``estimate_latency`` off): the latency the
            fixes prefer and its one sigma, s; None when it was estimated.
        noise_variance: variance factors the residuals gave on what was given: ``fixes[i]``
            (recording i's fix covariances), ``slip_along``, ``slip_across``; all 1 with
            ``estimate_noise`` off.
    """

    factors: CorrectionFactors
    sigma: dict[str, float]
    alignments: tuple[Alignment, ...]
    hedge_offset_m: tuple[float, float]
    latency_s: float
    residual_rms_m: float
    warnings: tuple[str, ...]
    n_fixes_used: int
    n_outliers: int
    held: tuple[str, ...]
    parameter_names: tuple[str, ...]
    correlation: _Array = field(repr=False)
    content: MotionContent
    installed: CorrectionFactors
    correlation_inflation: float
    n_slip_parameters: int
    held_reasons: Mapping[str, str] = field(default_factory=dict)
    class_chi2: Mapping[str, tuple[int, float]] = field(default_factory=dict)
    latency_from_fixes: tuple[float, float] | None = None
    noise_variance: Mapping[str, float] = field(default_factory=dict)

    @property
    def factor_sigma(self) -> CorrectionFactors:
        """One-sigma uncertainties of the seven factors as a CorrectionFactors (NaN = held)."""
        return CorrectionFactors(*(self.sigma[n] for n in FACTOR_NAMES))


def _kind(name: str) -> str:
    if name in FACTOR_NAMES:
        return Factor.from_field(name).kind.value
    if name in OFFSET_NAMES:
        return "offset"
    if name == LATENCY_NAME:
        return "latency"
    if name.startswith("slip["):
        return "slip"
    return "alignment"


def _content_holds(content: MotionContent, estimate_latency: bool) -> list[tuple[str, str]]:
    """(parameter, reason) for each parameter the motion content cannot determine."""
    holds: list[tuple[str, str]] = []
    lon = content.forward_m + content.reverse_m
    lat = content.left_m + content.right_m
    if lon < MIN_TRAVEL_M:
        holds.append((Factor.SCALE_LONGITUDINAL.field, f"only {lon:.2f} m of longitudinal travel"))
    if lat < MIN_TRAVEL_M:
        holds.append((Factor.SCALE_LATERAL.field, f"only {lat:.2f} m of lateral travel"))
    if content.rotation_rad < MIN_ROTATION_RAD:
        why = f"only {math.degrees(content.rotation_rad):.0f}° of rotation"
        holds.append((Factor.SCALE_ROTATIONAL.field, why))
        holds.extend((n, why) for n in OFFSET_NAMES)
    for factor in CROSSTALKS:
        direction = factor.yaml_key
        travelled = float(getattr(content, f"{direction}_m"))
        if travelled < MIN_TRAVEL_M:
            holds.append((factor.field, f"only {travelled:.2f} m of {direction} travel"))
    if estimate_latency and content.path_m < MIN_TRAVEL_M:
        holds.append((LATENCY_NAME, f"only {content.path_m:.2f} m of travel"))
    return holds


def _geyer_time(acov: _Array) -> float:
    """Integrated autocorrelation time (in samples) from autocovariances at lags 0, 1, …

    Geyer's initial positive sequence: pairs of lags are summed until a pair is not positive.
    """
    if not acov[0] > 0.0:
        return 1.0
    rho = acov / acov[0]
    tau = 1.0
    for k in range(1, rho.size - 1, 2):
        pair = rho[k] + rho[k + 1]
        if not pair > 0.0:
            break
        tau += 2.0 * pair
    return max(tau, 1.0)


def _lagged_products(x: _Array, lags: int) -> _Array:
    """(lags, m) sums Σ_i x_ij x_(i+k)j for k < lags, per column of x (n, m), by FFT (not BLAS:
    docs/joint-calibration.md)."""
    n = x.shape[0]
    size = 1 << int(n + lags - 1).bit_length()
    spectrum = np.fft.rfft(x, size, axis=0)
    out: _Array = np.fft.irfft(spectrum * np.conj(spectrum), size, axis=0)[:lags]
    return out


def _loss(
    fun: _Array, loss: str, f_scale: float, n_robust: int | None = None
) -> tuple[_Array, _Array, _Array]:
    """ρ, ρ', ρ'' of residuals ``fun`` as ``scipy.optimize.least_squares`` scales them.

    Only the first ``n_robust`` residuals (the fixes; default all) take the robust loss, the
    rest (the slip priors: Gaussian by construction, no outliers) the linear one.
    """
    n = fun.size if n_robust is None else n_robust
    z = (fun / f_scale) ** 2
    rho, rho1, rho2 = z.copy(), np.ones_like(z), np.zeros_like(z)
    rho[:n], rho1[:n], rho2[:n] = robust_loss(z[:n], loss)
    return rho * f_scale**2, rho1, rho2 / f_scale**2


def _cost(fun: _Array, loss: str, f_scale: float, n_robust: int | None = None) -> float:
    """The robust cost ½ Σ ρ(r²) of ``least_squares``."""
    return 0.5 * float(np.sum(_loss(fun, loss, f_scale, n_robust)[0]))


@functools.lru_cache(maxsize=16)
def _normal_consistency(loss: str, f_scale: float) -> float:
    """E[ψ(e)²] for e ~ N(0, 1), ψ(e) = ρ'(e² / f²) e: what Σ ψ² / dof is at unit variance."""
    from numpy.polynomial.hermite_e import hermegauss

    x, w = hermegauss(80)
    psi = robust_loss((x / f_scale) ** 2, loss)[1] * x
    return float(np.sum(w * psi**2) / math.sqrt(2.0 * math.pi))


def _m_scale(r: _Array, redundancy: float, loss: str, f_scale: float) -> float:
    """Robust variance s² of residuals r: Σ ψ(r / s)² = c · redundancy (Huber's Proposal 2).

    ψ(e) = ρ'(e² / f²) e, the loss's bounded influence; c (:func:`_normal_consistency`) makes
    s² the variance of normal residuals.
    """
    c = _normal_consistency(loss, f_scale)
    s2 = max(float(np.median(r**2)) / 0.4549, 1e-300)  # the median of χ²₁ is 0.4549
    for _ in range(100):
        rho1 = robust_loss(r**2 / (s2 * f_scale**2), loss)[1]
        new = float(np.sum((rho1 * r) ** 2)) / (c * redundancy)
        done = abs(new - s2) <= 1e-9 * s2
        s2 = max(new, 1e-300)
        if done:
            break
    return s2


@dataclass(frozen=True)
class _Sandwich:
    """The covariance of the named parameters at a linearisation (:func:`_sandwich`).

    Attributes:
        cov: the sandwich ``(JᵀWJ)⁻¹ M (JᵀWJ)⁻¹`` of the named parameters.
        bread: ``(JᵀWJ)⁻¹`` of the named parameters (the model's own covariance).
        step: the Gauss–Newton step of the named parameters from this point.
        fix_ratio: per recording, the robust variance of its whitened fix residuals.
        slip_ratio: (2,) the variance of the slip along and across the motion against the
            priors' (1: as assumed; also 1 when the fixes cannot tell).
        inflation: per named parameter, the variance factor of its fixes' autocorrelation.
        normal: the weighted normal equations.
    """

    cov: _Array
    bread: _Array
    step: _Array
    fix_ratio: _Array
    slip_ratio: _Array
    inflation: _Array
    normal: NormalEquations


def _sandwich(
    lin: Linearisation,
    named_local: NDArray[np.intp],
    shared_scale: _Array,
    fix_rows: Sequence[int],
    loss: str,
    f_scale: float,
    slip_share: _Array,
) -> _Sandwich:
    """Covariance of the named parameters: a sandwich over the fixes, the model over the slips.

    Bread ``(JᵀWJ)⁻¹``; meat per fix row ψ² / (1 − leverage) (HC2), per slip prior its
    modelled variance; the fixes' share inflated per parameter by the autocorrelation of its
    scores (Geyer, ≤ 400 lags). Also the noise model's variance components: per recording
    :func:`_m_scale` of its fixes, for the slip along and across ``3/2 Σ s r² / Σ s (1 − h)``
    (``slip_share``: each prior's share along). docs/joint-calibration.md, "Uncertainty".
    """
    n_robust = int(sum(fix_rows))
    fun = lin.fun
    _, rho1, rho2 = _loss(fun, loss, f_scale, n_robust)
    w = np.maximum(rho1 + 2.0 * rho2 * fun**2, _EPS)
    normal = NormalEquations(lin.local, lin.shared, w)
    inv = normal.inverse(shared_scale)
    redundant = np.clip(1.0 - normal.leverages(inv), 1e-6, 1.0)
    z_local, z_shared = normal.inverse_columns(inv, named_local)
    bread = np.vstack([z_shared, z_local[named_local]])
    # influence rows (rows, named); einsum, not BLAS (docs/joint-calibration.md)
    g = np.asarray(lin.local @ z_local) + np.einsum("ij,jk->ik", lin.shared, z_shared)
    gradient = rho1 * fun
    step = -(
        np.einsum("i,ik->k", np.asarray(lin.local.T @ gradient), z_local)
        + np.einsum("i,ik->k", np.einsum("ij,i->j", lin.shared, gradient), z_shared)
    )
    psi = gradient[:n_robust]
    gf = g[:n_robust]
    meat_fix = np.einsum("ij,ik->jk", gf * (psi**2 / redundant[:n_robust])[:, None], gf)
    lags = np.zeros((_MAX_LAG, g.shape[1]))
    start = 0
    for rows in fix_rows:
        u = (
            (gf[start : start + rows] * psi[start : start + rows, None])
            .reshape(rows // 2, 2, -1)
            .sum(axis=1)
        )  # one score per fix (its two whitened coordinates)
        start += rows
        k = min(_MAX_LAG, u.shape[0])
        lags[:k] += _lagged_products(u, k)
    inflation = np.array([_geyer_time(lags[:, j]) for j in range(g.shape[1])])
    root = np.sqrt(inflation)
    gp = g[n_robust:]
    cov = meat_fix * np.outer(root, root) + np.einsum("ij,ik->jk", gp, gp)
    fix_ratio = np.ones(len(fix_rows))
    start = 0
    for i, rows in enumerate(fix_rows):
        r = fun[start : start + rows]
        fix_ratio[i] = _m_scale(r, float(np.sum(redundant[start : start + rows])), loss, f_scale)
        start += rows
    slip_ratio = np.ones(2)
    r2, red = fun[n_robust:] ** 2, redundant[n_robust:]
    for g, share in enumerate((slip_share, 1.0 - slip_share)):
        dof = float(np.sum(share * red))
        if dof >= _MIN_REDUNDANCY:
            slip_ratio[g] = _RANDOM_WALK_STEPS * float(np.sum(share * r2)) / dof
    return _Sandwich(
        cov=cov,
        bread=bread,
        step=step,
        fix_ratio=fix_ratio,
        slip_ratio=slip_ratio,
        inflation=inflation,
        normal=normal,
    )


@dataclass(frozen=True)
class _Outcome:
    """What a solve leaves for the observability checks and the result.

    Attributes:
        fun: residuals at the solution.
        weights: ρ' of each residual.
        cov: covariance of the free named parameters (``_Fit.free_named`` order).
        norms: loss-scaled Jacobian column norms of the free named parameters, × x_scale.
        top: the largest such column norm over all free parameters.
        fix_ratio: per recording, the fixes' robust variance in whitened units.
        slip_ratio: (2,) the slip's variance along and across the motion, whitened units.
        inflation: per free named parameter, the variance factor of the fixes' autocorrelation.
        bread: ``(JᵀWJ)⁻¹`` of the free named parameters (the model's own covariance).
    """

    fun: _Array
    weights: _Array
    cov: _Array
    norms: _Array
    top: float
    fix_ratio: _Array
    slip_ratio: _Array
    inflation: _Array
    bread: _Array


@dataclass
class _Fit:
    """Mutable state of the estimation (local to one call)."""

    problem: SparseJointProblem
    full: _Array
    prior: _Array
    free: NDArray[np.bool_]
    x_scale: _Array
    loss: str
    f_scale: float
    notes: list[str] = field(default_factory=list)
    held: list[str] = field(default_factory=list)
    reasons: dict[str, str] = field(default_factory=dict)
    added_var: dict[str, float] = field(default_factory=dict)
    coupled: dict[str, tuple[str, ...]] = field(default_factory=dict)
    converged: bool = True
    assumed_latency: bool = False
    estimate_noise: bool = True
    latency_check: tuple[float, float] | None = None
    base_tracks: tuple[Track, ...] = ()
    fix_variance: _Array = field(default_factory=lambda: np.ones(0))
    slip_variance: _Array = field(default_factory=lambda: np.ones(2))

    def hold(self, name: str, reason: str, what: str = "not observable") -> None:
        j = self.problem.names.index(name)
        if not self.free[j]:
            return
        self.free[j] = False
        self.full[j] = self.prior[j]
        self.held.append(name)
        self.reasons[name] = f"{what}: {reason}"
        source = "the installed value" if _kind(name) in ("scale", "crosstalk") else "its prior"
        self.notes.append(f"{name}: {what} ({reason}); held at {self.prior[j]:.6g} ({source})")

    def free_named(self) -> NDArray[np.intp]:
        """Full-vector indices of the free named parameters, in the named order."""
        named = self.problem.named
        return named[self.free[named]]

    @property
    def fix_rows(self) -> list[int]:
        """Fix rows (two per fix) of each recording, at the head of the residual vector."""
        return [2 * tr.fix_xy.shape[0] for tr in self.problem.tracks]

    def run(self, *, noise: bool = True) -> _Outcome:
        """Least squares over the free parameters, with the noise model estimated (``noise``).

        Rescales the fixes' covariances and slip priors by :func:`_sandwich`'s ratios and
        solves again until they are within 10 % of 1. An assumed latency is free meanwhile,
        then held (:meth:`_hold_latency`).
        """
        if not self.base_tracks:
            self.base_tracks = self.problem.tracks
            self.fix_variance = np.ones(len(self.base_tracks))
        lat = self.problem.names.index(LATENCY_NAME)
        release = self.assumed_latency and not self.free[lat]
        held = float(self.full[lat])
        self.free[lat] = self.free[lat] or release
        outcome = self._solve()
        for _ in range(_NOISE_ROUNDS if noise and self.estimate_noise else 0):
            ratios = np.concatenate([outcome.fix_ratio, outcome.slip_ratio])
            if np.all(np.abs(np.log(ratios)) <= _NOISE_TOL):
                break
            self._rescale(outcome.fix_ratio, outcome.slip_ratio)
            outcome = self._solve()
        return self._hold_latency(outcome, held) if release else outcome

    def _hold_latency(self, free: _Outcome, assumed_s: float) -> _Outcome:
        """The fit again with the latency held at ``assumed_s``, charged with that value's error.

        ``free`` is the fit with the latency free (covariance C); the held estimates' covariance
        is C_jj + g_j² (assumed − free latency)², g = C_jL / C_LL (docs/joint-calibration.md,
        "The IPS latency").
        """
        lat = self.problem.names.index(LATENCY_NAME)
        k = int(np.searchsorted(self.free_named(), lat))
        free_latency = float(self.full[lat])
        self.free[lat] = False
        self.full[lat] = assumed_s
        held = self._solve()
        bread_ll = float(free.bread[k, k])
        if not (bread_ll > 0.0 and math.isfinite(bread_ll)):
            return held
        gain = np.delete(free.bread[:, k], k) / bread_ll
        shift = free_latency - assumed_s
        keep = np.delete(np.arange(free.cov.shape[0]), k)
        self.latency_check = (free_latency, math.sqrt(max(float(free.cov[k, k]), 0.0)))
        return replace(held, cov=free.cov[np.ix_(keep, keep)] + shift**2 * np.outer(gain, gain))

    def slip_share(self) -> _Array:
        """Each slip prior's current share of slip along the motion (prior-row order)."""
        parts = [tr.knot_share for tr in self.base_tracks]
        share = np.concatenate(parts) if parts else np.zeros(0)
        along = self.slip_variance[0] * share
        total = along + self.slip_variance[1] * (1.0 - share)
        return np.asarray(np.divide(along, total, out=np.zeros_like(along), where=total > 0.0))

    def _rescale(self, fix_ratio: _Array, slip_ratio: _Array) -> None:
        """Scale the fixes' covariances and the slip priors' variances; a new problem."""
        self.slip_variance = np.clip(self.slip_variance * slip_ratio, *_SLIP_VARIANCE_RANGE)
        self.fix_variance = self.fix_variance * fix_ratio
        along, across = self.slip_variance
        tracks = [
            replace(
                tr,
                chol=tr.chol * math.sqrt(float(f)),
                knot_sigma=tr.knot_sigma
                * np.sqrt(along * tr.knot_share + across * (1.0 - tr.knot_share)),
            )
            for tr, f in zip(self.base_tracks, self.fix_variance, strict=True)
        ]
        self.problem = SparseJointProblem(tracks)
        local_scale = self.problem.x_scale(_ALIGN_X_SCALE)
        self.x_scale = np.concatenate([self.x_scale[:N_SHARED], local_scale])

    def _solve(self) -> _Outcome:
        """Levenberg–Marquardt on the keyframe problem, stepping the keyframes themselves.

        Each step solves the banded normal equations (:class:`NormalEquations`, IRLS weights ρ')
        damped by μ in the x_scale'd variables. Stops as ``least_squares`` does (ftol, xtol,
        gtol = ``_TOL``), after at most ``_MAX_NFEV`` cost evaluations.
        """
        problem = self.problem
        shared = np.flatnonzero(self.free[:N_SHARED])
        n_robust = sum(self.fix_rows)
        if not np.all(self.free[N_SHARED:]):
            msg = "the joint solver holds only shared parameters"
            raise CalibrationError(msg)
        xs_s, xs_l = self.x_scale[shared], self.x_scale[N_SHARED:]
        diag_l, diag_s = 1.0 / xs_l**2, 1.0 / xs_s**2
        x = self.full.copy()
        lin = problem.linearise(x, shared)
        cost = _cost(lin.fun, self.loss, self.f_scale, n_robust)
        nfev, mu, nu = 1, -1.0, 2.0
        self.converged = False
        while True:
            normal, g_l, g_s = self._normal(lin, irls=True)
            scaled_g = np.concatenate([g_l * xs_l, g_s * xs_s])
            if float(np.max(np.abs(scaled_g), initial=0.0)) < _TOL:
                self.converged = True
                break
            if mu < 0.0:
                curvature = np.concatenate(
                    [normal.ab[normal.band] * xs_l**2, np.diag(normal.d) * xs_s**2]
                )
                mu = _MU0 * max(float(np.max(curvature, initial=0.0)), _EPS)
            done = accepted = False
            while nfev < _MAX_NFEV:
                p_l, p_s = normal.solve(-g_l, -g_s, mu=mu, diag_local=diag_l, diag_shared=diag_s)
                trial = x.copy()
                trial[shared] += p_s
                trial[N_SHARED:] += p_l
                fun = problem.residuals(trial)
                nfev += 1
                new_cost = _cost(fun, self.loss, self.f_scale, n_robust)
                predicted = -(float(g_l @ p_l + g_s @ p_s) + 0.5 * normal.quadratic(p_l, p_s))
                actual = cost - new_cost
                if np.isfinite(new_cost) and actual > 0.0 and predicted > 0.0:
                    ratio = actual / predicted
                    mu *= max(_MU_SHRINK, 1.0 - (2.0 * ratio - 1.0) ** 3)
                    nu = 2.0
                    step = math.hypot(
                        float(np.linalg.norm(p_l / xs_l)), float(np.linalg.norm(p_s / xs_s))
                    )
                    size = math.hypot(
                        float(np.linalg.norm(x[N_SHARED:] / xs_l)),
                        float(np.linalg.norm(x[shared] / xs_s)),
                    )
                    done = (actual < _TOL * cost and ratio > 0.25) or step < _TOL * (_TOL + size)
                    x, cost, accepted = trial, new_cost, True
                    break
                mu *= nu
                nu *= 2.0
            if not accepted:
                break
            del normal, lin  # the next linearisation's peak memory without them
            lin = problem.linearise(x, shared)
            if done:
                self.converged = True
                break
        self.full[:] = x
        named = self.free_named()
        named_local = named[named >= N_SHARED] - N_SHARED
        return self._outcome(lin, named_local, shared, self.x_scale[N_SHARED:])

    def _normal(
        self, lin: Linearisation, *, irls: bool = False
    ) -> tuple[NormalEquations, _Array, _Array]:
        """The loss-scaled normal equations and the gradient (local, shared) at ``lin``.

        Weights ρ' + 2 ρ'' r² (``least_squares``', for the covariance), or ρ' with ``irls`` (for
        the steps: a quadratic above the cost, every loss here being concave in r²).
        """
        _, rho1, rho2 = _loss(lin.fun, self.loss, self.f_scale, sum(self.fix_rows))
        w = rho1 if irls else np.maximum(rho1 + 2.0 * rho2 * lin.fun**2, _EPS)
        gr = rho1 * lin.fun
        normal = NormalEquations(lin.local, lin.shared, w)
        return normal, np.asarray(lin.local.T @ gr), np.einsum("ij,i->j", lin.shared, gr)

    def _outcome(
        self,
        lin: Linearisation,
        named_local: NDArray[np.intp],
        shared: NDArray[np.intp],
        local_scale: _Array,
    ) -> _Outcome:
        sw = _sandwich(
            lin,
            named_local,
            self.x_scale[shared],
            self.fix_rows,
            self.loss,
            self.f_scale,
            self.slip_share(),
        )
        d_l, d_s = sw.normal.diagonal()
        norms_l = np.sqrt(np.maximum(d_l, 0.0)) * local_scale
        norms_s = np.sqrt(np.maximum(d_s, 0.0)) * self.x_scale[shared]
        top = float(np.max(np.concatenate([norms_l, norms_s])))
        return _Outcome(
            fun=lin.fun,
            weights=_loss(lin.fun, self.loss, self.f_scale, sum(self.fix_rows))[1],
            cov=sw.cov,
            norms=np.concatenate([norms_s, norms_l[named_local]]),
            top=max(top, 1e-300),
            fix_ratio=sw.fix_ratio,
            slip_ratio=sw.slip_ratio,
            inflation=sw.inflation,
            bread=sw.bread,
        )


def _check_options(
    loss: str, f_scale: float, model_sigma_m: float, noise: tuple[float, float, float, float]
) -> None:
    if loss not in LOSSES:
        msg = f"loss must be one of {', '.join(LOSSES)}, got {loss!r}"
        raise CalibrationError(msg)
    if not f_scale > 0.0:
        msg = f"f_scale must be > 0, got {f_scale}"
        raise CalibrationError(msg)
    if not model_sigma_m >= 0.0:
        msg = f"model_sigma_m must be >= 0 m, got {model_sigma_m}"
        raise CalibrationError(msg)
    if not all(v >= 0.0 for v in noise):
        msg = f"odometry noise densities must be >= 0, got {noise}"
        raise CalibrationError(msg)


def estimate_joint(
    recordings: Sequence[Recording],
    *,
    installed: CorrectionFactors | None = None,
    fixes: Sequence[Fixes] | None = None,
    estimate_latency: bool = False,
    latency_s: float = DEFAULT_IPS_LATENCY_S,
    hedge_offset_m: tuple[float, float] = (0.0, 0.0),
    loss: str = "soft_l1",
    f_scale: float = 2.0,
    model_sigma_m: float = 0.01,
    heading_noise_rad_per_sqrt_rad: float = 0.004,
    heading_noise_rad_per_sqrt_m: float = 0.0005,
    position_noise_m_per_sqrt_m: float = 0.002,
    cross_noise_m_per_sqrt_m: float = 0.0005,
    max_sigma: dict[str, float] | None = None,
    odom_yaw_deadband_radps: float = ODOM_YAW_DEADBAND_RADPS,
    estimate_noise: bool = True,
) -> JointEstimate:
    """Estimate the seven factors, the alignments, the hedgehog offset (and latency) together.

    Never reads ``/ground_truth``: only ``/odom`` and the IPS topics (or the given fixes).

    Args:
        recordings: one or more recordings with ``/odom`` and the IPS topics (or ``fixes``).
        installed: factors the recordings' odometry was compensated with (default identity);
            also the prior at which unobservable factors are held.
        fixes: precomputed fixes per recording (default: :func:`omnical.ips.from_recording.locate`).
        estimate_latency: also estimate the IPS latency; else it is held at ``latency_s`` and
            the σ include that value's error (:attr:`JointEstimate.latency_from_fixes`).
        latency_s: assumed (or initial) delay from emission to the fix's bag time, s.
        hedge_offset_m: initial (and, when unobservable, held) hedgehog (x, y) in base_link, m.
        loss: robust loss of ``scipy.optimize.least_squares`` (``soft_l1``, ``cauchy``, ...)
            on the fixes (the slip priors are Gaussian).
        f_scale: inlier scale of the loss, in whitened units (standard deviations).
        model_sigma_m: added in quadrature to every fix's covariance (timing, unmodelled slip), m.
        heading_noise_rad_per_sqrt_rad: prior σ of the odometry's heading random walk per √rad
            turned (slip along the motion).
        heading_noise_rad_per_sqrt_m: the same per √m travelled (slip across the motion).
        position_noise_m_per_sqrt_m: prior σ of the position random walk along the direction
            of travel per √m travelled (slip along the motion).
        cross_noise_m_per_sqrt_m: the same across the direction of travel (slip across).
        max_sigma: largest one-sigma uncertainty for a parameter to count as observable, per
            kind ``scale``, ``crosstalk`` (rad/m), ``offset`` (m), ``latency`` (s); defaults
            0.01, 0.01, 0.02, 0.05.
        odom_yaw_deadband_radps: odometry yaw rates up to this are no rotation (the robot's
            :func:`~omnical.calibration.procedures.tracks.yaw_deadband_radps`).
        estimate_noise: scale the fixes' covariances (per recording) and the slip densities
            (along and across, each as a whole) by what the residuals show
            (:attr:`JointEstimate.noise_variance`); off: as given.

    Returns:
        The estimate, its uncertainties and correlations, and the observability warnings (also
        issued as :class:`ObservabilityWarning`).

    Raises:
        CalibrationError: no recordings, a fixes list of the wrong length, bad options, too few
            usable fixes, or too little motion to estimate any factor.
        RecordingError: a recording lacks ``/odom`` (or the IPS distances, without ``fixes``).
    """
    if not recordings:
        msg = "the joint estimate needs at least one recording"
        raise CalibrationError(msg)
    if fixes is not None and len(fixes) != len(recordings):
        msg = f"got {len(fixes)} sets of fixes for {len(recordings)} recordings"
        raise CalibrationError(msg)
    noise = (
        heading_noise_rad_per_sqrt_rad,
        heading_noise_rad_per_sqrt_m,
        position_noise_m_per_sqrt_m,
        cross_noise_m_per_sqrt_m,
    )
    _check_options(loss, f_scale, model_sigma_m, noise)
    prior = installed if installed is not None else CorrectionFactors()
    limits = {**_MAX_SIGMA_DEFAULT, **(max_sigma or {})}
    tracks = [
        prepare_track(
            rec,
            None if fixes is None else fixes[i],
            prior,
            model_sigma_m=model_sigma_m,
            noise=noise,
            index=i,
            odom_yaw_deadband_radps=odom_yaw_deadband_radps,
        )
        for i, rec in enumerate(recordings)
    ]
    problem = SparseJointProblem(tracks)
    content = tracks[0].content
    for tr in tracks[1:]:
        content = content + tr.content
    fit = _initial_fit(problem, prior, hedge_offset_m, latency_s, loss, f_scale)
    fit.estimate_noise = estimate_noise
    if not estimate_latency:
        fit.free[problem.names.index(LATENCY_NAME)] = False
        fit.assumed_latency = True
    for name, reason in _content_holds(content, estimate_latency):
        fit.hold(name, reason)
    if not np.any(fit.free[: len(FACTOR_NAMES)]):
        msg = "the recordings hold too little motion to estimate any correction factor"
        raise CalibrationError(msg)

    outcome = fit.run()
    first, before, estimates = outcome, fit.free_named(), fit.full.copy()
    for _ in range(_MAX_HOLD_ROUNDS):
        weak = _weak_parameters(fit, outcome, limits)
        weak += _inconsistent_parameters(fit, outcome, {n for n, _, _ in weak})
        if not weak:
            break
        for name, reason, what in weak:
            fit.hold(name, reason, what)
        _propagate_held(fit, first, before, estimates)
        if not np.any(fit.free[: len(FACTOR_NAMES)]):
            msg = "the recordings determine no correction factor: " + "; ".join(fit.notes)
            raise CalibrationError(msg)
        outcome = fit.run(noise=False)  # the noise model stays the first fit's
    return _result(fit, outcome, content, prior)


def _initial_fit(
    problem: SparseJointProblem,
    prior: CorrectionFactors,
    hedge_offset_m: tuple[float, float],
    latency_s: float,
    loss: str,
    f_scale: float,
) -> _Fit:
    """Prior factors, given offset and latency; alignments and keyframes from the fixes
    (:meth:`SparseJointProblem.anchor`)."""
    names = problem.names
    full = np.zeros(len(names))
    full[:7] = prior.as_vector()
    full[7:9] = hedge_offset_m
    full[9] = latency_s
    for i, tr in enumerate(problem.tracks):
        poses = integrate_increments(tr.start_odom, real_increments(tr.raw, prior))
        q = interpolate_track(tr.t_s, hedge_track(poses, full[7:9]), tr.fix_t_s - latency_s)
        a = int(problem.named[N_SHARED + 3 * i])
        whole = np.zeros(len(q))  # one window of every fix: a robust rigid alignment
        full[a : a + 3] = windowed_procrustes(whole, q, tr.fix_xy, whole[:1], 1.0)[0]
    shared_scale = [_X_SCALE[_kind(n)] for n in names[:N_SHARED]]
    problem.initialise(full)
    problem.anchor(full)
    x_scale = np.concatenate([shared_scale, problem.x_scale(_ALIGN_X_SCALE)])
    return _Fit(
        problem=problem,
        full=full,
        prior=full.copy(),
        free=np.ones(len(names), dtype=bool),
        x_scale=x_scale,
        loss=loss,
        f_scale=f_scale,
    )


def _weak_parameters(
    fit: _Fit, outcome: _Outcome, limits: dict[str, float]
) -> list[tuple[str, str, str]]:
    """Free named parameters the fixes do not determine: (name, reason, what).

    A tiny column, or a one-sigma uncertainty (with what the held parameters add,
    :func:`_propagate_held`) beyond the limit.
    """
    weak: list[tuple[str, str, str]] = []
    for k, j in enumerate(fit.free_named()):
        name = fit.problem.names[j]
        kind = _kind(name)
        if kind in ("alignment", "slip"):
            continue
        added = fit.added_var.get(name, 0.0)  # what the held parameters add
        sd = math.sqrt(max(float(outcome.cov[k, k]), 0.0) + added)
        if outcome.norms[k] < 1e-6 * outcome.top:
            weak.append((name, "the fixes do not depend on it", "not observable"))
        elif not sd <= limits[kind] and added > float(outcome.cov[k, k]):
            held = ", ".join(fit.coupled.get(name, ()))
            why = (
                f"the fixes determine it only together with {held}, held at a guess: its "
                f"one sigma including theirs, {sd:.3g}, exceeds {limits[kind]:g}"
            )
            weak.append((name, why, "not separable"))
        elif not sd <= limits[kind]:
            why = f"its one sigma from the fixes, {sd:.3g}, exceeds {limits[kind]:g}"
            weak.append((name, why, "not observable"))
    return weak


_CLASSES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("forward", (Factor.CROSSTALK_FORWARD.field,)),
    ("reverse", (Factor.CROSSTALK_REVERSE.field,)),
    ("left", (Factor.CROSSTALK_LEFT.field,)),
    ("right", (Factor.CROSSTALK_RIGHT.field,)),
    ("turning", (Factor.SCALE_ROTATIONAL.field,)),
)
"""Motion classes of the fixes and the factors that only their motion excites."""


def motion_class_chi2(
    problem: SparseJointProblem, full: _Array, weights: _Array
) -> dict[str, tuple[int, float]]:
    """Normalised χ² of the fix residuals per motion class (and ``all``): (fixes, χ²/dof).

    A fix belongs to ``forward`` / ``reverse`` / ``left`` / ``right`` when the odometry moved
    that way at ≥ 0.02 m/s at its time (a diagonal in two classes), ``turning`` at ≥ 0.02 rad/s.
    χ²/dof = Σ ρ' r² / Σ ρ' over the whitened coordinates (≈ 1 when the model explains them).
    """
    whitened = problem.whitened(full)
    start = 0
    num = {name: 0.0 for name, _ in _CLASSES} | {"all": 0.0}
    den = dict.fromkeys(num, 0.0)
    count = dict.fromkeys(num, 0)
    for tr, w in zip(problem.tracks, whitened, strict=True):
        n = w.shape[0]
        wt = weights[start : start + 2 * n].reshape(n, 2)
        start += 2 * n
        dt = np.maximum(np.diff(tr.t_s), 1e-9)
        k = np.clip(np.searchsorted(tr.t_s, tr.fix_t_s) - 1, 0, dt.size - 1)
        v = tr.raw[k] / dt[k, None]
        chi = np.sum(wt * w**2, axis=1)
        ws = np.sum(wt, axis=1)
        sel = {
            "forward": v[:, 0] >= 0.02,
            "reverse": v[:, 0] <= -0.02,
            "left": v[:, 1] >= 0.02,
            "right": v[:, 1] <= -0.02,
            "turning": np.abs(v[:, 2]) >= 0.02,
            "all": np.ones(n, dtype=bool),
        }
        for name, m in sel.items():
            num[name] += float(np.sum(chi[m]))
            den[name] += float(np.sum(ws[m]))
            count[name] += int(np.count_nonzero(m))
    return {
        name: (count[name], num[name] / den[name] if den[name] > 0.0 else math.nan) for name in num
    }


def _inconsistent_parameters(
    fit: _Fit, outcome: _Outcome, already: set[str]
) -> list[tuple[str, str, str]]:
    """Free factors whose own motion the model does not explain: (name, reason, what).

    A motion class whose normalised χ² exceeds :data:`MAX_CLASS_CHI2` and
    :data:`MAX_CLASS_CHI2_RATIO` × the overall one makes its factor ``inconsistent``.
    """
    chi2 = motion_class_chi2(fit.problem, fit.full, outcome.weights)
    overall = chi2["all"][1]
    out: list[tuple[str, str, str]] = []
    for cls, factors in _CLASSES:
        n, value = chi2[cls]
        if n < MIN_CLASS_FIXES or not value > max(MAX_CLASS_CHI2, MAX_CLASS_CHI2_RATIO * overall):
            continue
        for name in factors:
            j = fit.problem.names.index(name)
            if fit.free[j] and name not in already:
                why = (
                    f"the fixes while {'turning' if cls == 'turning' else 'moving ' + cls} "
                    f"have a normalised chi-square of {value:.3g} against {overall:.3g} overall"
                )
                out.append((name, why, "inconsistent"))
    return out


def _propagate_held(fit: _Fit, outcome: _Outcome, before: NDArray[np.intp], x: _Array) -> None:
    """Charge the free parameters with the error of those held at their prior (in ``fit``).

    ``outcome``, ``before``, ``x``: the first fit, its free named parameters and estimates. For
    the held set H, S = C_jH C_HH⁻¹ and d = x_H − p_H, ``S (d dᵀ + C_HH) Sᵀ`` is added to each
    free j's variance (``fit.added_var``); ``fit.coupled`` names the held ones that matter.
    """
    names = fit.problem.names
    held_now = [k for k, j in enumerate(before) if not fit.free[j]]
    still = [k for k, j in enumerate(before) if fit.free[j]]
    if not held_now or not still:
        return
    cov = outcome.cov
    c_hh = cov[np.ix_(held_now, held_now)]
    c_fh = cov[np.ix_(still, held_now)]
    gain = c_fh @ np.linalg.pinv(c_hh, hermitian=True)
    d = x[before[held_now]] - fit.prior[before[held_now]]
    added = np.einsum("ij,jk,ik->i", gain, np.outer(d, d) + c_hh, gain)
    held_names = [names[before[k]] for k in held_now]
    for i, (k, var) in enumerate(zip(still, added, strict=True)):
        name = names[before[k]]
        if _kind(name) in ("alignment", "slip") or not var > 0.0:
            continue
        fit.added_var[name] = float(var)
        share = np.abs(gain[i]) * np.sqrt(d**2 + np.diag(c_hh))
        fit.coupled[name] = tuple(
            h for h, w in zip(held_names, share, strict=True) if w >= 0.25 * share.max()
        )


def _result(
    fit: _Fit, outcome: _Outcome, content: MotionContent, prior: CorrectionFactors
) -> JointEstimate:
    problem = fit.problem
    named = problem.named
    named_names = tuple(problem.names[j] for j in named)
    n_named = named.size
    free = fit.free[named]
    whitened = problem.whitened(fit.full)
    cov = outcome.cov
    free_names = [problem.names[j] for j in fit.free_named()]
    added = np.array([fit.added_var.get(n, 0.0) for n in free_names])
    cov = cov + np.diag(added)
    latency_check = fit.latency_check
    sigma = np.full(n_named, np.nan)
    sigma[free] = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = np.full((n_named, n_named), np.nan)
    sd = sigma[free]
    with np.errstate(invalid="ignore", divide="ignore"):
        corr[np.ix_(free, free)] = cov / np.outer(sd, sd)

    errors = problem.errors(fit.full)
    norm_w = np.concatenate([np.hypot(w[:, 0], w[:, 1]) for w in whitened])
    dist = np.concatenate([np.hypot(e[:, 0], e[:, 1]) for e in errors])
    inlier = norm_w <= _OUTLIER_WHITENED
    rms = float(np.sqrt(np.mean(dist[inlier] ** 2))) if np.any(inlier) else float("nan")
    full = fit.full
    notes = list(fit.notes)
    for note in notes:
        warnings.warn(note, ObservabilityWarning, stacklevel=3)
    if not fit.converged:
        note = (
            f"fit: the least squares stopped after {_MAX_NFEV} evaluations without converging; "
            "check the recordings (motion, fixes) and the initial alignment"
        )
        notes.append(note)
        warnings.warn(note, JointWarning, stacklevel=3)
    return JointEstimate(
        factors=CorrectionFactors.from_vector(full[:7]),
        sigma={n: float(s) for n, s in zip(named_names, sigma, strict=True)},
        alignments=tuple(
            Alignment(*(float(v) for v in full[named[N_SHARED + 3 * i : N_SHARED + 3 * i + 3]]))
            for i in range(len(problem.tracks))
        ),
        hedge_offset_m=(float(full[7]), float(full[8])),
        latency_s=float(full[9]),
        residual_rms_m=rms,
        warnings=tuple(notes),
        n_fixes_used=int(dist.size),
        n_outliers=int(np.count_nonzero(~inlier)),
        held=tuple(fit.held),
        held_reasons=dict(fit.reasons),
        class_chi2=motion_class_chi2(problem, full, outcome.weights),
        parameter_names=named_names,
        correlation=corr,
        content=content,
        installed=prior,
        correlation_inflation=float(np.max(outcome.inflation, initial=1.0)),
        noise_variance={
            **{f"fixes[{i}]": float(v) for i, v in enumerate(fit.fix_variance)},
            "slip_along": float(fit.slip_variance[0]),
            "slip_across": float(fit.slip_variance[1]),
        },
        n_slip_parameters=sum(tr.knot_index.size for tr in problem.tracks),
        latency_from_fixes=latency_check,
    )
