"""Batch smoother of a whole run: wheel odometry, IPS fixes and the gyro, in one least squares.

What a user without ground truth can trust as the robot's trajectory: every pose of the run
estimated from all the measurements before *and after* it (a fixed-interval smoother, the
batch counterpart of the EKF in :mod:`omnical.estimation.fusion`).

Unknowns: the pose (x, y, yaw) of base_link in ``map`` at every odometry sample, and a few
shared parameters of the run:

- the IPS latency τ: a fix stamped at t measured the hedgehog at t − τ;
- a linear correction of the odometry increments (scale of the body x, y and yaw increments,
  yaw cross-talk per metre forward, backward, left and right: the seven-factor model of
  seed 000 to first order), so an uncalibrated base's systematic odometry error is not
  forced onto the trajectory; weak priors keep the factors the motion does not excite at zero;
- the gyro bias, when the gyro is given.

Factors (residuals, each whitened by its standard deviation):

- **odometry** between consecutive poses: the body-frame motion ⊖x_k ⊕ x_{k+1} minus the
  corrected odometry increment; σ grows with the motion (slip) plus a random walk in time;
- **gyro** (optional): the yaw change minus the integrated yaw rate less the bias;
- **IPS position**: fix z_j minus the hedgehog h = p + R(ψ) o at t_j − τ (the poses on both
  sides interpolated linearly), o the hedgehog's lever arm in base_link, whitened by the fix's
  own covariance (plus a small floor), under a Huber loss (iteratively reweighted) so a fix that
  is far from the others barely counts.

Gauss–Newton on the sparse normal equations (the pose block is block tridiagonal: every
factor touches two consecutive poses; the shared parameters form a dense border). The
marginal covariance of every pose is computed exactly from the same normal matrix (block
tridiagonal selected inversion plus the border's low-rank term), so each smoothed position
carries its own 1σ uncertainty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError, GeometryError
from omnical.estimation.se2 import between_poses, compose_poses

__all__ = [
    "SHARED_NAMES",
    "SmoothedTrack",
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
)
"""The shared parameters, in their order in :attr:`SmoothedTrack.shared`. Scales are relative
corrections (0 = the odometry is right)."""

_LAT, _GYRO = 0, 8
_N_SHARED = len(SHARED_NAMES)


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
        odometry_delay_s: how long after the motion the odometry is stamped, s: each odometry
            sample describes the pose at its stamp minus this, and the smoothed poses are
            returned at those times. Only the latency *between* the fixes and the odometry is
            observable from the two, so a delay of the odometry is otherwise carried into the
            smoothed track (and counts as tracking error against a reference). The digital
            twin stamps its odometry one control period (10 ms) after the firmware tick that
            computed it; a real base's delay (serial transfer, the host's stamping) is its own.
        estimate_latency: estimate τ (needs motion).
        latency_prior_sigma_s: σ of the prior on τ around ``latency_s``.
        estimate_odometry_factors: estimate the odometry correction.
        scale_prior_sigma: σ of the prior on each relative scale correction (around 0).
        crosstalk_prior_sigma_rad_per_m: σ of the prior on each cross-talk (around 0).
        gyro_bias_prior_sigma_radps: σ of the prior on the gyro bias.
        max_iterations: Gauss–Newton iterations at most.

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
    max_iterations: int = 30

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
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f"{name} must be finite and > 0, got {value}")
        if self.max_iterations < 1:
            raise ConfigError(f"max_iterations must be >= 1, got {self.max_iterations}")


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

    def shared_dict(self) -> dict[str, tuple[float, float]]:
        """Name → (value, 1σ) of the shared parameters."""
        return {
            n: (float(v), float(s))
            for n, v, s in zip(SHARED_NAMES, self.shared, self.shared_sigma, strict=True)
        }


# --------------------------------------------------------------------------- model


def _rot(yaw: F64) -> tuple[F64, F64]:
    return np.cos(yaw), np.sin(yaw)


def _increment_design(inc: F64) -> F64:
    """(K, 3, 7): how the scale/cross-talk corrections change each body increment."""
    k = inc.shape[0]
    g = np.zeros((k, 3, 7))
    dx, dy, dth = inc[:, 0], inc[:, 1], inc[:, 2]
    g[:, 0, 0] = dx
    g[:, 1, 1] = dy
    g[:, 2, 2] = dth
    g[:, 2, 3] = np.maximum(dx, 0.0)
    g[:, 2, 4] = np.maximum(-dx, 0.0)
    g[:, 2, 5] = np.maximum(dy, 0.0)
    g[:, 2, 6] = np.maximum(-dy, 0.0)
    return g


@dataclass(frozen=True, eq=False)
class _Problem:
    t: F64
    inc: F64
    inc_design: F64
    odom_sigma: F64  # (K, 3)
    gyro_dpsi: F64 | None  # (K,)
    gyro_dt: F64
    gyro_sigma: F64
    fix_t: F64
    fix_xy: F64
    fix_whiten: F64  # (M, 2, 2): W with Wᵀ W = C⁻¹
    offset: F64
    prior_sigma: F64  # (N_SHARED,)
    prior_mean: F64
    free: NDArray[np.bool_]


def _whiteners(cov: F64, floor_m: float) -> F64:
    c = cov + np.eye(2) * floor_m**2
    inv = np.linalg.inv(c)
    # Wᵀ W = C⁻¹: W = Lᵀ with L L ᵀ = C⁻¹ (Cholesky)
    chol = np.linalg.cholesky(inv)
    out: F64 = np.transpose(chol, (0, 2, 1))
    return out


def _fix_geometry(
    pr: _Problem, poses: F64, latency: float
) -> tuple[NDArray[np.intp], F64, F64, F64, F64, NDArray[np.bool_]]:
    """Interval index, interpolation weight, modelled hedgehog, d h/d s and ∂h/∂ψ per fix."""
    s = pr.fix_t - latency
    n = pr.t.size
    inside = (s >= pr.t[0]) & (s <= pr.t[-1])
    k = np.clip(np.searchsorted(pr.t, s, side="right") - 1, 0, n - 2)
    dt = pr.t[k + 1] - pr.t[k]
    a = np.where(dt > 0, (s - pr.t[k]) / np.where(dt > 0, dt, 1.0), 0.0)
    a = np.clip(a, 0.0, 1.0)
    p0, p1 = poses[k], poses[k + 1]
    pose = p0 + a[:, None] * (p1 - p0)
    c, sn = _rot(pose[:, 2])
    ox, oy = pr.offset
    h = np.column_stack([pose[:, 0] + c * ox - sn * oy, pose[:, 1] + sn * ox + c * oy])
    dh_dpsi = np.column_stack([-sn * ox - c * oy, c * ox - sn * oy])
    rate = (p1 - p0) / np.where(dt > 0, dt, 1.0)[:, None]
    dh_ds = rate[:, :2] + dh_dpsi * rate[:, 2:3]
    return k, a, h, dh_ds, dh_dpsi, inside


def _huber_weights(norm: F64, k: float) -> F64:
    w: F64 = np.where(norm <= k, 1.0, k / np.maximum(norm, 1e-12))
    return w


def _linearise(
    pr: _Problem, poses: F64, shared: F64, huber_k: float
) -> tuple[sp.csc_matrix, F64, float, dict[str, float]]:
    """The IRLS-weighted normal matrix H, gradient side b (H δ = b) and the robust cost."""
    n = poses.shape[0]
    nv = 3 * n + _N_SHARED
    rows: list[NDArray[np.intp]] = []
    cols: list[NDArray[np.intp]] = []
    vals: list[F64] = []
    res: list[F64] = []
    r0 = 0

    def add(r: NDArray[np.intp], c: NDArray[np.intp], v: F64) -> None:
        rows.append(r.ravel())
        cols.append(c.ravel())
        vals.append(v.ravel())

    # --- odometry between-factors
    k = poses.shape[0] - 1
    theta = np.zeros(7)
    theta[:] = shared[1:8]
    corrected = pr.inc + np.einsum("kij,j->ki", pr.inc_design, theta)
    p0, p1 = poses[:-1], poses[1:]
    c, s = _rot(p0[:, 2])
    dx, dy = p1[:, 0] - p0[:, 0], p1[:, 1] - p0[:, 1]
    bx, by = c * dx + s * dy, -s * dx + c * dy
    e = np.column_stack([bx, by, p1[:, 2] - p0[:, 2]]) - corrected
    inv_sig = 1.0 / pr.odom_sigma
    res.append((e * inv_sig).ravel())
    idx = np.arange(k)
    rr = r0 + 3 * idx
    base0, base1 = 3 * idx, 3 * (idx + 1)
    # row x: bx = c dx + s dy
    jx = np.stack([-c, -s, -s * dx + c * dy, c, s], axis=1) * inv_sig[:, :1]
    cx = np.stack([base0, base0 + 1, base0 + 2, base1, base1 + 1], axis=1)
    add(np.repeat(rr[:, None], 5, axis=1), cx, jx)
    jy = np.stack([s, -c, -c * dx - s * dy, -s, c], axis=1) * inv_sig[:, 1:2]
    add(np.repeat(rr[:, None] + 1, 5, axis=1), cx, jy)
    jt = np.stack([-np.ones(k), np.ones(k)], axis=1) * inv_sig[:, 2:3]
    add(np.repeat(rr[:, None] + 2, 2, axis=1), np.stack([base0 + 2, base1 + 2], axis=1), jt)
    # ∂e/∂θ = −G
    shared_cols = 3 * n + 1 + np.arange(7)
    for axis in range(3):
        jg = -pr.inc_design[:, axis, :] * inv_sig[:, axis : axis + 1]
        add(np.repeat(rr[:, None] + axis, 7, axis=1), np.broadcast_to(shared_cols, (k, 7)), jg)
    r0 += 3 * k

    # --- gyro factors
    if pr.gyro_dpsi is not None:
        eg = (p1[:, 2] - p0[:, 2]) - (pr.gyro_dpsi - shared[_GYRO] * pr.gyro_dt)
        ig = 1.0 / pr.gyro_sigma
        res.append(eg * ig)
        rg = r0 + idx
        add(
            np.repeat(rg[:, None], 3, axis=1),
            np.stack([base0 + 2, base1 + 2, np.full(k, 3 * n + _GYRO)], axis=1),
            np.stack([-ig, ig, pr.gyro_dt * ig], axis=1),
        )
        r0 += k

    # --- IPS position factors
    kk, a, h, dh_ds, dh_dpsi, inside = _fix_geometry(pr, poses, float(shared[_LAT]))
    w_mat = pr.fix_whiten
    raw = pr.fix_xy - h
    white = np.einsum("mij,mj->mi", w_mat, raw)
    norm = np.hypot(white[:, 0], white[:, 1])
    weight = _huber_weights(norm, huber_k) * inside
    sw = np.sqrt(weight)
    fix_part = len(res)
    res.append((white * sw[:, None]).ravel())
    m = pr.fix_t.size
    rf = r0 + 2 * np.arange(m)
    # r = W (z − h): ∂r/∂(x_k, y_k, ψ_k) = −(1−a) W [I | dh_dpsi]; x_{k+1}: −a W [...]
    # ∂r/∂τ = +W dh_ds
    jac_pose = np.zeros((m, 2, 3))
    jac_pose[:, 0, 0] = 1.0
    jac_pose[:, 1, 1] = 1.0
    jac_pose[:, :, 2] = dh_dpsi
    wj = -np.einsum("mij,mjk->mik", w_mat, jac_pose) * sw[:, None, None]
    jl = np.einsum("mij,mj->mi", w_mat, dh_ds) * sw[:, None]
    b0, b1 = 3 * kk, 3 * (kk + 1)
    for axis in range(2):
        r = rf + axis
        add(
            np.repeat(r[:, None], 7, axis=1),
            np.stack([b0, b0 + 1, b0 + 2, b1, b1 + 1, b1 + 2, np.full(m, 3 * n + _LAT)], axis=1),
            np.column_stack(
                [
                    wj[:, axis, :] * (1.0 - a)[:, None],
                    wj[:, axis, :] * a[:, None],
                    jl[:, axis],
                ]
            ),
        )
    r0 += 2 * m

    # --- priors on the shared parameters (and a weak one on the first pose: the gauge when
    # the fixes do not fix it)
    ps = 1.0 / pr.prior_sigma
    res.append((shared - pr.prior_mean) * ps)
    add(r0 + np.arange(_N_SHARED), 3 * n + np.arange(_N_SHARED), ps)
    r0 += _N_SHARED
    weak = np.array([1e-3, 1e-3, 1e-2])
    res.append(np.zeros(3))
    add(r0 + np.arange(3), np.arange(3), weak)
    r0 += 3

    jac = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(r0, nv)
    )
    keep = np.concatenate([np.ones(3 * n, dtype=bool), pr.free])
    jac = jac[:, np.flatnonzero(keep)]
    r = np.concatenate(res)
    hess = (jac.T @ jac).tocsc()
    grad = -(jac.T @ r)
    # robust cost: the Huber ρ of the fixes plus ½‖r‖² of every other factor
    rho = np.where(norm <= huber_k, 0.5 * norm**2, huber_k * norm - 0.5 * huber_k**2) * inside
    plain = np.concatenate([part for i, part in enumerate(res) if i != fix_part])
    cost = 0.5 * float(plain @ plain) + float(np.sum(rho))
    info = {
        "fixes_used": float(np.sum(inside)),
        "downweighted": float(np.sum(inside & (norm > huber_k))),
        "residual_rms_m": float(np.sqrt(np.mean(np.sum(raw[inside] ** 2, axis=1))))
        if np.any(inside)
        else float("nan"),
    }
    return hess, np.asarray(grad, dtype=np.float64), cost, info


# --------------------------------------------------------------------------- covariance


def _block_tridiagonal_marginals(hess: sp.csc_matrix, n: int) -> F64:
    """Diagonal 3×3 blocks of the inverse of the block-tridiagonal pose block of ``hess``."""
    dense = hess[: 3 * n, : 3 * n].tocsr()
    d = np.empty((n, 3, 3))
    b = np.empty((max(n - 1, 0), 3, 3))
    for i in range(3):
        for j in range(3):
            d[:, i, j] = dense[np.arange(n) * 3 + i, np.arange(n) * 3 + j].A1
            if n > 1:
                b[:, i, j] = dense[np.arange(n - 1) * 3 + i, np.arange(1, n) * 3 + j].A1
    s_inv = np.empty((n, 3, 3))
    s = d[0]
    s_inv[0] = np.linalg.inv(s)
    for i in range(1, n):
        s = d[i] - b[i - 1].T @ s_inv[i - 1] @ b[i - 1]
        s_inv[i] = np.linalg.inv(s)
    sigma = np.empty((n, 3, 3))
    sigma[-1] = s_inv[-1]
    for i in range(n - 2, -1, -1):
        g = s_inv[i] @ b[i]
        sigma[i] = s_inv[i] + g @ sigma[i + 1] @ g.T
    out: F64 = 0.5 * (sigma + np.transpose(sigma, (0, 2, 1)))
    return out


def _marginals(hess: sp.csc_matrix, n: int, n_free: int) -> tuple[F64, F64]:
    """Pose marginal covariances (N, 3, 3) and the shared parameters' covariance."""
    a_block = _block_tridiagonal_marginals(hess, n)
    if n_free == 0:
        return a_block, np.zeros((0, 0))
    a = hess[: 3 * n, : 3 * n].tocsc()
    c = hess[: 3 * n, 3 * n :].toarray()
    e = hess[3 * n :, 3 * n :].toarray()
    lu = spla.splu(a)
    a_inv_c = lu.solve(c)
    schur = e - c.T @ a_inv_c
    shared_cov = np.linalg.inv(schur)
    blocks = a_inv_c.reshape(n, 3, n_free)
    extra = np.einsum("nik,kl,njl->nij", blocks, shared_cov, blocks)
    return a_block + extra, shared_cov


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


