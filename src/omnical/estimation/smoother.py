"""Batch smoother of a whole run: wheel odometry, IPS fixes and the gyro, in one least squares.

:func:`smooth_track` gives every pose with its 1σ, the IPS latency, an odometry correction and the
gyro bias; :class:`SmootherCheck` says whether to trust it. Design: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Final, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import cho_solve_banded, cholesky_banded

from omnical.errors import ConfigError, GeometryError
from omnical.estimation.handover import Handover, taken
from omnical.estimation.keyframes import (
    bridge,
    increment_design,
    keyframes_by_time,
    odometry_increments,
    preintegrate,
)
from omnical.estimation.se2 import compose_poses, transform_points

__all__ = [
    "SHARED_NAMES",
    "SmoothedTrack",
    "SmootherCheck",
    "SmootherParams",
    "smooth_track",
]

F64 = NDArray[np.float64]

SHARED_NAMES: Final[tuple[str, ...]] = (
    "latency_s",
    "scale_x",
    "scale_y",
    "scale_yaw",
    "crosstalk_forward_rad_per_m",
    "crosstalk_backward_rad_per_m",
    "crosstalk_left_rad_per_m",
    "crosstalk_right_rad_per_m",
    "gyro_bias_radps",
    "hedge_offset_x_m",
    "hedge_offset_y_m",
)
"""The shared parameters, in their order in :attr:`SmoothedTrack.shared`. Scales are relative
corrections (0 = the odometry is right)."""

_LAT, _GYRO = 0, 8
_OFF: Final = (9, 10)
_FIX_SHARED: Final = (_LAT, *_OFF)
"""The shared parameters an IPS fix depends on: the latency and the lever arm."""
_N_SHARED = len(SHARED_NAMES)
_BAND: Final = 5
"""Upper bandwidth of the pose block: 3×3 blocks, every factor on two consecutive poses."""
_GAUGE: Final = np.array([1e-3, 1e-3, 1e-2])
"""σ⁻¹ of the weak damping on the first pose (the gauge when the fixes do not fix it)."""
_INIT_WINDOW_S: Final = 60.0
"""Length of the windows of the rigid fits that start a long run's smoothing, s."""
_CHUNK: Final = 4096
"""Odometry intervals linearised at a time: bounds the temporaries whatever the run's length."""
_FIX_CHUNKED: Final = 32_768
"""Fixes whose covariance terms (:class:`_Tally`) are made at a time: bounds the temporaries
whatever the run's length."""


