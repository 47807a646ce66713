"""The least-squares problem of the joint estimator: parameters, residuals and Jacobian.

Full parameter vector: the seven factors (:class:`CorrectionFactors` field order), the hedgehog
offset x, y (m, base_link), the IPS latency (s), then per recording its alignment (map ← odom
x, y, yaw), then per recording its slip perturbations (the odometry's random walk in body dx, dy
and dθ, see :func:`omnical.calibration.joint_model.process_knots`).

Residuals: per fix, the fix position minus the modelled hedgehog position, whitened by the
Cholesky factor of the fix covariance (plus the model floor); then one pseudo-residual
``η_j / σ_j`` per slip perturbation. The Jacobian is analytic for the perturbations (a heading
change at increment k rotates everything after it about the middle of that increment, a
translation shifts it) and central differences for the named parameters.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from omnical.calibration.joint_model import (
    MotionContent,
    body_increments,
    hedge_track,
    integrate_increments,
    interpolate_track,
    motion_content,
    process_knots,
    raw_increments,
    real_increments,
)
from omnical.errors import CalibrationError
from omnical.estimation.se2 import compose_poses
from omnical.ips.from_recording import locate
from omnical.ips.solve.fixes import Fixes, FixStatus
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import FACTORS
from omnical.recording.recording import Recording

__all__ = [
    "FACTOR_NAMES",
    "LATENCY_NAME",
    "MIN_FIXES",
    "N_SHARED",
    "OFFSET_NAMES",
    "JointProblem",
    "Track",
    "alignment_names",
    "prepare_track",
]

_Array = NDArray[np.float64]
_NS_PER_S = 1e9

FACTOR_NAMES: tuple[str, ...] = tuple(f.field for f in FACTORS)
"""CorrectionFactors field names of the seven factors, in field order."""
"""The seven factor names, in :class:`CorrectionFactors` field order."""
OFFSET_NAMES = ("hedge_offset_x_m", "hedge_offset_y_m")
LATENCY_NAME = "latency_s"
N_SHARED = len(FACTOR_NAMES) + len(OFFSET_NAMES) + 1
MIN_FIXES = 20
"""Fewest usable fixes per recording."""


def alignment_names(i: int) -> tuple[str, str, str]:
    """Parameter names of recording ``i``'s alignment."""
    return (f"alignment[{i}].x_m", f"alignment[{i}].y_m", f"alignment[{i}].yaw_rad")


@dataclass(frozen=True)
class Track:
    """One recording, prepared for the fit.

    Attributes:
        t_s: (N,) odometry sample times since the first sample, s.
        start_odom: (3,) odometry pose at the first sample.
        raw: (N − 1, 3) raw body increments (installed compensation undone).
        fix_t_s: (n,) fix times on the same clock, s.
        fix_xy: (n, 2) fix positions, map frame, m.
        chol: (n, 3) l11, l21, l22 of the lower Cholesky factor of each fix's covariance.
        content: motion content as the odometry reported it.
        knot_index: (K,) increments that carry a slip perturbation.
        knot_comp: (K,) its component: 0 = along the travel, 1 = across it, 2 = dθ.
        knot_sigma: (K,) prior σ of each perturbation, m or rad.
        knot_dir: (K,) body-frame direction of "along" for position perturbations, rad.
    """

    t_s: _Array
    start_odom: _Array
    raw: _Array
    fix_t_s: _Array
    fix_xy: _Array
    chol: _Array
    content: MotionContent
    knot_index: NDArray[np.intp]
    knot_comp: NDArray[np.intp]
    knot_sigma: _Array
    knot_dir: _Array