def _initial_poses(odom_poses: F64, fix_t: F64, fix_xy: F64, t: F64, offset: F64) -> F64:
    """The odometry carried into map by the least-squares rigid fit of its hedgehog track."""
    poses = odom_poses.copy()
    for _ in range(3):  # the lever arm turns with the heading the fit finds: refit
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        hx = poses[:, 0] + c * offset[0] - s * offset[1]
        hy = poses[:, 1] + s * offset[0] + c * offset[1]
        src = np.column_stack([np.interp(fix_t, t, hx), np.interp(fix_t, t, hy)])
        rot, shift = _rigid_fit(src, fix_xy)
        poses = compose_poses(np.array([shift[0], shift[1], rot]), poses)
    return poses


def _gyro_increments(t: F64, gyro: F64) -> tuple[F64, F64]:
    """Integrated yaw rate over every odometry interval, and the intervals' durations."""
    gt, gz = gyro[:, 0], gyro[:, 1]
    order = np.argsort(gt, kind="stable")
    gt, gz = gt[order], gz[order]
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (gz[1:] + gz[:-1]) * np.diff(gt))])
    at = np.interp(t, gt, cum)
    return np.diff(at), np.diff(t)


_NO_LOSS: Final = 1e9


def _gauss_newton(
    pr: _Problem,
    poses: F64,
    shared: F64,
    free_idx: NDArray[np.intp],
    huber_k: float,
    max_iterations: int,
) -> tuple[F64, F64, sp.csc_matrix, dict[str, float], int, bool]:
    """Levenberg–Marquardt-damped Gauss–Newton (IRLS under the Huber loss) from a start."""
    n = poses.shape[0]
    hess, grad, cost, info = _linearise(pr, poses, shared, huber_k)
    lam = 0.0
    iterations = 0
    for iterations in range(1, max_iterations + 1):
        damped = hess + sp.diags(lam * hess.diagonal()) if lam > 0 else hess
        step = spla.spsolve(damped.tocsc(), grad)
        new_poses = poses + step[: 3 * n].reshape(n, 3)
        new_shared = shared.copy()
        new_shared[free_idx] += step[3 * n :]
        h2, g2, c2, i2 = _linearise(pr, new_poses, new_shared, huber_k)
        if c2 <= cost * (1 + 1e-12):
            poses, shared, hess, grad, info = new_poses, new_shared, h2, g2, i2
            small = abs(cost - c2) <= 1e-9 * max(cost, 1.0) or float(np.max(np.abs(step))) < 1e-7
            cost = c2
            lam = lam / 10.0 if lam > 1e-6 else 0.0
            if small:
                return poses, shared, hess, info, iterations, True
        else:
            lam = 1e-4 if lam == 0.0 else lam * 10.0
            if lam > 1e6:
                break
    return poses, shared, hess, info, iterations, False