@dataclass(frozen=True)
class SmootherParams:
    """Noise model and settings of the batch smoother.

    Attributes:
        hedge_offset_m: hedgehog (x, y) in base_link, m.
        odom_trans_sigma_per_m: σ of each body-axis increment per metre travelled (slip left
            after the estimated correction).
        odom_yaw_sigma_per_rad: σ of the yaw increment per radian turned.
        odom_yaw_sigma_per_m: σ of the yaw increment per metre travelled, rad/m.
        position_random_walk_m: position random walk, m/√s.
        yaw_random_walk_rad: yaw random walk, rad/√s.
        gyro_sigma_rad: σ of the integrated gyro yaw change per √s, rad/√s.
        fix_sigma_floor_m: added in quadrature to every fix's own σ (per axis), m.
        huber_k: Huber threshold on a fix's whitened residual norm (in σ).
        latency_s: the IPS latency to start from (held there when not estimated), s.
        odometry_delay_s: how long after the motion the odometry is stamped, s; the smoothed
            poses are returned at the stamps minus this.
        estimate_latency: estimate τ (needs motion).
        latency_prior_sigma_s: σ of the prior on τ around ``latency_s``.
        estimate_odometry_factors: estimate the odometry correction.
        scale_prior_sigma: σ of the prior on each relative scale correction (around 0).
        crosstalk_prior_sigma_rad_per_m: σ of the prior on each cross-talk (around 0).
        gyro_bias_prior_sigma_radps: σ of the prior on the gyro bias.
        estimate_hedge_offset: estimate the lever arm (prior ``hedge_offset_m``) when the run
            turns at least ``offset_min_rotation_rad`` in all; else it is held at the prior.
        hedge_offset_prior_sigma_m: σ of the prior on each lever-arm coordinate, m.
        offset_min_rotation_rad: least total rotation (odometry, faster than 0.02 rad/s) for the
            lever arm to be estimated: the joint calibration's rule (π).
        noise_rounds: rounds of the noise scales' estimation (variance components per group);
            1: the noise model as given.
        check_max_chi2_per_dof: the self-check fails when the fixes' normalised residuals
            (against their own covariance) have a χ² per degree of freedom above this.
        check_min_band_share: ... or when fewer of the trusted fixes than this lie inside the
            smoothed track's 95 % band (its own covariance plus the fix's).
        check_max_odometry_noise_scale: ... or when the odometry had to be made noisier than
            the model by more than this factor (σ) to fit the fixes.
        max_iterations: Gauss–Newton iterations at most.
        long_run_s: a run longer than this (s) is smoothed through keyframes; None: every
            odometry sample is a pose node.
        keyframe_interval_s: the keyframes' spacing on a long run, s, at most 1 s.

    Raises:
        ConfigError: a negative or non-finite value, a non-positive σ, threshold or count.
    """

    hedge_offset_m: tuple[float, float] = (0.0, 0.0)
    odom_trans_sigma_per_m: float = 0.01
    odom_yaw_sigma_per_rad: float = 0.01
    odom_yaw_sigma_per_m: float = 0.005
    position_random_walk_m: float = 0.001
    yaw_random_walk_rad: float = 0.001
    gyro_sigma_rad: float = 0.002
    fix_sigma_floor_m: float = 0.003
    huber_k: float = 2.5
    latency_s: float = 0.0
    odometry_delay_s: float = 0.0
    estimate_latency: bool = True
    latency_prior_sigma_s: float = 0.3
    estimate_odometry_factors: bool = True
    scale_prior_sigma: float = 0.1
    crosstalk_prior_sigma_rad_per_m: float = 0.05
    gyro_bias_prior_sigma_radps: float = 0.01
    estimate_hedge_offset: bool = True
    hedge_offset_prior_sigma_m: float = 0.05
    offset_min_rotation_rad: float = math.pi
    noise_rounds: int = 4
    check_max_chi2_per_dof: float = 2.0
    check_min_band_share: float = 0.9
    check_max_odometry_noise_scale: float = 3.0
    max_iterations: int = 30
    long_run_s: float | None = 300.0
    keyframe_interval_s: float = 0.1

    def __post_init__(self) -> None:
        if len(self.hedge_offset_m) != 2 or not all(math.isfinite(v) for v in self.hedge_offset_m):
            msg = f"hedge_offset_m must be 2 finite numbers (x, y), got {self.hedge_offset_m}"
            raise ConfigError(msg)
        if not math.isfinite(self.latency_s):
            raise ConfigError(f"latency_s must be finite, got {self.latency_s}")
        if not (math.isfinite(self.odometry_delay_s) and abs(self.odometry_delay_s) <= 10.0):
            msg = f"odometry_delay_s must be finite and within ±10 s, got {self.odometry_delay_s}"
            raise ConfigError(msg)
        for name in ("odom_trans_sigma_per_m", "odom_yaw_sigma_per_rad", "odom_yaw_sigma_per_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigError(f"{name} must be finite and >= 0, got {value}")
        for name in (
            "position_random_walk_m",
            "yaw_random_walk_rad",
            "gyro_sigma_rad",
            "fix_sigma_floor_m",
            "huber_k",
            "latency_prior_sigma_s",
            "scale_prior_sigma",
            "crosstalk_prior_sigma_rad_per_m",
            "gyro_bias_prior_sigma_radps",
            "hedge_offset_prior_sigma_m",
            "check_max_chi2_per_dof",
            "check_max_odometry_noise_scale",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f"{name} must be finite and > 0, got {value}")
        if not (math.isfinite(self.offset_min_rotation_rad) and self.offset_min_rotation_rad >= 0):
            msg = f"offset_min_rotation_rad must be finite and >= 0, got {self.offset_min_rotation_rad}"
            raise ConfigError(msg)
        if not 0.0 <= self.check_min_band_share <= 1.0:
            msg = f"check_min_band_share must be within [0, 1], got {self.check_min_band_share}"
            raise ConfigError(msg)
        if self.max_iterations < 1:
            raise ConfigError(f"max_iterations must be >= 1, got {self.max_iterations}")
        if not 1 <= self.noise_rounds <= 20:
            raise ConfigError(f"noise_rounds must be within 1 … 20, got {self.noise_rounds}")
        if self.long_run_s is not None and not (
            math.isfinite(self.long_run_s) and self.long_run_s >= 0.0
        ):
            raise ConfigError(
                f"long_run_s must be finite and >= 0 (or None), got {self.long_run_s}"
            )
        if not (math.isfinite(self.keyframe_interval_s) and 0.0 < self.keyframe_interval_s <= 1.0):
            msg = f"keyframe_interval_s must be within (0, 1] s, got {self.keyframe_interval_s}"
            raise ConfigError(msg)


@dataclass(frozen=True)
class SmootherCheck:
    """The smoother's check of itself against its own fixes, and the noise scales it found.

    Attributes:
        fix_chi2_per_dof: Σ w d² / Σ w (2 − t) over the trusted fixes inside the run: d² the
            residual normalised by the fix's own covariance (plus the floor), t = tr(C_fix⁻¹
            C_pred), w the Huber weight; ≈ 1 when the fixes are as noisy as they say.
        fixes_in_band_95: share of those fixes inside the smoothed hedgehog's 95 % band
            (residual normalised by the fix's covariance plus the prediction's: χ²(2) ≤ 5.99).
        odometry_noise_scale: the factor the odometry's σ was scaled by to match its residuals
            (1 with ``noise_rounds`` 1).
        fix_noise_scale: the same for the fixes' σ.
        rounds: the rounds of solution the scales took (the gyro's last one included).
        odometry_dof: the odometry residuals' degrees of freedom (their redundancy).
        passed: every criterion of :class:`SmootherParams` holds (and the solution converged).
        reasons: one phrase per failed criterion.
    """

    fix_chi2_per_dof: float
    fixes_in_band_95: float
    odometry_noise_scale: float
    fix_noise_scale: float
    rounds: int
    odometry_dof: float
    passed: bool
    reasons: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class SmoothedTrack:
    """The smoothed trajectory and what the smoother learned about the run.

    Attributes:
        t_s: (N,) times (the odometry's), s.
        poses: (N, 3) x m, y m, yaw rad of base_link in map (yaw continuous).
        covariance: (N, 3, 3) marginal covariance of each pose.
        shared: (len(SHARED_NAMES),) the shared parameters (:data:`SHARED_NAMES`).
        shared_sigma: their 1σ (0 for a parameter held fixed).
        fixes_used: fixes inside the odometry's span that entered the solution.
        fixes_downweighted: of those, how many the Huber loss down-weighted at the solution.
        fix_residual_rms_m: RMS of the fixes' residuals (hedgehog, metres) at the solution.
        iterations: Gauss–Newton iterations run.
        converged: the last step was negligible.
        keyframe_stride: odometry samples per pose node on average (1 on a short run).
        check: the self-check against the fixes (:class:`SmootherCheck`); None: not made.
    """

    t_s: F64
    poses: F64
    covariance: F64
    shared: F64
    shared_sigma: F64
    fixes_used: int
    fixes_downweighted: int
    fix_residual_rms_m: float
    iterations: int
    converged: bool
    keyframe_stride: int = 1
    check: SmootherCheck | None = None

    @property
    def latency_s(self) -> float:
        """The IPS latency the smoother found (or held), s."""
        return float(self.shared[_LAT])

    @property
    def latency_sigma_s(self) -> float:
        """1σ of :attr:`latency_s` (0 when held)."""
        return float(self.shared_sigma[_LAT])

    @property
    def position_sigma_m(self) -> F64:
        """(N,) sqrt(σ_x² + σ_y²) of every smoothed position, m."""
        out: F64 = np.sqrt(self.covariance[:, 0, 0] + self.covariance[:, 1, 1])
        return out

    @property
    def position_sigma_rms_m(self) -> float:
        """RMS of :attr:`position_sigma_m`: how far the smoothed positions are from the truth."""
        return float(np.sqrt(np.mean(self.position_sigma_m**2)))

    @property
    def hedge_offset_m(self) -> tuple[float, float]:
        """The hedgehog's lever arm in base_link the smoother found (or held), m."""
        return float(self.shared[_OFF[0]]), float(self.shared[_OFF[1]])

    @property
    def trustworthy(self) -> bool:
        """Converged and its self-check passed: the estimate to quote."""
        return self.converged and self.check is not None and self.check.passed

    def shared_dict(self) -> dict[str, tuple[float, float]]:
        """Name → (value, 1σ) of the shared parameters."""
        return {
            n: (float(v), float(s))
            for n, v, s in zip(SHARED_NAMES, self.shared, self.shared_sigma, strict=True)
        }


# --------------------------------------------------------------------------- model


def _rot(yaw: F64) -> tuple[F64, F64]:
    return np.cos(yaw), np.sin(yaw)


@dataclass(frozen=True, eq=False)
class _Problem:
    t: F64
    inc: F64
    odom_whiten: F64  # (K, 3, 3) whitener of inc, Wᵀ W = Σ⁻¹ (diagonal at full rate)
    gyro_dpsi: F64 | None  # (K,)
    gyro_sigma_rad: float  # σ of the integrated yaw per √s (the intervals' from the node times)
    fix_t: F64
    fix_xy: F64
    fix_whiten: F64  # (M, 2, 2): W with Wᵀ W = C⁻¹
    prior_sigma: F64  # (N_SHARED,)
    prior_mean: F64
    free: NDArray[np.bool_]
    design: F64 | None = None  # (K, 3, 7) ∂inc/∂θ given (keyframes); None: from inc
    odom_scale: float = 1.0  # every odometry σ times this (the noise scale found)
    fix_scale: float = 1.0  # every fix σ times this

    def fix_whiteners(self, rows: slice = slice(None)) -> F64:
        """The fixes' whiteners as weighed (their own over :attr:`fix_scale`)."""
        w = self.fix_whiten[rows]
        out: F64 = w if self.fix_scale == 1.0 else w / self.fix_scale
        return out


def _whiteners(cov: F64, floor_m: float) -> F64:
    c = cov + np.eye(2) * floor_m**2
    inv = np.linalg.inv(c)
    # Wᵀ W = C⁻¹: W = Lᵀ with L L ᵀ = C⁻¹ (Cholesky)
    chol = np.linalg.cholesky(inv)
    out: F64 = np.transpose(chol, (0, 2, 1))
    return out


def _fix_geometry(
    pr: _Problem, poses: F64, shared: F64, rows: slice = slice(None)
) -> tuple[NDArray[np.intp], F64, F64, F64, F64, F64, NDArray[np.bool_]]:
    """Interval index, interpolation weight, modelled hedgehog, d h/d s, ∂h/∂ψ and
    (cos ψ, sin ψ) per fix (of the fixes ``rows``), at the latency and lever arm of ``shared``."""
    s = pr.fix_t[rows] - float(shared[_LAT])
    n = pr.t.size
    inside = (s >= pr.t[0]) & (s <= pr.t[-1])
    k = np.clip(np.searchsorted(pr.t, s, side="right") - 1, 0, n - 2)
    dt = pr.t[k + 1] - pr.t[k]
    a = np.where(dt > 0, (s - pr.t[k]) / np.where(dt > 0, dt, 1.0), 0.0)
    a = np.clip(a, 0.0, 1.0)
    p0, p1 = poses[k], poses[k + 1]
    pose = p0 + a[:, None] * (p1 - p0)
    c, sn = _rot(pose[:, 2])
    ox, oy = float(shared[_OFF[0]]), float(shared[_OFF[1]])
    h = np.column_stack([pose[:, 0] + c * ox - sn * oy, pose[:, 1] + sn * ox + c * oy])
    dh_dpsi = np.column_stack([-sn * ox - c * oy, c * ox - sn * oy])
    rate = (p1 - p0) / np.where(dt > 0, dt, 1.0)[:, None]
    dh_ds = rate[:, :2] + dh_dpsi * rate[:, 2:3]
    return k, a, h, dh_ds, dh_dpsi, np.column_stack([c, sn]), inside


def _huber_weights(norm: F64, k: float) -> F64:
    w: F64 = np.where(norm <= k, 1.0, k / np.maximum(norm, 1e-12))
    return w


@dataclass(frozen=True, eq=False)
class _Normal:
    """The IRLS-weighted normal equations H δ = b of one linearisation, in the arrow structure.

    H = [[A, C], [Cᵀ, E]]: A (3N × 3N) the pose block, block tridiagonal, kept as its upper band
    in LAPACK storage (``band[_BAND + i − j, j] = A[i, j]`` for i ≤ j ≤ i + _BAND); C the poses'
    coupling to the free shared parameters; E the free shared parameters' block.
    """

    band: F64  # (_BAND + 1, 3N)
    border: F64  # (F, N, 3): Cᵀ, a contiguous row per shared parameter
    shared: F64  # (F, F)
    b_pose: F64  # (N, 3)
    b_shared: F64  # (F,)


def _scatter_intervals(
    nm: _Normal, free: NDArray[np.intp], k0: int, h6: F64, c6: F64, g6: F64, gs: F64
) -> None:
    """Add the blocks of intervals k0 … k0 + L − 1 (each on poses k and k + 1) to ``nm``."""
    k1 = k0 + h6.shape[0]
    for i in range(6):
        for j in range(i, 6):  # H[3k + i, 3k + j], k = k0 … k1 − 1
            nm.band[_BAND + i - j, 3 * k0 + j : 3 * k1 + j : 3] += h6[:, i, j]
    nm.border[:, k0:k1] += np.transpose(c6[:, :3, free], (2, 0, 1))
    nm.border[:, k0 + 1 : k1 + 1] += np.transpose(c6[:, 3:, free], (2, 0, 1))
    nm.b_pose[k0:k1] += g6[:, :3]
    nm.b_pose[k0 + 1 : k1 + 1] += g6[:, 3:]
    nm.b_shared[:] += gs[free]


@dataclass(frozen=True, eq=False)
class _Fixes:
    """What the normal equations take of some fixes: interval, weight a, ∂h/∂s, ∂h/∂ψ,
    (cos ψ, sin ψ), inside, whitener W, whitened residual and √(Huber weight)."""

    kk: NDArray[np.intp]
    a: F64
    dh_ds: F64
    dh_dpsi: F64
    rot: F64
    inside: NDArray[np.bool_]
    w_mat: F64
    white: F64
    sw: F64


def _fixes_part(
    pr: _Problem, poses: F64, shared: F64, huber_k: float, rows: slice
) -> tuple[_Fixes, F64]:
    """The fixes ``rows``: their :class:`_Fixes` and (robust cost, fixes used, down-weighted,
    Σ squared residual, its count)."""
    kk, a, h, dh_ds, dh_dpsi, rot, inside = _fix_geometry(pr, poses, shared, rows)
    w_mat = pr.fix_whiteners(rows)
    raw = pr.fix_xy[rows] - h
    white = (w_mat @ raw[:, :, None])[:, :, 0]
    norm = np.hypot(white[:, 0], white[:, 1])
    weight = _huber_weights(norm, huber_k) * inside
    rho = np.where(norm <= huber_k, 0.5 * norm**2, huber_k * norm - 0.5 * huber_k**2) * inside
    sums = np.array(
        [
            float(np.sum(rho)),
            float(np.sum(inside)),
            float(np.sum(inside & (norm > huber_k))),
            float(np.sum(raw[inside] ** 2)),
            float(np.sum(inside)),
        ]
    )
    return _Fixes(kk, a, dh_ds, dh_dpsi, rot, inside, w_mat, white, np.sqrt(weight)), sums


def _fix_shared_jacobian(dh_ds: F64, rot: F64) -> F64:
    """(M, 2, 3) ∂h/∂(τ, o_x, o_y) of the modelled hedgehog: −dh/ds (a later latency is an
    earlier pose) and R(ψ)."""
    out = np.empty((dh_ds.shape[0], 2, 3))
    out[:, :, 0] = -dh_ds
    out[:, 0, 1], out[:, 0, 2] = rot[:, 0], -rot[:, 1]
    out[:, 1, 1], out[:, 1, 2] = rot[:, 1], rot[:, 0]
    return out


def _add_fixes(
    blocks: tuple[F64, F64, F64, F64, F64],
    local: NDArray[np.intp],
    f: _Fixes,
    pick: NDArray[np.intp],
) -> None:
    """Add the fixes ``pick`` of ``f`` (on intervals ``local`` of the run) to the run's
    ``blocks`` (h6, c6, g6, the shared gradient, the shared block)."""
    h6, c6, g6, gs, e_full = blocks
    # r = W (z − h): ∂r/∂(x_k, y_k, ψ_k) = −(1−a) W [I | dh_dpsi]; x_{k+1}: −a W [...];
    # ∂r/∂(τ, o) = −W ∂h/∂(τ, o)
    wm, ws, ap = f.w_mat[pick], f.sw[pick, None], f.a[pick, None, None]
    r_fix = f.white[pick] * ws
    jac_pose = np.zeros((pick.size, 2, 3))
    jac_pose[:, 0, 0] = 1.0
    jac_pose[:, 1, 1] = 1.0
    jac_pose[:, :, 2] = f.dh_dpsi[pick]
    wj = -(wm @ jac_pose) * ws[:, :, None]
    jf = np.concatenate([wj * (1.0 - ap), wj * ap], axis=2)
    j_sh = -(wm @ _fix_shared_jacobian(f.dh_ds[pick], f.rot[pick])) * ws[:, :, None]
    jft = np.swapaxes(jf, 1, 2)
    np.add.at(h6, local, jft @ jf)
    cross = jft @ j_sh
    for i, col in enumerate(_FIX_SHARED):
        np.add.at(c6[:, :, col], local, cross[:, :, i])
    np.add.at(g6, local, -(jft @ r_fix[:, :, None])[:, :, 0])
    cols = list(_FIX_SHARED)
    gs[cols] -= np.einsum("mri,mr->i", j_sh, r_fix)
    e_full[np.ix_(cols, cols)] += np.einsum("mri,mrj->ij", j_sh, j_sh)


def _linearise(
    pr: _Problem, poses: F64, shared: F64, huber_k: float, *, normal: bool = True
) -> tuple[_Normal | None, float, dict[str, float]]:
    """The robust cost at (poses, shared) and, with ``normal``, the normal equations there.

    The factors are visited in runs of :data:`_CHUNK` odometry intervals (with the fixes that
    fall in them), each run's blocks added straight into the banded pose block and the border,
    so the temporaries stay bounded whatever the length of the run.
    """
    n = poses.shape[0]
    free = np.flatnonzero(pr.free)
    nf = free.size
    theta = shared[1:8]
    # the fixes with their intervals, a run of intervals at a time (intervals sorted: a slice)
    k_all = np.clip(
        np.searchsorted(pr.t, pr.fix_t - float(shared[_LAT]), side="right") - 1, 0, n - 2
    )
    odometry_ss = gyro_ss = cost = 0.0  # Σ r² of the odometry's and the gyro's whitened residuals
    tally = np.zeros(4)  # fixes used, down-weighted, Σ squared residual (m²), its count
    # --- priors on the shared parameters (the weak one on the first pose is on the step only:
    # the gauge when the fixes do not fix it; no residual)
    ps = 1.0 / pr.prior_sigma
    r_prior = (shared - pr.prior_mean) * ps
    cost += 0.5 * float(r_prior @ r_prior)
    nm: _Normal | None = None
    e_full = np.zeros((_N_SHARED, _N_SHARED))
    if normal:
        nm = _Normal(
            band=np.zeros((_BAND + 1, 3 * n), order="F"),  # LAPACK's order: factored in place
            border=np.zeros((nf, n, 3)),
            shared=np.zeros((nf, nf)),
            b_pose=np.zeros((n, 3)),
            b_shared=np.zeros(nf),
        )
        e_full += np.diag(ps**2)
        nm.b_shared[:] -= (ps * r_prior)[free]
        nm.band[_BAND, :3] += _GAUGE**2
    for k0 in range(0, n - 1, _CHUNK):
        k1 = min(k0 + _CHUNK, n - 1)
        length = k1 - k0
        f0, f1 = (int(i) for i in np.searchsorted(k_all, (k0, k1)))
        f, part = _fixes_part(pr, poses, shared, huber_k, slice(f0, f1))
        cost += part[0]
        tally += part[1:]
        # --- odometry between-factors
        inc = pr.inc[k0:k1]
        design = increment_design(inc) if pr.design is None else pr.design[k0:k1]
        corrected = inc + design @ theta
        p0, p1 = poses[k0:k1], poses[k0 + 1 : k1 + 1]
        c, s = _rot(p0[:, 2])
        dx, dy = p1[:, 0] - p0[:, 0], p1[:, 1] - p0[:, 1]
        e = np.column_stack([c * dx + s * dy, -s * dx + c * dy, p1[:, 2] - p0[:, 2]]) - corrected
        wo = pr.odom_whiten[k0:k1]  # the σ scale applied after
        r_odo = (wo @ e[:, :, None])[:, :, 0] / pr.odom_scale
        odometry_ss += float(np.sum(r_odo**2))
        r_gyro: F64 | None = None
        ig: F64 | None = None
        gdt: F64 | None = None
        if pr.gyro_dpsi is not None:
            gdt = np.diff(pr.t[k0 : k1 + 1])  # the intervals' durations (not held: from t)
            eg = (p1[:, 2] - p0[:, 2]) - (pr.gyro_dpsi[k0:k1] - shared[_GYRO] * gdt)
            ig = 1.0 / (pr.gyro_sigma_rad * np.sqrt(gdt))
            r_gyro = eg * ig
            gyro_ss += float(r_gyro @ r_gyro)
        if nm is None:
            continue
        jo = np.zeros((length, 3, 6))
        jo[:, 0, :5] = np.stack([-c, -s, -s * dx + c * dy, c, s], axis=1)
        jo[:, 1, :5] = np.stack([s, -c, -c * dx - s * dy, -s, c], axis=1)
        jo[:, 2, 2] = -1.0
        jo[:, 2, 5] = 1.0
        jo = (wo @ jo) / pr.odom_scale
        js = -(wo @ design) / pr.odom_scale  # ∂r/∂θ = −W G (θ: the shared parameters 1 … 7)
        jot = np.swapaxes(jo, 1, 2)
        h6 = jot @ jo
        c6 = np.zeros((length, 6, _N_SHARED))
        np.matmul(jot, js, out=c6[:, :, 1:8])
        g6 = -(jot @ r_odo[:, :, None])[:, :, 0]
        js2 = js.reshape(-1, 7)
        e_full[1:8, 1:8] += js2.T @ js2
        gs = np.zeros(_N_SHARED)
        gs[1:8] = -(js2.T @ r_odo.reshape(-1))
        if r_gyro is not None and ig is not None and gdt is not None:
            # r = ig (ψ_{k+1} − ψ_k − Δψ_gyro + b dt): ∂r/∂ψ_k = −ig, ∂r/∂ψ_{k+1} = ig, ∂r/∂b = ig dt
            ig2 = ig**2
            h6[:, 2, 2] += ig2
            h6[:, 5, 5] += ig2
            h6[:, 2, 5] -= ig2
            h6[:, 5, 2] -= ig2
            jb = ig * gdt
            c6[:, 2, _GYRO] -= ig * jb
            c6[:, 5, _GYRO] += ig * jb
            e_full[_GYRO, _GYRO] += float(jb @ jb)
            g6[:, 2] += ig * r_gyro
            g6[:, 5] -= ig * r_gyro
            gs[_GYRO] -= float(jb @ r_gyro)
        # --- the IPS fixes whose interval is in this run
        pick = np.flatnonzero(f.inside)
        if pick.size:
            _add_fixes((h6, c6, g6, gs, e_full), f.kk[pick] - k0, f, pick)
        _scatter_intervals(nm, free, k0, h6, c6, g6, gs)
    cost += 0.5 * (odometry_ss + gyro_ss)
    info = {
        "fixes_used": float(tally[0]),
        "downweighted": float(tally[1]),
        "residual_rms_m": float(np.sqrt(tally[2] / tally[3])) if tally[3] else float("nan"),
        "odometry_ss": odometry_ss,
        "gyro_ss": gyro_ss,
    }
    if nm is not None:
        nm.shared[:] = e_full[np.ix_(free, free)]
    return nm, cost, info


# --------------------------------------------------------------------------- linear algebra


def _pose_factor(band: F64) -> F64 | None:
    """Upper banded Cholesky factor of the pose block, over ``band`` (None: not positive
    definite)."""
    try:
        cb = cholesky_banded(band, overwrite_ab=True, lower=False, check_finite=False)
    except np.linalg.LinAlgError:
        return None
    out: F64 = np.asarray(cb)
    return out


def _pose_solve(cb: F64, rhs: F64) -> F64:
    out: F64 = np.asarray(cho_solve_banded((cb, False), rhs, check_finite=False))
    return out


def _schur(nm: _Normal, cb: F64, shared: F64) -> F64:
    """E − Cᵀ A⁻¹ C, one column of C at a time (no 3N × F temporary)."""
    ct = nm.border.reshape(nm.border.shape[0], -1)
    out = shared.copy()
    for j in range(ct.shape[0]):
        out[:, j] -= ct @ _pose_solve(cb, ct[j])
    sym: F64 = 0.5 * (out + out.T)
    return sym


def _solve_banded(nm: _Normal, lam: float) -> tuple[F64, F64] | None:
    """The Levenberg–Marquardt step (H + λ diag H) δ = b by the Schur complement on the shared
    parameters and a banded Cholesky of the pose block; None: not positive definite.

    The pose block is damped and factored in place: ``nm.band`` is spent (a rejected step
    rebuilds the normal equations; no copy of the band is held meanwhile).
    """
    shared = nm.shared.copy()
    if lam > 0:
        nm.band[_BAND] *= 1.0 + lam
        shared[np.diag_indices_from(shared)] *= 1.0 + lam
    cb = _pose_factor(nm.band)
    if cb is None:
        return None
    n = nm.b_pose.shape[0]
    b_pose = nm.b_pose.reshape(-1)
    y = _pose_solve(cb, b_pose)
    ct = nm.border.reshape(-1, 3 * n)
    if ct.shape[0] == 0:
        return y.reshape(n, 3), np.zeros(0)
    try:
        d_shared = np.asarray(
            np.linalg.solve(_schur(nm, cb, shared), nm.b_shared - ct @ y), dtype=np.float64
        )
    except np.linalg.LinAlgError:
        return None
    d_pose = _pose_solve(cb, b_pose - ct.T @ d_shared)
    return d_pose.reshape(n, 3), d_shared


def _backward_congruence(p: F64, g: F64) -> F64:
    """Σ_{N−1} = P_{N−1}, Σ_k = P_k + G_k Σ_{k+1} G_kᵀ for k = N−2 … 0, written over ``p``.

    The recursion is sequential; it is run in √N chunks side by side: a first sweep finds each
    chunk's affine map Σ_start = α + Φ Σ_next Φᵀ from the chunk after it, the chunks' starts
    are chained, and a second sweep fills every chunk from its successor's start. About 3√N
    vectorised steps instead of N small ones.
    """
    n = p.shape[0]
    length = max(1, math.isqrt(n // 2))
    full = n // length
    tail = n - full * length
    # the tail (shorter than a chunk), straight
    nxt = np.zeros((3, 3))
    for k in range(n - 1, full * length - 1, -1):
        nxt = p[k] + g[k] @ nxt @ g[k].T
        p[k] = nxt
    if full == 0:
        return p
    nxt = p[full * length] if tail else np.zeros((3, 3))
    pv = p[: full * length].reshape(full, length, 3, 3)
    gv = g[: full * length].reshape(full, length, 3, 3)
    alpha = np.zeros((full, 3, 3))
    phi = np.broadcast_to(np.eye(3), (full, 3, 3)).copy()
    for j in range(length - 1, -1, -1):
        gj = gv[:, j]
        alpha = pv[:, j] + gj @ alpha @ np.swapaxes(gj, 1, 2)
        phi = gj @ phi
    starts = np.empty((full + 1, 3, 3))
    starts[full] = nxt
    for c in range(full - 1, -1, -1):
        starts[c] = alpha[c] + phi[c] @ starts[c + 1] @ phi[c].T
    cur = starts[1:].copy()
    for j in range(length - 1, -1, -1):
        gj = gv[:, j]
        cur = pv[:, j] + gj @ cur @ np.swapaxes(gj, 1, 2)
        pv[:, j] = cur
    return p


class _Visitor(Protocol):
    """What sees the covariance as the marginals are built (:class:`_Tally`)."""

    def pose_block(self, sigma: F64, g: F64) -> None:
        """The pose block's inverse: its diagonal blocks Σ_k and the G_k of Σ_k,k+1 = −G_k Σ_k+1."""

    def column(self, col: F64, root: F64) -> None:
        """One low-rank term of the shared parameters: the joint covariance of (poses, shared)
        is the pose block's inverse plus Σ_j v_j v_jᵀ, v_j = (−col_j, root_j)."""


def _marginals_banded(nm: _Normal, visit: _Visitor | None = None) -> tuple[F64, F64]:
    """Pose marginal covariances (N, 3, 3) and the free shared parameters' covariance.

    The pose block's inverse on its diagonal blocks from its banded Cholesky factor
    A = UᵀU (S_k⁻¹ = U_kk⁻¹ U_kk⁻ᵀ, G_k = U_kk⁻¹ U_k,k+1, Σ_k = S_k⁻¹ + G_k Σ_{k+1} G_kᵀ, and
    Σ_k,k+1 = −G_k Σ_k+1), plus the shared parameters' share (A⁻¹C) Σ_s (A⁻¹C)ᵀ, one column of
    C Σ_s^½ at a time; ``visit`` sees both as they are made.
    """
    n = nm.b_pose.shape[0]
    nf = nm.shared.shape[0]
    cb = _pose_factor(nm.band)  # nm.band is spent: the marginals are the last use of nm
    if cb is None:
        raise GeometryError("the smoothed poses' information matrix is not positive definite")
    p = np.empty((n, 3, 3))
    g = np.zeros((n, 3, 3))  # G_{N−1} = 0
    for k0 in range(0, n, _CHUNK):
        k1 = min(k0 + _CHUNK, n)
        u = np.zeros((k1 - k0, 3, 3))
        off = np.zeros((k1 - k0, 3, 3))  # U_k,k+1 (none after the last pose)
        for r in range(3):
            for c in range(3):
                if c >= r:  # U[3k + r, 3k + c]
                    u[:, r, c] = cb[_BAND + r - c, 3 * k0 + c : 3 * k1 + c : 3]
                # U[3k + r, 3(k + 1) + c]
                end = min(k1, n - 1)
                off[: end - k0, r, c] = cb[_BAND - 3 + r - c, 3 * k0 + 3 + c : 3 * end + 3 + c : 3]
        u_inv = np.asarray(np.linalg.inv(u), dtype=np.float64)
        p[k0:k1] = u_inv @ np.swapaxes(u_inv, 1, 2)
        g[k0:k1] = u_inv @ off
    sigma = _backward_congruence(p, g)
    if visit is not None:
        visit.pose_block(sigma, g)
    del g
    shared_cov: F64 = np.zeros((0, 0))
    if nf:
        shared_cov = np.asarray(np.linalg.inv(_schur(nm, cb, nm.shared)), dtype=np.float64)
        w, v = np.linalg.eigh(0.5 * (shared_cov + shared_cov.T))
        root = v * np.sqrt(np.maximum(w, 0.0))
        ct = nm.border.reshape(nf, 3 * n)
        for j in range(nf):
            col = _pose_solve(cb, ct.T @ root[:, j]).reshape(n, 3)
            sigma += col[:, :, None] * col[:, None, :]
            if visit is not None:
                visit.column(col, root[:, j])
    for i, j in ((0, 1), (0, 2), (1, 2)):
        mean = 0.5 * (sigma[:, i, j] + sigma[:, j, i])
        sigma[:, i, j] = mean
        sigma[:, j, i] = mean
    return sigma, shared_cov


# --------------------------------------------------------------------------- self-check

_CHI2_2_95: Final = 5.991464547107979
"""χ²(2) quantile 0.95: a fix inside the smoothed track's 95 % band."""
_MIN_DOF: Final = 5.0
"""Fewest degrees of freedom of a group's residuals for its noise scale to be estimated."""
_SCALE_RANGE: Final = (1e-2, 1e4)
"""Bounds of a group's variance factor (σ scaled by at most 10 down, 100 up)."""
_SETTLED: Final = 0.1
"""A group's variance ratio within this of 1 has settled (its σ within 5 %)."""
_ODOMETRY_FLOOR: Final = 0.04
"""Least variance factor of the odometry (σ at least a fifth of the model's)."""


class _Tally:
    """The covariance of the solution seen through each fix and each gyro interval.

    For a fix: the covariance C_h of the modelled hedgehog (its two poses interpolated with
    their cross-covariance, the latency and the lever arm), exactly from the normal matrix;
    for a gyro interval: the variance of its yaw change less the bias. What the fit took of a
    group's residuals (their redundancy) and the fixes' band follow from these. Per fix, only
    what the Jacobians are made of is held (they are rebuilt a chunk at a time).
    """

    def __init__(self, pr: _Problem, poses: F64, shared: F64, free_idx: NDArray[np.intp]) -> None:
        kk, a, h, dh_ds, dh_dpsi, rot, inside = _fix_geometry(pr, poses, shared)
        self.rows = np.flatnonzero(inside)
        every = self.rows.size == inside.size  # no copies when every fix is inside
        pick = slice(None) if every else self.rows
        self.kk, self.a, self.dh_dpsi = kk[pick], a[pick], dh_dpsi[pick]
        self.dh_ds, self.rot = dh_ds[pick], rot[pick]
        del kk, a, dh_ds, dh_dpsi, rot
        self.raw = pr.fix_xy[pick] - h[pick]
        del h
        where = {int(c): i for i, c in enumerate(free_idx)}
        self.keep = [i for i, c in enumerate(_FIX_SHARED) if c in where]
        self.root_rows = [where[_FIX_SHARED[i]] for i in self.keep]
        self.ch = np.zeros((self.kk.size, 2, 2))
        self.var_gyro: F64 | None = None
        self.bias_row = where.get(_GYRO)
        self.dt = np.diff(pr.t)
        if pr.gyro_dpsi is not None:
            self.var_gyro = np.zeros(pr.t.size - 1)

    def chunks(self) -> range:
        """Starts of the chunks of fixes the temporaries are bounded by."""
        return range(0, self.kk.size, _FIX_CHUNKED)

    def _jp(self, rows: slice) -> F64:
        jp = np.zeros((self.dh_dpsi[rows].shape[0], 2, 3))
        jp[:, 0, 0] = 1.0
        jp[:, 1, 1] = 1.0
        jp[:, :, 2] = self.dh_dpsi[rows]
        return jp

    def pose_block(self, sigma: F64, g: F64) -> None:
        for f0 in self.chunks():
            rows = slice(f0, f0 + _FIX_CHUNKED)
            k, a = self.kk[rows], self.a[rows, None, None]
            s1 = sigma[k + 1]
            x = -g[k] @ s1
            s_int = (
                (1.0 - a) ** 2 * sigma[k] + a**2 * s1 + a * (1.0 - a) * (x + np.swapaxes(x, 1, 2))
            )
            jp = self._jp(rows)
            self.ch[rows] += jp @ s_int @ np.swapaxes(jp, 1, 2)
        if self.var_gyro is not None:
            for k0 in range(0, self.var_gyro.size, _CHUNK):
                k = np.arange(k0, min(k0 + _CHUNK, self.var_gyro.size))
                x = -(g[k] @ sigma[k + 1])[:, 2, 2]
                self.var_gyro[k] += sigma[k, 2, 2] + sigma[k + 1, 2, 2] - 2.0 * x

    def column(self, col: F64, root: F64) -> None:
        for f0 in self.chunks():
            rows = slice(f0, f0 + _FIX_CHUNKED)
            k, a = self.kk[rows], self.a[rows, None]
            c_int = (1.0 - a) * col[k] + a * col[k + 1]
            u = -(self._jp(rows) @ c_int[:, :, None])[:, :, 0]
            if self.keep:
                j_sh = _fix_shared_jacobian(self.dh_ds[rows], self.rot[rows])[:, :, self.keep]
                u += j_sh @ root[self.root_rows]
            self.ch[rows] += u[:, :, None] * u[:, None, :]
        if self.var_gyro is not None:
            v = -np.diff(col[:, 2])
            if self.bias_row is not None:
                v = v + self.dt * root[self.bias_row]
            self.var_gyro += v**2


@dataclass(frozen=True)
class _Scales:
    """Variance factors of the two noise groups whose scale is estimated: odometry, fixes."""

    odometry: float = 1.0
    fixes: float = 1.0


def _scaled(pr: _Problem, scales: _Scales) -> _Problem:
    """``pr`` with its noise scaled by ``scales`` (σ by the square roots; no array copied)."""
    return replace(pr, odom_scale=math.sqrt(scales.odometry), fix_scale=math.sqrt(scales.fixes))


@dataclass(frozen=True)
class _Verdict:
    """One round's check: the groups' variance ratios (residuals over redundancy), the fixes'
    χ²/dof against their own covariance and share inside the 95 % band, the odometry's dof."""

    ratio_odometry: float | None
    ratio_fixes: float | None
    chi2_own: float
    band: float
    odometry_dof: float


def _verdict(
    pr: _Problem,
    tally: _Tally,
    info: dict[str, float],
    shared_cov: F64,
    first_cov: F64,
    free_idx: NDArray[np.intp],
    huber_k: float,
) -> _Verdict:
    """The groups' redundancies from the tally (tr(H⁻¹ H_g) per group: the fixes' and the
    gyro's directly, the odometry's by difference from the dimension) and their ratios."""
    sums = np.zeros(6)  # Σ w d², Σ w (2 − t), Σ w d²_own, Σ w (2 − t_own), Σ w t, in band
    own = pr.fix_scale**2  # the fixes' own variance over the weighed one
    whiten = pr.fix_whiteners()
    for f0 in tally.chunks():
        rows = slice(f0, f0 + _FIX_CHUNKED)
        w_mat = whiten[tally.rows[rows]]
        white = (w_mat @ tally.raw[rows, :, None])[:, :, 0]
        d2 = np.sum(white**2, axis=1)
        t = np.einsum("mij,mji->m", w_mat @ tally.ch[rows], np.swapaxes(w_mat, 1, 2))
        w = _huber_weights(np.sqrt(d2), huber_k)
        # the band: the residual against the fix's own covariance plus the prediction's
        band_cov = np.linalg.inv(np.swapaxes(w_mat, 1, 2) @ w_mat) / own + tally.ch[rows]
        band_d2 = np.einsum(
            "mi,mij,mj->m", tally.raw[rows], np.linalg.inv(band_cov), tally.raw[rows]
        )
        sums += (
            float(np.sum(w * d2)),
            float(np.sum(w * (2.0 - t))),
            float(np.sum(w * d2 * own)),
            float(np.sum(w * (2.0 - t * own))),
            float(np.sum(w * t)),
            float(np.sum(band_d2 <= _CHI2_2_95)),
        )
    count = tally.kk.size
    ratio_fixes = sums[0] / sums[1] if sums[1] >= _MIN_DOF else None
    chi2_own = sums[2] / sums[3] if sums[3] > 0.0 else float("nan")
    band = sums[5] / count if count else float("nan")
    n = pr.t.size
    hat = sums[4] + float(np.sum(np.diag(first_cov) * _GAUGE**2))
    if free_idx.size:
        hat += float(np.sum(np.diag(shared_cov) / pr.prior_sigma[free_idx] ** 2))
    if tally.var_gyro is not None:
        hat += float(np.sum(tally.var_gyro / (pr.gyro_sigma_rad**2 * tally.dt)))
    odometry_dof = 3 * (n - 1) - (3 * n + free_idx.size - hat)
    ratio_odometry = info["odometry_ss"] / odometry_dof if odometry_dof >= _MIN_DOF else None
    return _Verdict(ratio_odometry, ratio_fixes, chi2_own, band, odometry_dof)


def _check(
    params: SmootherParams, v: _Verdict, scales: _Scales, converged: bool, rounds: int
) -> SmootherCheck:
    """The self-check of the last round against the thresholds of ``params``."""
    odometry_scale = math.sqrt(scales.odometry)
    reasons = []
    if not converged:
        reasons.append("the solution did not converge")
    if not v.chi2_own <= params.check_max_chi2_per_dof:
        reasons.append(
            f"the fixes' normalised residuals have χ²/dof {v.chi2_own:.2f} "
            f"(> {params.check_max_chi2_per_dof:g})"
        )
    if not v.band >= params.check_min_band_share:
        reasons.append(
            f"only {100 * v.band:.1f} % of the trusted fixes lie inside the 95 % band "
            f"(< {100 * params.check_min_band_share:g} %)"
        )
    if not odometry_scale <= params.check_max_odometry_noise_scale:
        reasons.append(
            f"the odometry fits the fixes only {odometry_scale:.1f} times noisier than modelled "
            f"(> {params.check_max_odometry_noise_scale:g})"
        )
    return SmootherCheck(
        fix_chi2_per_dof=v.chi2_own,
        fixes_in_band_95=v.band,
        odometry_noise_scale=odometry_scale,
        fix_noise_scale=math.sqrt(scales.fixes),
        rounds=rounds,
        odometry_dof=v.odometry_dof,
        passed=not reasons,
        reasons=tuple(reasons),
    )


_History = tuple[tuple[float, float] | None, tuple[float, float] | None]
"""Per group (odometry, fixes): (log variance factor, log ratio) of the last round."""


def _next_scales(scales: _Scales, v: _Verdict, history: _History) -> tuple[_Scales, bool, _History]:
    """The variance factors for the next round, whether they have settled (every ratio within
    :data:`_SETTLED` of 1), and this round's history.

    Each group's factor is the root of f(u) = log ratio at u = log factor (its residuals over
    their redundancy, 1 when the σ are right). The plain step u + f (scale by the ratio) is a
    fixed-point iteration that crawls when the redundancy shrinks with the factor (odometry
    far better than modelled: 0.57, 0.62, 0.67 … round after round); from the second round on
    the step is a secant's, f's slope from the last two rounds (the plain one when the slope is
    not negative), at most ×/÷ 100 a round.
    """
    hi = math.log(_SCALE_RANGE[1])
    floors = (_ODOMETRY_FLOOR, _SCALE_RANGE[0])
    values = (scales.odometry, scales.fixes)
    ratios = (v.ratio_odometry, v.ratio_fixes)
    out: list[float] = []
    now: list[tuple[float, float] | None] = []
    for value, ratio, last, floor in zip(values, ratios, history, floors, strict=True):
        lo = math.log(floor)
        if ratio is None or not (math.isfinite(ratio) and ratio > 0.0):
            out.append(value)
            now.append(None)
            continue
        u, f = math.log(value), math.log(ratio)
        step = f
        if last is not None and u != last[0]:
            slope = (f - last[1]) / (u - last[0])
            if slope < -1e-3:
                step = -f / slope
        step = min(max(step, -math.log(100.0)), math.log(100.0))
        out.append(math.exp(min(max(u + step, lo), hi)))
        now.append((u, f))
    settled = all(abs(x - 1.0) <= _SETTLED for x in ratios if x is not None)
    return _Scales(*out), settled, (now[0], now[1])


def _rotation_rad(od: F64) -> float:
    """Total rotation of the odometry at yaw rates of 0.02 rad/s or more (the joint
    calibration's motion content: yaw jitter at a stand-still does not count)."""
    total = 0.0
    for a in range(0, od.shape[0] - 1, _CHUNK):  # bounded temporaries
        part = od[a : a + _CHUNK + 1]
        turn = np.abs(np.remainder(np.diff(part[:, 3]) + math.pi, 2.0 * math.pi) - math.pi)
        total += float(np.sum(turn[turn >= 0.02 * np.diff(part[:, 0])]))
    return total


# --------------------------------------------------------------------------- entry point


def _rigid_fit(src: F64, dst: F64) -> tuple[float, F64]:
    """Rotation and translation carrying ``src`` onto ``dst`` (least squares; 0 if no spread)."""
    a_mean, b_mean = src.mean(axis=0), dst.mean(axis=0)
    ac, bc = src - a_mean, dst - b_mean
    rot = 0.0
    if float(np.sqrt(np.mean(np.sum(ac**2, axis=1)))) > 0.05:
        cross = float(np.sum(ac[:, 0] * bc[:, 1] - ac[:, 1] * bc[:, 0]))
        dot = float(np.sum(ac[:, 0] * bc[:, 0] + ac[:, 1] * bc[:, 1]))
        rot = math.atan2(cross, dot)
    c, s = math.cos(rot), math.sin(rot)
    shift: F64 = b_mean - np.array([[c, -s], [s, c]]) @ a_mean
    return rot, shift


def _rigid_transform(odom_poses: F64, fix_t: F64, fix_xy: F64, t: F64, offset: F64) -> F64:
    """(x, y, θ) carrying the odometry's hedgehog track onto the fixes (least squares)."""
    total = np.zeros(3)
    poses = odom_poses
    for _ in range(3):  # the lever arm turns with the heading the fit finds: refit
        hedge = transform_points(poses, offset)
        src = np.column_stack([np.interp(fix_t, t, hedge[:, 0]), np.interp(fix_t, t, hedge[:, 1])])
        rot, shift = _rigid_fit(src, fix_xy)
        step = np.array([shift[0], shift[1], rot])
        poses = compose_poses(step, poses)
        total = compose_poses(step, total)
    return total


def _initial_poses(odom_poses: F64, fix_t: F64, fix_xy: F64, t: F64, offset: F64) -> F64:
    """The odometry carried into map by least-squares rigid fits of its hedgehog track.

    One fit over the whole run when it is short; on a longer run, one per window of about
    :data:`_INIT_WINDOW_S` (the odometry's drift over a long run is far from rigid: a single
    fit can start the smoother in the wrong basin), the transforms interpolated in time
    between the windows' centres. A window without enough fixes or spread is skipped.
    """
    count = max(1, round((t[-1] - t[0]) / _INIT_WINDOW_S))
    if count == 1:
        return compose_poses(_rigid_transform(odom_poses, fix_t, fix_xy, t, offset), odom_poses)
    edges = np.linspace(t[0], t[-1], count + 1)
    centres: list[float] = []
    transforms: list[F64] = []
    for w in range(count):
        lo, hi = np.searchsorted(fix_t, (edges[w], edges[w + 1]))
        spread = fix_xy[lo:hi] - np.mean(fix_xy[lo:hi], axis=0) if hi - lo >= 10 else None
        if spread is None or float(np.sqrt(np.mean(np.sum(spread**2, axis=1)))) < 0.1:
            continue
        a, b = np.searchsorted(t, (edges[w], edges[w + 1]))
        a, b = max(a - 1, 0), min(b + 1, t.size)
        transforms.append(
            _rigid_transform(odom_poses[a:b], fix_t[lo:hi], fix_xy[lo:hi], t[a:b], offset)
        )
        centres.append(0.5 * (edges[w] + edges[w + 1]))
    if len(transforms) < 2:
        return compose_poses(_rigid_transform(odom_poses, fix_t, fix_xy, t, offset), odom_poses)
    tr = np.array(transforms)
    tr[:, 2] = np.unwrap(tr[:, 2])
    at = np.column_stack([np.interp(t, centres, tr[:, k]) for k in range(3)])
    return compose_poses(at, odom_poses)


def _gyro_increments(t: F64, gyro: F64) -> tuple[F64, F64]:
    """Integrated yaw rate over every odometry interval, and the intervals' durations."""
    gt, gz = gyro[:, 0], gyro[:, 1]
    if np.any(gt[1:] < gt[:-1]):  # in time order already: no sorted copies
        order = np.argsort(gt, kind="stable")
        gt, gz = gt[order], gz[order]
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (gz[1:] + gz[:-1]) * np.diff(gt))])
    at = np.interp(t, gt, cum)
    return np.diff(at), np.diff(t)