def prepare_track(
    recording: Recording,
    fixes: Fixes | None,
    installed: CorrectionFactors,
    *,
    model_sigma_m: float,
    noise: tuple[float, float, float, float],
    index: int = 0,
) -> Track:
    """Odometry increments, usable fixes (ok or degraded, during the odometry) and knots.

    ``noise`` = (heading σ per √rad, heading σ per √m, position σ along and across the travel
    per √m) of the slip model.

    Raises:
        CalibrationError: fewer than 2 odometry samples, fixes without times, or fewer than
            :data:`MIN_FIXES` usable fixes.
        RecordingError: no ``/odom`` (or no IPS distances when ``fixes`` is None).
    """
    odom = recording.topic("/odom")
    if len(odom) < 2:
        msg = (
            f"recording {index}: /odom has {len(odom)} samples, the joint estimate needs 2 or more"
        )
        raise CalibrationError(msg)
    t0 = int(odom.t_ns[0])
    t_s = odom.t_s(t0)
    keep = np.concatenate([[True], np.diff(t_s) > 0.0])
    if not np.all(keep):
        odom = odom.take(keep)
        t_s = t_s[keep]
    poses = np.column_stack([odom["x_m"], odom["y_m"], odom["yaw_rad"]]).astype(np.float64)
    body = body_increments(poses)
    if fixes is None:
        fixes, _ = locate(recording)
    if fixes.t_ns is None:
        msg = f"recording {index}: the fixes have no times (t_ns); locate them from the recording"
        raise CalibrationError(msg)
    ft = (fixes.t_ns - np.int64(t0)).astype(np.float64) / _NS_PER_S
    cov = fixes.covariance_xy_m2
    xy = fixes.positions_map_m[:, :2]
    good = (
        ((fixes.status == FixStatus.OK) | (fixes.status == FixStatus.DEGRADED))
        & np.all(np.isfinite(xy), axis=1)
        & np.all(np.isfinite(cov.reshape(-1, 4)), axis=1)
        & (ft >= t_s[0])
        & (ft <= t_s[-1])
    )
    n_good = int(np.count_nonzero(good))
    if n_good < MIN_FIXES:
        msg = (
            f"recording {index}: {n_good} usable IPS fixes (ok or degraded, during the "
            f"odometry); the joint estimate needs at least {MIN_FIXES}"
        )
        raise CalibrationError(msg)
    c = cov[good] + (model_sigma_m**2) * np.eye(2)
    l11 = np.sqrt(np.maximum(c[:, 0, 0], 1e-12))
    l21 = c[:, 1, 0] / l11
    l22 = np.sqrt(np.maximum(c[:, 1, 1] - l21**2, 1e-12))
    knot_index, knot_comp, knot_sigma, knot_dir = process_knots(
        body,
        heading_noise_rad_per_sqrt_rad=noise[0],
        heading_noise_rad_per_sqrt_m=noise[1],
        position_noise_m_per_sqrt_m=noise[2],
        cross_noise_m_per_sqrt_m=noise[3],
    )
    return Track(
        t_s=t_s,
        start_odom=poses[0],
        raw=raw_increments(body, installed),
        fix_t_s=ft[good],
        fix_xy=xy[good],
        chol=np.column_stack([l11, l21, l22]),
        content=motion_content(body, np.diff(t_s)),
        knot_index=knot_index,
        knot_comp=knot_comp,
        knot_sigma=knot_sigma,
        knot_dir=knot_dir,
    )


def _whiten(chol: _Array, err: _Array) -> _Array:
    """L⁻¹ e per fix for errors (n, 2) or Jacobian blocks (n, 2, k)."""
    l11, l21, l22 = chol[:, 0], chol[:, 1], chol[:, 2]
    if err.ndim == 3:
        l11, l21, l22 = l11[:, None], l21[:, None], l22[:, None]
    r1 = err[:, 0] / l11
    r2 = (err[:, 1] - l21 * r1) / l22
    return np.stack([r1, r2], axis=1)


