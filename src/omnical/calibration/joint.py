"""Joint estimation of the seven correction factors from odometry and IPS fixes (beyond seed 000).

Seed 000 measures each factor from its own scripted move. Here all seven are estimated together,
with the map←odom alignment of every recording, the hedgehog's mounting offset and optionally
the IPS latency, by nonlinear least squares of the integrated, compensated odometry against the
IPS fixes (model: :mod:`omnical.calibration.joint_model`; problem:
:mod:`omnical.calibration.joint_problem`). Any recording that moves in the directions of interest
will do — a calibration script, the demo tour, a Lissajous-like run — and several recordings can
be combined: each gets its own alignment; factors, offset and latency are shared.

Residuals are the fix position minus the modelled hedgehog position, whitened by the fix's
covariance plus a model floor (``model_sigma_m``), under a robust loss against multipath
outliers. The odometry is not perfect even with the true factors: slip makes its heading and
position random walks (the heading mostly while turning). The model carries small slip
perturbations with priors (``heading_noise_*``, ``position_noise_*``); without them a heading
slip during a turn, or a few millimetres of slip along one move seen sideways by the next,
would be blamed on the cross-talk of the moves around it.

One-sigma uncertainties come from the Jacobian at the solution, scaled by the robust residual
variance and inflated by the residuals' autocorrelation time.

Observability: a factor the motion does not excite (no lateral travel → lateral scale and the
left/right cross-talks; no turning → rotational scale and hedgehog offset; no reverse → reverse
cross-talk) is held at its prior (the installed value) and a warning says so — first from the
motion content (distances per direction, total rotation, as the odometry reports them), then
from the Jacobian at the solution (negligible column, or a one-sigma uncertainty beyond
``max_sigma``).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from omnical.calibration.joint_model import MotionContent, hedge_track, interpolate_track
from omnical.calibration.joint_problem import (
    FACTOR_NAMES,
    LATENCY_NAME,
    N_SHARED,
    OFFSET_NAMES,
    JointProblem,
    prepare_track,
)
from omnical.errors import CalibrationError
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
_FD_STEP = 1e-4  # central-difference step, in units of x_scale
_OUTLIER_WHITENED = 5.0
_MAX_NFEV = 100
_MAX_LAG = 400
_LOSSES = ("linear", "soft_l1", "huber", "cauchy", "arctan")


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

    def as_array(self) -> _Array:
        """(3,) x, y, yaw."""
        return np.array([self.x_m, self.y_m, self.yaw_rad])


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
        parameter_names: order of the rows and columns of :attr:`correlation`.
        correlation: correlation matrix of the named parameters (NaN rows/columns if held).
        content: motion content of all recordings together, as the odometry reported it.
        installed: the factors the recordings' odometry was compensated with (the prior).
        correlation_inflation: variance factor applied for the residuals' autocorrelation (≥ 1).
        n_slip_parameters: slip perturbations the model carried.
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


def _procrustes(q: _Array, p: _Array) -> _Array:
    """Robust SE(2) transform (x, y, yaw) that best maps points q (n, 2) onto p (n, 2)."""
    keep = np.ones(len(q), dtype=bool)
    out = np.zeros(3)
    for _ in range(4):
        qk, pk = q[keep], p[keep]
        qc, pc = qk.mean(axis=0), pk.mean(axis=0)
        h = (qk - qc).T @ (pk - pc)
        yaw = math.atan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
        c, s = math.cos(yaw), math.sin(yaw)
        t = pc - np.array([c * qc[0] - s * qc[1], s * qc[0] + c * qc[1]])
        out = np.array([t[0], t[1], yaw])
        moved = np.column_stack([c * q[:, 0] - s * q[:, 1], s * q[:, 0] + c * q[:, 1]]) + t
        d = np.hypot(moved[:, 0] - p[:, 0], moved[:, 1] - p[:, 1])
        new_keep = d <= max(3.0 * float(np.median(d)), 0.05)
        if np.count_nonzero(new_keep) < 3 or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    return out


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


def _autocorrelation_time(series: Sequence[_Array]) -> float:
    """Integrated autocorrelation time (in samples) of residual series (Geyer's initial sequence)."""
    num = np.zeros(_MAX_LAG + 1)
    den = np.zeros(_MAX_LAG + 1)
    for x in series:
        x = x - np.mean(x)
        n = x.size
        for k in range(min(_MAX_LAG, n - 1) + 1):
            num[k] += float(np.dot(x[: n - k], x[k:]))
            den[k] += n - k
    if not (den[0] > 0.0 and num[0] > 0.0):
        return 1.0
    acov = num / np.maximum(den, 1.0)
    rho = acov / acov[0]
    tau = 1.0
    for k in range(1, _MAX_LAG - 1, 2):
        pair = rho[k] + rho[k + 1]
        if not pair > 0.0 or den[k + 1] == 0.0:
            break
        tau += 2.0 * pair
    return max(tau, 1.0)


def _loss_weights(z: _Array, loss: str) -> _Array:
    """ρ'(z) of scipy's losses at z = (r / f_scale)²."""
    if loss == "soft_l1":
        return np.asarray(1.0 / np.sqrt(1.0 + z))
    if loss == "cauchy":
        return np.asarray(1.0 / (1.0 + z))
    if loss == "huber":
        return np.asarray(1.0 / np.sqrt(np.maximum(z, 1.0)))
    if loss == "arctan":
        return np.asarray(1.0 / (1.0 + z * z))
    return np.ones_like(z)


def _covariance(
    jac: _Array, fun: _Array, scale: _Array, loss: str, f_scale: float
) -> tuple[_Array, _Array]:
    """s² (JᵀJ)⁻¹ with the robust residual variance s² = Σ ρ' r² / (Σ ρ' − p); and ρ'.

    ``jac`` is the loss-scaled Jacobian of ``least_squares``; the inverse is taken with the
    columns scaled by ``scale`` (the parameters' typical sizes) for conditioning.
    """
    p = jac.shape[1]
    weights = _loss_weights((fun / f_scale) ** 2, loss)
    dof = max(float(np.sum(weights)) - p, 1.0)
    s2 = float(np.sum(weights * fun**2)) / dof
    js = jac * scale
    cov: _Array = np.linalg.pinv(js.T @ js, hermitian=True) * np.outer(scale, scale) * s2
    return cov, weights


@dataclass
class _Fit:
    """Mutable state of the estimation (local to one call)."""

    problem: JointProblem
    full: _Array
    prior: _Array
    free: NDArray[np.bool_]
    x_scale: _Array
    loss: str
    f_scale: float
    notes: list[str] = field(default_factory=list)
    held: list[str] = field(default_factory=list)
    converged: bool = True

    def hold(self, name: str, reason: str) -> None:
        j = self.problem.names.index(name)
        if not self.free[j]:
            return
        self.free[j] = False
        self.full[j] = self.prior[j]
        self.held.append(name)
        source = "the installed value" if _kind(name) in ("scale", "crosstalk") else "its prior"
        self.notes.append(
            f"{name}: not observable ({reason}); held at {self.prior[j]:.6g} ({source})"
        )

    def run(self) -> tuple[_Array, _Array]:
        """Least squares over the free parameters; returns (robust) Jacobian and residuals."""
        from scipy.optimize import least_squares  # 0.35 s to import: only fits need it

        idx = np.flatnonzero(self.free)
        steps = _FD_STEP * self.x_scale
        res = least_squares(
            lambda x: self.problem.residuals(x, self.full, idx),
            self.full[idx],
            jac=lambda x: self.problem.jacobian(x, self.full, idx, steps),
            loss=self.loss,
            f_scale=self.f_scale,
            x_scale=self.x_scale[idx],
            method="trf",
            xtol=1e-10,
            ftol=1e-10,
            gtol=1e-10,
            max_nfev=_MAX_NFEV,
        )
        self.full[idx] = res.x
        self.converged = res.status > 0
        return np.asarray(res.jac), np.asarray(res.fun)


def _check_options(
    loss: str, f_scale: float, model_sigma_m: float, noise: tuple[float, float, float, float]
) -> None:
    if loss not in _LOSSES:
        msg = f"loss must be one of {', '.join(_LOSSES)}, got {loss!r}"
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
) -> JointEstimate:
    """Estimate the seven factors, the alignments, the hedgehog offset (and latency) together.

    Never reads ``/ground_truth``: only ``/odom`` and the IPS topics (or the given fixes).

    Args:
        recordings: one or more recordings with ``/odom`` and the IPS topics (or ``fixes``).
        installed: factors the vehicle controller compensated the recordings with (default
            identity); also the prior at which unobservable factors are held.
        fixes: precomputed fixes per recording (default: :func:`omnical.ips.from_recording.locate`).
        estimate_latency: also estimate the IPS latency (else it is held at ``latency_s``).
        latency_s: assumed (or initial) delay from emission to the fix's bag time, s.
        hedge_offset_m: initial (and, when unobservable, held) hedgehog (x, y) in base_link, m.
        loss: robust loss of ``scipy.optimize.least_squares`` (``soft_l1``, ``cauchy``, ...).
        f_scale: inlier scale of the loss, in whitened units (standard deviations).
        model_sigma_m: added in quadrature to every fix's covariance (timing, unmodelled slip), m.
        heading_noise_rad_per_sqrt_rad: prior σ of the odometry's heading random walk per
            square root of radian turned (slip while turning).
        heading_noise_rad_per_sqrt_m: the same per square root of metre travelled.
        position_noise_m_per_sqrt_m: prior σ of the odometry's position random walk along the
            direction of travel, per square root of metre travelled (slip).
        cross_noise_m_per_sqrt_m: the same across the direction of travel.
        max_sigma: largest one-sigma uncertainty for a parameter to count as observable, per
            kind ``scale``, ``crosstalk`` (rad/m), ``offset`` (m), ``latency`` (s); defaults
            0.01, 0.01, 0.02, 0.05.

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
        )
        for i, rec in enumerate(recordings)
    ]
    problem = JointProblem(tracks)
    content = tracks[0].content
    for tr in tracks[1:]:
        content = content + tr.content
    fit = _initial_fit(problem, prior, hedge_offset_m, latency_s, loss, f_scale)
    if not estimate_latency:
        fit.free[problem.names.index(LATENCY_NAME)] = False
    for name, reason in _content_holds(content, estimate_latency):
        fit.hold(name, reason)
    if not np.any(fit.free[:N_SHARED]):
        msg = "the recordings hold too little motion to estimate any correction factor"
        raise CalibrationError(msg)

    jac, fun = fit.run()
    for _ in range(3):
        weak = _weak_parameters(fit, jac, fun, limits)
        if not weak:
            break
        for name, reason in weak:
            fit.hold(name, reason)
        jac, fun = fit.run()
    return _result(fit, jac, fun, content, prior)


def _initial_fit(
    problem: JointProblem,
    prior: CorrectionFactors,
    hedge_offset_m: tuple[float, float],
    latency_s: float,
    loss: str,
    f_scale: float,
) -> _Fit:
    """Prior factors, given offset and latency, zero perturbations, Procrustes alignments."""
    names = problem.names
    full = np.zeros(len(names))
    full[:7] = prior.as_vector()
    full[7:9] = hedge_offset_m
    full[9] = latency_s
    for i, tr in enumerate(problem.tracks):
        poses = problem.poses(full, i)
        q = interpolate_track(tr.t_s, hedge_track(poses, full[7:9]), tr.fix_t_s - latency_s)
        full[problem.align_slice(i)] = _procrustes(q, tr.fix_xy)
    x_scale = np.concatenate(
        [
            [_X_SCALE[_kind(n)] for n in names[:N_SHARED]],
            list(_ALIGN_X_SCALE) * len(problem.tracks),
            *[tr.knot_sigma for tr in problem.tracks],
        ]
    )
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
    fit: _Fit, jac: _Array, fun: _Array, limits: dict[str, float]
) -> list[tuple[str, str]]:
    """Free named parameters the fixes do not determine (tiny column or σ beyond the limit)."""
    idx = np.flatnonzero(fit.free)
    cov, _ = _covariance(jac, fun, fit.x_scale[idx], fit.loss, fit.f_scale)
    norms = np.linalg.norm(jac * fit.x_scale[idx], axis=0)
    top = max(float(norms.max()), 1e-300)
    weak: list[tuple[str, str]] = []
    for k, j in enumerate(idx):
        name = fit.problem.names[j]
        kind = _kind(name)
        if kind in ("alignment", "slip"):
            continue
        sd = math.sqrt(max(float(cov[k, k]), 0.0))
        if norms[k] < 1e-6 * top:
            weak.append((name, "the fixes do not depend on it"))
        elif not sd <= limits[kind]:
            weak.append((name, f"its one sigma from the fixes, {sd:.3g}, exceeds {limits[kind]:g}"))
    return weak


def _result(
    fit: _Fit, jac: _Array, fun: _Array, content: MotionContent, prior: CorrectionFactors
) -> JointEstimate:
    problem = fit.problem
    names = problem.names
    idx = np.flatnonzero(fit.free)
    cov, weights = _covariance(jac, fun, fit.x_scale[idx], fit.loss, fit.f_scale)
    whitened = problem.whitened(fit.full)
    series: list[_Array] = []
    start = 0
    for w in whitened:
        n = w.shape[0]
        wt = weights[start : start + 2 * n].reshape(n, 2)
        series.extend([np.sqrt(wt[:, 0]) * w[:, 0], np.sqrt(wt[:, 1]) * w[:, 1]])
        start += 2 * n
    tau = _autocorrelation_time(series)
    cov = cov * tau
    sigma_all = np.full(len(names), np.nan)
    sigma_all[idx] = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr_all = np.full((len(names), len(names)), np.nan)
    sd = sigma_all[idx]
    with np.errstate(invalid="ignore", divide="ignore"):
        corr_all[np.ix_(idx, idx)] = cov / np.outer(sd, sd)
    n_named = problem.n_named

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
        sigma={n: float(s) for n, s in zip(names[:n_named], sigma_all[:n_named], strict=True)},
        alignments=tuple(
            Alignment(*(float(v) for v in full[problem.align_slice(i)]))
            for i in range(len(problem.tracks))
        ),
        hedge_offset_m=(float(full[7]), float(full[8])),
        latency_s=float(full[9]),
        residual_rms_m=rms,
        warnings=tuple(notes),
        n_fixes_used=int(dist.size),
        n_outliers=int(np.count_nonzero(~inlier)),
        held=tuple(fit.held),
        parameter_names=names[:n_named],
        correlation=corr_all[:n_named, :n_named],
        content=content,
        installed=prior,
        correlation_inflation=float(tau),
        n_slip_parameters=sum(tr.knot_index.size for tr in problem.tracks),
    )