_NO_LOSS: Final = 1e9
_DECREMENT: Final = 1e-3
"""A solution whose undamped Gauss–Newton step would lower the cost (½ χ²) by less than this has
converged: no parameter is then more than √(2 · 0.001) ≈ 0.045σ from the local optimum."""


def _keyframes(params: SmootherParams, t: F64) -> NDArray[np.intp] | None:
    """The odometry rows that are pose nodes: None (every sample) unless the run is longer
    than ``params.long_run_s``; then one about every ``params.keyframe_interval_s``
    (:func:`~omnical.estimation.keyframes.keyframes_by_time`), None if that is every sample."""
    if params.long_run_s is None or t.size < 3 or t[-1] - t[0] <= params.long_run_s:
        return None
    keys = keyframes_by_time(t, params.keyframe_interval_s)
    return keys if keys.size < t.size else None


def _odometry_whiteners(cov: F64) -> F64:
    """W (K, 3, 3) with Wᵀ W = Σ⁻¹ for each composite odometry covariance Σ: W = L⁻¹, Σ = L Lᵀ."""
    out: F64 = np.linalg.inv(np.linalg.cholesky(cov))
    return out


def _normal(
    pr: _Problem, poses: F64, shared: F64, huber_k: float
) -> tuple[_Normal, float, dict[str, float]]:
    nm, cost, info = _linearise(pr, poses, shared, huber_k)
    if nm is None:  # pragma: no cover - _linearise builds it when asked
        raise GeometryError("no normal equations")
    return nm, cost, info