def smooth_track(
    params: SmootherParams,
    odom: ArrayLike,
    fix_t_s: ArrayLike,
    fix_xy_m: ArrayLike,
    fix_covariance_xy_m2: ArrayLike,
    *,
    gyro: ArrayLike | None = None,
) -> SmoothedTrack:
    """Smooth a whole run: odometry, IPS fixes (and the gyro) in one robust least squares.

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
        covariances and the shared parameters (module docstring).

    Raises:
        GeometryError: fewer than 2 odometry samples or 3 finite fixes, bad shapes.
    """
    od = np.asarray(odom, dtype=np.float64)
    if od.ndim != 2 or od.shape[1] != 4 or od.shape[0] < 2:
        raise GeometryError(f"smoothing needs (N, 4) odometry with N >= 2, got {od.shape}")
    keep_od = np.concatenate([[True], np.diff(od[:, 0]) > 0])
    od = od[keep_od]
    od[:, 0] -= params.odometry_delay_s
    if np.any(np.diff(od[:, 0]) <= 0) or not np.all(np.isfinite(od)):
        raise GeometryError("odometry times must increase and its values be finite")
    ft = np.asarray(fix_t_s, dtype=np.float64).reshape(-1)
    fxy = np.asarray(fix_xy_m, dtype=np.float64).reshape(-1, 2)
    fcov = np.asarray(fix_covariance_xy_m2, dtype=np.float64).reshape(-1, 2, 2)
    if not (ft.size == fxy.shape[0] == fcov.shape[0]):
        raise GeometryError("fix times, positions and covariances must have one row per fix")
    good = (
        np.isfinite(ft) & np.all(np.isfinite(fxy), axis=1) & np.all(np.isfinite(fcov), axis=(1, 2))
    )
    good &= (ft >= od[0, 0] - 1.0) & (ft <= od[-1, 0] + 1.0)
    ft, fxy, fcov = ft[good], fxy[good], fcov[good]
    if ft.size < 3:
        raise GeometryError(f"smoothing needs at least 3 fixes during the odometry, got {ft.size}")
    t = od[:, 0]
    n = t.size
    inc = between_poses(od[:-1, 1:], od[1:, 1:])
    inc[:, 2] = np.angle(np.exp(1j * (od[1:, 3] - od[:-1, 3])))
    dist = np.hypot(inc[:, 0], inc[:, 1])
    dt = np.diff(t)
    sig_t = np.sqrt(
        (params.odom_trans_sigma_per_m * dist) ** 2 + params.position_random_walk_m**2 * dt
    )
    sig_yaw = np.sqrt(
        (params.odom_yaw_sigma_per_rad * np.abs(inc[:, 2]) + params.odom_yaw_sigma_per_m * dist)
        ** 2
        + params.yaw_random_walk_rad**2 * dt
    )
    gyro_dpsi = None
    gyro_sig = np.ones(n - 1)
    if gyro is not None:
        g = np.asarray(gyro, dtype=np.float64)
        if g.ndim != 2 or g.shape[1] != 2:
            raise GeometryError(f"gyro must be (G, 2) t_s, yaw rate, got {g.shape}")
        g = g[np.all(np.isfinite(g), axis=1)]
        if g.shape[0] >= 2:
            gyro_dpsi, _ = _gyro_increments(t, g)
            gyro_sig = params.gyro_sigma_rad * np.sqrt(dt)
    offset = np.asarray(params.hedge_offset_m, dtype=np.float64)
    prior_sigma = np.array(
        [
            params.latency_prior_sigma_s,
            *([params.scale_prior_sigma] * 3),
            *([params.crosstalk_prior_sigma_rad_per_m] * 4),
            params.gyro_bias_prior_sigma_radps,
        ]
    )
    prior_mean = np.zeros(_N_SHARED)
    prior_mean[_LAT] = params.latency_s
    free = np.zeros(_N_SHARED, dtype=bool)
    free[_LAT] = params.estimate_latency
    free[1:8] = params.estimate_odometry_factors
    free[_GYRO] = gyro_dpsi is not None
    pr = _Problem(
        t=t,
        inc=inc,
        inc_design=_increment_design(inc),
        odom_sigma=np.column_stack([sig_t, sig_t, sig_yaw]),
        gyro_dpsi=gyro_dpsi,
        gyro_dt=dt,
        gyro_sigma=gyro_sig,
        fix_t=ft,
        fix_xy=fxy,
        fix_whiten=_whiteners(fcov, params.fix_sigma_floor_m),
        offset=offset,
        prior_sigma=prior_sigma,
        prior_mean=prior_mean,
        free=free,
    )
    poses = _initial_poses(od[:, 1:], ft - params.latency_s, fxy, t, offset)
    poses[:, 2] = np.unwrap(poses[:, 2])  # continuous: the factors difference and interpolate it
    shared = prior_mean.copy()
    free_idx = np.flatnonzero(free)
    # two stages: plain least squares first (from a dead-reckoned start far from the fixes,
    # a robust loss would write most of them off), then the Huber loss from there
    total = 0
    converged = False
    for huber_k in (_NO_LOSS, params.huber_k):
        poses, shared, hess, info, its, converged = _gauss_newton(
            pr, poses, shared, free_idx, huber_k, params.max_iterations
        )
        total += its
    iterations = total
    cov, shared_cov = _marginals(hess, n, free_idx.size)
    shared_sigma = np.zeros(_N_SHARED)
    if free_idx.size:
        shared_sigma[free_idx] = np.sqrt(np.maximum(np.diag(shared_cov), 0.0))
    return SmoothedTrack(
        t_s=t,
        poses=poses,
        covariance=cov,
        shared=shared,
        shared_sigma=shared_sigma,
        fixes_used=int(info["fixes_used"]),
        fixes_downweighted=int(info["downweighted"]),
        fix_residual_rms_m=float(info["residual_rms_m"]),
        iterations=iterations,
        converged=converged,
    )