class JointProblem:
    """Parameter bookkeeping (full ↔ free vector), residuals and Jacobian of the joint fit."""

    def __init__(self, tracks: Sequence[Track]) -> None:
        self.tracks = tuple(tracks)
        names = [*FACTOR_NAMES, *OFFSET_NAMES, LATENCY_NAME]
        for i in range(len(self.tracks)):
            names.extend(alignment_names(i))
        self.n_named = len(names)
        self.knot_slices: list[slice] = []
        start = self.n_named
        for i, tr in enumerate(self.tracks):
            k = tr.knot_index.size
            names.extend(
                f"slip[{i}][{j}].{('along', 'across', 'yaw')[c]}"
                for j, c in enumerate(tr.knot_comp)
            )
            self.knot_slices.append(slice(start, start + k))
            start += k
        self.names = tuple(names)

    @staticmethod
    def align_slice(i: int) -> slice:
        """Slice of recording ``i``'s alignment in the full vector."""
        return slice(N_SHARED + 3 * i, N_SHARED + 3 * i + 3)

    def poses(self, full: _Array, i: int, factors: CorrectionFactors | None = None) -> _Array:
        """(N, 3) modelled poses of recording ``i`` in the map frame."""
        tr = self.tracks[i]
        f = factors if factors is not None else CorrectionFactors.from_vector(full[:7])
        real = real_increments(tr.raw, f)
        values = full[self.knot_slices[i]]
        pos = tr.knot_comp < 2
        ang = tr.knot_dir[pos] + np.where(tr.knot_comp[pos] == 1, 0.5 * np.pi, 0.0)
        np.add.at(real[:, 0], tr.knot_index[pos], values[pos] * np.cos(ang))
        np.add.at(real[:, 1], tr.knot_index[pos], values[pos] * np.sin(ang))
        head = ~pos
        real[tr.knot_index[head], 2] += values[head]
        start = compose_poses(full[self.align_slice(i)], tr.start_odom)
        return integrate_increments(start, real)

    def model_xy(self, full: _Array, i: int) -> _Array:
        """(n, 2) modelled hedgehog positions at recording ``i``'s fixes."""
        tr = self.tracks[i]
        track = hedge_track(self.poses(full, i), full[7:9])
        return interpolate_track(tr.t_s, track, tr.fix_t_s - full[9])

    def errors(self, full: _Array) -> list[_Array]:
        """Fix minus model, (n, 2) per recording, metres."""
        return [tr.fix_xy - self.model_xy(full, i) for i, tr in enumerate(self.tracks)]

    def whitened(self, full: _Array) -> list[_Array]:
        """Whitened fix residuals, (n, 2) per recording."""
        return [_whiten(tr.chol, e) for tr, e in zip(self.tracks, self.errors(full), strict=True)]

    def priors(self, full: _Array) -> _Array:
        """Pseudo-residuals of the slip perturbations against their prior σ."""
        parts = [
            full[ks] / tr.knot_sigma for tr, ks in zip(self.tracks, self.knot_slices, strict=True)
        ]
        return np.concatenate(parts) if parts else np.zeros(0)

    def _stack(self, full: _Array) -> _Array:
        return np.concatenate([*(w.ravel() for w in self.whitened(full)), self.priors(full)])

    def residuals(self, free: _Array, full0: _Array, free_idx: NDArray[np.intp]) -> _Array:
        """The residual vector for free values ``free`` at indices ``free_idx`` of ``full0``."""
        full = full0.copy()
        full[free_idx] = free
        return self._stack(full)

    def jacobian(
        self, free: _Array, full0: _Array, free_idx: NDArray[np.intp], steps: _Array
    ) -> _Array:
        """∂residuals/∂free: central differences (steps per full index) and analytic knots."""
        full = full0.copy()
        full[free_idx] = free
        n_fix = [2 * tr.fix_xy.shape[0] for tr in self.tracks]
        n_rows = sum(n_fix) + sum(tr.knot_index.size for tr in self.tracks)
        jac = np.zeros((n_rows, free_idx.size))
        column = {int(j): c for c, j in enumerate(free_idx)}
        for j, c in column.items():
            if j >= self.n_named:
                continue
            h = steps[j]
            up, down = full.copy(), full.copy()
            up[j] += h
            down[j] -= h
            jac[:, c] = (self._stack(up) - self._stack(down)) / (2.0 * h)
        row = 0
        prior_row = sum(n_fix)
        for i, tr in enumerate(self.tracks):
            ks = self.knot_slices[i]
            k = tr.knot_index.size
            if k:
                cols = [column[j] for j in range(ks.start, ks.stop)]
                jac[row : row + n_fix[i], cols] = self._knot_block(full, i)
                jac[prior_row + np.arange(k), cols] = 1.0 / tr.knot_sigma
            row += n_fix[i]
            prior_row += k
        return jac

    def _knot_block(self, full: _Array, i: int) -> _Array:
        """(2n, K) whitened derivatives of recording ``i``'s residuals w.r.t. its knots."""
        tr = self.tracks[i]
        poses = self.poses(full, i)
        at = tr.fix_t_s - full[9]
        h = interpolate_track(tr.t_s, hedge_track(poses, full[7:9]), at)
        s = np.interp(at, tr.t_s, np.arange(tr.t_s.size, dtype=np.float64))
        k = tr.knot_index
        w = np.clip(s[:, None] - k[None, :], 0.0, 1.0)  # (n, K)
        centre = 0.5 * (poses[k, :2] + poses[k + 1, :2])  # (K, 2)
        phi = 0.5 * (poses[k, 2] + poses[k + 1, 2])
        phi = phi + tr.knot_dir + np.where(tr.knot_comp == 1, 0.5 * np.pi, 0.0)
        c, sn = np.cos(phi), np.sin(phi)
        lever = h[:, None, :] - centre[None, :, :]  # (n, K, 2)
        comp = tr.knot_comp[None, :]
        dx = np.where(comp == 2, -lever[..., 1], c)
        dy = np.where(comp == 2, lever[..., 0], sn)
        d_model = np.stack([dx, dy], axis=1) * w[:, None, :]  # (n, 2, K)
        block = _whiten(tr.chol, -d_model)
        return block.reshape(-1, k.size)