def _gauss_newton(
    pr: _Problem,
    poses: F64,
    shared: F64,
    free_idx: NDArray[np.intp],
    huber_k: float,
    max_iterations: int,
) -> tuple[F64, F64, _Normal, dict[str, float], int, bool]:
    """Levenberg–Marquardt-damped Gauss–Newton (IRLS under the Huber loss) from a start.

    A trial point is costed without its normal equations (built only once it is taken), so
    one set of them is held at a time. A solve spends ``nm.band``: after a rejected step the
    normal equations are built again.
    """
    nm, cost, info = _normal(pr, poses, shared, huber_k)
    lam = 0.0
    iterations = 0
    for iterations in range(1, max_iterations + 1):
        step = _solve_banded(nm, lam)
        if step is not None:
            new_poses = poses + step[0]
            new_shared = shared.copy()
            new_shared[free_idx] += step[1]
            _, c2, i2 = _linearise(pr, new_poses, new_shared, huber_k, normal=False)
            if c2 <= cost * (1 + 1e-12):
                largest = max(
                    float(np.max(np.abs(step[0]))), float(np.max(np.abs(step[1]), initial=0.0))
                )
                small = abs(cost - c2) <= 1e-9 * max(cost, 1.0) or largest < 1e-7
                poses, shared, info, cost = new_poses, new_shared, i2, c2
                del nm
                nm, _, _ = _normal(pr, poses, shared, huber_k)
                lam = lam / 10.0 if lam > 1e-6 else 0.0
                if small:
                    return poses, shared, nm, info, iterations, True
                continue
        del nm
        nm, _, _ = _normal(pr, poses, shared, huber_k)
        lam = 1e-4 if lam == 0.0 else lam * 10.0
        if lam > 1e6:
            break
    # out of iterations: converged all the same when the undamped step would lower the cost by
    # less than _DECREMENT
    undamped = _solve_banded(nm, 0.0)
    del nm
    nm, _, _ = _normal(pr, poses, shared, huber_k)
    settled = undamped is not None and (
        0.5 * float(nm.b_pose.ravel() @ undamped[0].ravel() + nm.b_shared @ undamped[1])
        <= _DECREMENT
    )
    return poses, shared, nm, info, iterations, settled


_NO_ROWS: Final = np.zeros((0, 3))


def _odometry_part(
    od: F64, keys: NDArray[np.intp] | None, sigma_args: tuple[float, float, float, float, float]
) -> tuple[F64, F64 | None, F64]:
    """The odometry factors' increments, θ design and whiteners: at every sample (diagonal
    whiteners; the design follows from the increments) or between keyframes (preintegrated)."""
    if keys is None:
        inc, sigma = odometry_increments(od, *sigma_args)
        whiten = np.zeros((sigma.shape[0], 3, 3))
        whiten[:, range(3), range(3)] = 1.0 / sigma
        return inc, None, whiten
    inc, design, inc_cov = preintegrate(od, keys, sigma_args)
    return inc, design, _odometry_whiteners(inc_cov)


def _sigma_args(params: SmootherParams, scale: float) -> tuple[float, float, float, float, float]:
    """The odometry's noise settings (:func:`~omnical.estimation.keyframes.odometry_increments`)
    with every σ times ``scale``."""
    return (
        params.odom_trans_sigma_per_m * scale,
        params.odom_yaw_sigma_per_rad * scale,
        params.odom_yaw_sigma_per_m * scale,
        params.position_random_walk_m * scale,
        params.yaw_random_walk_rad * scale,
    )


def _odometry_rows(odom: ArrayLike, delay_s: float) -> F64:
    """The odometry (N, 4) as smoothed: repeated times dropped, times less ``delay_s``.

    Raises:
        GeometryError: not (N, 4) with N ≥ 2, times not increasing, a value not finite.
    """
    od = np.asarray(odom, dtype=np.float64)
    if od.ndim != 2 or od.shape[1] != 4 or od.shape[0] < 2:
        raise GeometryError(f"smoothing needs (N, 4) odometry with N >= 2, got {od.shape}")
    keep_od = np.concatenate([[True], np.diff(od[:, 0]) > 0])
    out: F64 = od[keep_od]
    out[:, 0] -= delay_s
    if np.any(np.diff(out[:, 0]) <= 0) or not np.all(np.isfinite(out)):
        raise GeometryError("odometry times must increase and its values be finite")
    return out


def smooth_track(
    params: SmootherParams,
    odom: ArrayLike | Handover[F64] | Callable[[], ArrayLike],
    fix_t_s: ArrayLike | Handover[F64],
    fix_xy_m: ArrayLike | Handover[F64],
    fix_covariance_xy_m2: ArrayLike | Handover[F64],
    *,
    gyro: ArrayLike | Handover[F64] | None = None,
) -> SmoothedTrack:
    """Smooth a whole run: odometry, IPS fixes (and the gyro) in one robust least squares.

    Every array may come in a :class:`~omnical.estimation.handover.Handover` (let go once used).
    ``odom`` may also be a function returning it, called again for a long run's bridge (it
    must return the same odometry).

    Args:
        params: noise model and settings.
        odom: (N, 4) t_s, x, y, yaw of the wheel odometry (any odom frame), times increasing;
            the poses are placed at ``t_s − params.odometry_delay_s``.
        fix_t_s: (M,) the fixes' time stamps (the latency is estimated on top), s.
        fix_xy_m: (M, 2) hedgehog positions in map.
        fix_covariance_xy_m2: (M, 2, 2) their covariances.
        gyro: (G, 2) t_s, yaw rate (rad/s) of the IMU, or None.

    Returns:
        The smoothed poses at the odometry times (less the odometry delay) with their
        covariances and the shared parameters (docs/DESIGN-NOTES.md).

    Raises:
        GeometryError: fewer than 2 odometry samples or 3 finite fixes, bad shapes.
    """
    again: Callable[[], ArrayLike] | None = None  # the odometry asked for again for the bridge
    if isinstance(odom, Handover):
        od = _odometry_rows(odom.take(), params.odometry_delay_s)
    elif callable(odom):
        again = odom
        od = _odometry_rows(again(), params.odometry_delay_s)
    else:
        od = _odometry_rows(odom, params.odometry_delay_s)
    del odom
    ft = np.asarray(taken(fix_t_s), dtype=np.float64).reshape(-1)
    fxy = np.asarray(taken(fix_xy_m), dtype=np.float64).reshape(-1, 2)
    fcov = np.asarray(taken(fix_covariance_xy_m2), dtype=np.float64).reshape(-1, 2, 2)
    del fix_t_s, fix_xy_m, fix_covariance_xy_m2
    if not (ft.size == fxy.shape[0] == fcov.shape[0]):
        raise GeometryError("fix times, positions and covariances must have one row per fix")
    good = (
        np.isfinite(ft) & np.all(np.isfinite(fxy), axis=1) & np.all(np.isfinite(fcov), axis=(1, 2))
    )
    good &= (ft >= od[0, 0] - 1.0) & (ft <= od[-1, 0] + 1.0)
    order = np.flatnonzero(good)
    order = order[np.argsort(ft[order], kind="stable")]  # time order: the fixes' intervals sorted
    ft, fxy, fcov = ft[order], fxy[order], fcov[order]
    if ft.size < 3:
        raise GeometryError(f"smoothing needs at least 3 fixes during the odometry, got {ft.size}")
    t_full = od[:, 0]
    sigma_args = _sigma_args(params, 1.0)
    turned = _rotation_rad(od)
    keys = _keyframes(params, t_full)
    stride = 1 if keys is None else round((t_full.size - 1) / max(1, keys.size - 1))
    inc, design, odom_whiten = _odometry_part(od, keys, sigma_args)
    if keys is not None:  # a long run: pose nodes at the keyframes, the odometry preintegrated
        t = t_full[keys]
        start = od[keys, 1:]
        if again is not None:  # asked for again for the bridge: not held through the solution
            del od, t_full
    else:
        t = t_full
        start = od[:, 1:]
    gyro_dpsi = None
    if gyro is not None:
        g = np.asarray(taken(gyro), dtype=np.float64)
        del gyro
        if g.ndim != 2 or g.shape[1] != 2:
            raise GeometryError(f"gyro must be (G, 2) t_s, yaw rate, got {g.shape}")
        finite = np.all(np.isfinite(g), axis=1)
        if not finite.all():  # no copy of a clean gyro
            g = g[finite]
        if g.shape[0] >= 2:
            gyro_dpsi, _ = _gyro_increments(t, g)
        del g  # integrated over the intervals: not held through the solution
    offset = np.asarray(params.hedge_offset_m, dtype=np.float64)
    prior_sigma = np.array(
        [
            params.latency_prior_sigma_s,
            *([params.scale_prior_sigma] * 3),
            *([params.crosstalk_prior_sigma_rad_per_m] * 4),
            params.gyro_bias_prior_sigma_radps,
            *([params.hedge_offset_prior_sigma_m] * 2),
        ]
    )
    prior_mean = np.zeros(_N_SHARED)
    prior_mean[_LAT] = params.latency_s
    prior_mean[list(_OFF)] = offset
    free = np.zeros(_N_SHARED, dtype=bool)
    free[_LAT] = params.estimate_latency
    free[1:8] = params.estimate_odometry_factors
    free[_GYRO] = gyro_dpsi is not None
    free[list(_OFF)] = params.estimate_hedge_offset and turned >= params.offset_min_rotation_rad
    pr = _Problem(
        t=t,
        inc=inc,
        odom_whiten=odom_whiten,
        gyro_dpsi=gyro_dpsi,
        gyro_sigma_rad=params.gyro_sigma_rad,
        fix_t=ft,
        fix_xy=fxy,
        fix_whiten=_whiteners(fcov, params.fix_sigma_floor_m),
        prior_sigma=prior_sigma,
        prior_mean=prior_mean,
        free=free,
        design=design,
    )
    del inc, design, odom_whiten, fcov, good, order  # in ``pr`` (whitened)
    poses = _initial_poses(start, ft - params.latency_s, fxy, t, offset)
    del start
    poses[:, 2] = np.unwrap(poses[:, 2])  # continuous: the factors difference and interpolate it
    shared = prior_mean.copy()
    free_idx = np.flatnonzero(free)
    scales = _Scales()
    history: _History = (None, None)
    total = 0
    stages: tuple[float, ...] = (_NO_LOSS, params.huber_k)
    solution: tuple[F64, F64, SmootherCheck] | None = None
    # the noise scales are found without the gyro, which joins for a last round
    gyro_dpsi = pr.gyro_dpsi
    gyro_last = gyro_dpsi is not None and params.noise_rounds > 1
    no_gyro = free.copy()
    no_gyro[_GYRO] = False
    if gyro_last:
        pr = replace(pr, gyro_dpsi=None, free=no_gyro)
    rounds = 0
    while solution is None:
        # two stages at first: plain least squares, then the Huber loss from there; a later
        # round starts from the last solution
        run_idx = np.flatnonzero(pr.free)
        converged = False
        nm: _Normal | None = None
        info: dict[str, float] = {}
        for huber_k in stages:
            nm = None  # the previous normal equations: not held while the next are built
            poses, shared, nm, info, its, converged = _gauss_newton(
                pr, poses, shared, run_idx, huber_k, params.max_iterations
            )
            total += its
        stages = (params.huber_k,)
        rounds += 1
        if nm is None:  # pragma: no cover - a stage ran
            raise GeometryError("no normal equations")
        tally = _Tally(pr, poses, shared, run_idx)
        # the odometry's arrays are not held through the marginals: made again if needed
        pr = replace(pr, inc=_NO_ROWS, design=None, odom_whiten=_NO_ROWS)
        cov, shared_cov = _marginals_banded(nm, tally)
        del nm
        verdict = _verdict(pr, tally, info, shared_cov, cov[0], run_idx, params.huber_k)
        del tally
        check = _check(params, verdict, scales, converged, rounds)
        with_gyro = pr.gyro_dpsi
        if with_gyro is None or not gyro_last:  # a round of the scales
            scales, settled, history = _next_scales(scales, verdict, history)
            if settled or rounds >= params.noise_rounds:
                if not gyro_last:
                    solution = (cov, shared_cov, check)
                    break
                with_gyro = gyro_dpsi  # the scales found: the gyro's round next
        else:  # the gyro's round: the last
            solution = (cov, shared_cov, check)
            break
        del cov, shared_cov  # not held through the next round's solution
        rows = (
            od
            if again is None or keys is None
            else _odometry_rows(again(), params.odometry_delay_s)
        )
        inc, design, odom_whiten = _odometry_part(rows, keys, sigma_args)
        del rows
        pr = replace(
            _scaled(pr, scales),
            inc=inc,
            design=design,
            odom_whiten=odom_whiten,
            gyro_dpsi=with_gyro,
            free=free if with_gyro is not None else no_gyro,
        )
        del inc, design, odom_whiten
    cov, shared_cov, check = solution
    iterations = total
    del pr
    shared_sigma = np.zeros(_N_SHARED)
    if free_idx.size:
        shared_sigma[free_idx] = np.sqrt(np.maximum(np.diag(shared_cov), 0.0))
    if keys is not None:  # every odometry sample bridged from the smoothed keyframes
        if again is not None:
            od = _odometry_rows(again(), params.odometry_delay_s)
            t_full = od[:, 0]
            if t_full.size - 1 != int(keys[-1]):
                raise GeometryError("the odometry asked for again is not the one smoothed")
        bridge_sigma = _sigma_args(params, check.odometry_noise_scale)
        poses, cov = bridge(od, keys, bridge_sigma, poses, cov, shared[1:8])
    t_full = t_full.copy()  # not a view holding the whole odometry copy
    for array in (t_full, poses, cov):
        array.setflags(write=False)  # the result is frozen: shared without copies
    return SmoothedTrack(
        t_s=t_full,
        poses=poses,
        covariance=cov,
        shared=shared,
        shared_sigma=shared_sigma,
        fixes_used=int(info["fixes_used"]),
        fixes_downweighted=int(info["downweighted"]),
        fix_residual_rms_m=float(info["residual_rms_m"]),
        iterations=iterations,
        converged=converged,
        keyframe_stride=stride,
        check=check,
    )
