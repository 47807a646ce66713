"""The joint estimator's least-squares problem: parameters, residuals, Jacobian, normal equations.

The keyframe problem (sparse Jacobian); banded Cholesky + Schur complement, selected inversion
for leverages and covariances. Layout and reasoning: docs/joint-calibration.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from omnical.calibration.joint.model import (
    MotionContent,
    hedge_track,
    interpolate_track,
    motion_content,
    process_knots,
    raw_increments,
    real_increments,
    real_increments_jacobian,
)
from omnical.calibration.procedures.tracks import ODOM_YAW_DEADBAND_RADPS, resolved_odometry
from omnical.errors import CalibrationError
from omnical.estimation.se2 import (
    body_increments,
    compose_poses,
    integrate_increments,
    invert_poses,
    rotate_xy,
)
from omnical.ips.from_recording import locate
from omnical.ips.solve.fixes import Fixes, FixStatus
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import FACTORS
from omnical.recording.recording import Recording
from omnical.recording.topics import ODOM

__all__ = [
    "FACTOR_NAMES",
    "LATENCY_NAME",
    "MIN_FIXES",
    "N_SHARED",
    "OFFSET_NAMES",
    "Inverse",
    "Linearisation",
    "NormalEquations",
    "SparseJointProblem",
    "Track",
    "alignment_names",
    "prepare_track",
    "windowed_procrustes",
]

_Array = NDArray[np.float64]
_NS_PER_S = 1e9

FACTOR_NAMES: tuple[str, ...] = tuple(f.field for f in FACTORS)
"""The seven factor names, in :class:`CorrectionFactors` field order."""
OFFSET_NAMES = ("hedge_offset_x_m", "hedge_offset_y_m")
LATENCY_NAME = "latency_s"
N_SHARED = len(FACTOR_NAMES) + len(OFFSET_NAMES) + 1
MIN_FIXES = 20
"""Fewest usable fixes per recording."""
ANCHOR_REACH = 1.5
"""Half-width of the window of fixes that places a keyframe, in units of motion (1 m or 1 rad)."""
ANCHOR_SPREAD_M = 0.3
"""Least RMS spread of a window's points for its rigid alignment to fix a heading, m."""


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
        knot_share: (K,) share of each prior variance that is slip along the motion (the rest
            is slip across it; :func:`~omnical.calibration.joint.model.process_knots`).
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
    knot_share: _Array


def prepare_track(
    recording: Recording,
    fixes: Fixes | None,
    installed: CorrectionFactors,
    *,
    model_sigma_m: float,
    noise: tuple[float, float, float, float],
    index: int = 0,
    odom_yaw_deadband_radps: float = ODOM_YAW_DEADBAND_RADPS,
) -> Track:
    """Odometry increments, usable fixes (ok or degraded, during the odometry) and knots.

    ``noise`` = (heading σ per √rad, heading σ per √m, position σ along and across the travel
    per √m) of the slip model (:func:`~omnical.calibration.joint.model.process_knots`);
    odometry yaw rates up to ``odom_yaw_deadband_radps`` are no rotation
    (:func:`resolved_odometry`).

    Raises:
        CalibrationError: fewer than 2 odometry samples, fixes without times, or fewer than
            :data:`MIN_FIXES` usable fixes.
        RecordingError: no ``/odom`` (or no IPS distances when ``fixes`` is None).
    """
    odom = recording.topic(ODOM)
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
    # the status frames' yaw-rate flicker on straight moves is not rotation (analysis_tracks)
    poses = resolved_odometry(t_s, poses, odom_yaw_deadband_radps)
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
    knot_index, knot_comp, knot_sigma, knot_dir, knot_share = process_knots(
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
        knot_share=knot_share,
    )


def _whiten(chol: _Array, err: _Array) -> _Array:
    """L⁻¹ e per fix for errors (n, 2) or Jacobian blocks (n, 2, k)."""
    l11, l21, l22 = chol[:, 0], chol[:, 1], chol[:, 2]
    if err.ndim == 3:
        l11, l21, l22 = l11[:, None], l21[:, None], l22[:, None]
    r1 = err[:, 0] / l11
    r2 = (err[:, 1] - l21 * r1) / l22
    return np.stack([r1, r2], axis=1)


# --------------------------------------------------------------------------- keyframes


@dataclass(frozen=True)
class _Layout:
    """Where one recording's keyframes and slip parameters sit (see :class:`SparseJointProblem`).

    Attributes:
        seg_start: (S,) first odometry sample of each segment.
        seg_of_sample: (N,) segment of each odometry sample.
        origin: (S,) full-vector index of each segment origin's x (y and yaw follow).
        full_inc: (S − 1,) increment of the full knot that starts segments 1 … S − 1.
        full_knots: (S − 1, 3) positions in the track's knot list of its along, across and dθ.
        partial: (Kp,) positions in the knot list of the other (partial) knots.
        partial_seg: (Kp,) their segment.
        partial_col: (Kp,) their full-vector index.
    """

    seg_start: NDArray[np.intp]
    seg_of_sample: NDArray[np.intp]
    origin: NDArray[np.intp]
    full_inc: NDArray[np.intp]
    full_knots: NDArray[np.intp]
    partial: NDArray[np.intp]
    partial_seg: NDArray[np.intp]
    partial_col: NDArray[np.intp]


def _layout(tr: Track, offset: int) -> tuple[_Layout, int]:
    """The keyframe layout of a track whose local parameters start at ``offset``; and their count."""
    n = tr.t_s.size
    inc, first, counts = np.unique(tr.knot_index, return_index=True, return_counts=True)
    full = counts == 3  # ordered by index then component: along, across, dθ
    full_inc = inc[full].astype(np.intp)
    full_knots = first[full][:, None] + np.arange(3)[None, :]
    seg_start = np.concatenate([[0], full_inc + 1]).astype(np.intp)
    seg_of_sample = np.searchsorted(full_inc, np.arange(n), side="left").astype(np.intp)
    partial = np.flatnonzero(~np.isin(tr.knot_index, full_inc)).astype(np.intp)
    partial_seg = seg_of_sample[tr.knot_index[partial]]
    segments = np.arange(seg_start.size)
    before = np.searchsorted(partial_seg, segments, side="left")
    origin = (offset + 3 * segments + before).astype(np.intp)
    partial_col = (offset + 3 * (partial_seg + 1) + np.arange(partial.size)).astype(np.intp)
    layout = _Layout(
        seg_start=seg_start,
        seg_of_sample=seg_of_sample,
        origin=origin,
        full_inc=full_inc,
        full_knots=full_knots.astype(np.intp),
        partial=partial,
        partial_seg=partial_seg.astype(np.intp),
        partial_col=partial_col,
    )
    return layout, 3 * seg_start.size + partial.size


def _ragged(
    lo: NDArray[np.intp], hi: NDArray[np.intp]
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """(owner, item) for every item in the half-open ranges [lo_j, hi_j), owners in order."""
    counts = np.maximum(hi - lo, 0)
    owner = np.repeat(np.arange(lo.size), counts)
    starts = np.cumsum(counts) - counts
    item = np.arange(int(counts.sum())) - np.repeat(starts - lo, counts)
    return owner.astype(np.intp), item.astype(np.intp)


@dataclass
class _State:
    """One recording's model at a parameter vector (what the Jacobian needs)."""

    real: _Array
    poses: _Array
    hedge: _Array
    origins: _Array


@dataclass(frozen=True)
class _FixPattern:
    """Where one recording's fix rows have entries in the local Jacobian (valid while no fix
    moves across an odometry sample). Two terms per fix (sample a, weight 1 − u; sample a + 1,
    weight u), sorted by sample; each has its segment origin's three columns, then partial knots.

    Attributes:
        a: (n,) the fixes' first samples it was built for.
        order: (2n,) term → index into ``[1 − u, u]`` (fix-major).
        sample: (2n,) the term's odometry sample.
        seg: (2n,) its segment.
        owner: (T,) per partial-knot entry, its partial knot (position in the layout's list).
        term: (T,) and its term.
        chol: (E, 3) the Cholesky factor of each entry's fix (E = 3 × 2n + T).
        rows: (2E,) COO rows (fix rows of both coordinates, the track's first row at 0).
        cols: (2E,) COO columns (full-vector indices).
    """

    a: NDArray[np.intp]
    order: NDArray[np.intp]
    sample: NDArray[np.intp]
    seg: NDArray[np.intp]
    owner: NDArray[np.intp]
    term: NDArray[np.intp]
    chol: _Array
    rows: NDArray[np.intp]
    cols: NDArray[np.intp]


@dataclass(frozen=True)
class _CsrPattern:
    """The local Jacobian's CSR structure and where each COO entry adds into its data."""

    a: tuple[NDArray[np.intp], ...]
    fix: tuple[_FixPattern, ...]
    target: NDArray[np.intp]
    indices: NDArray[np.int32]
    indptr: NDArray[np.int32]
    nnz: int


@dataclass
class Linearisation:
    """Residuals and Jacobian of the sparse problem at a point.

    Attributes:
        fun: residual vector (fix rows of every recording, then the slip priors).
        local: (rows, P − N_SHARED) sparse CSR ∂fun/∂(alignments, keyframes, partial slips).
        shared: (rows, free shared) dense ∂fun/∂(free factors, offset, latency).
    """

    fun: _Array
    local: Any
    shared: _Array


class SparseJointProblem:
    """The joint fit with keyframes: a Jacobian with O(N) non-zeros, a banded normal matrix.

    A knot with all three slip components (a chunk that travelled) is a keyframe: the pose
    after it is a free map-frame parameter and its slip is what takes the pose before it there;
    between keyframes, the odometry integrated from the keyframe, perturbed by the partial
    knots. Full vector: the shared parameters, then per recording its segments, each its origin
    (3) then its partial knots (the first origin is the alignment, map ← odom).
    """

    def __init__(self, tracks: Sequence[Track]) -> None:
        self.tracks = tuple(tracks)
        names = [*FACTOR_NAMES, *OFFSET_NAMES, LATENCY_NAME]
        named = list(range(N_SHARED))
        layouts: list[_Layout] = []
        start = N_SHARED
        for i, tr in enumerate(self.tracks):
            lay, count = _layout(tr, start)
            layouts.append(lay)
            local = [""] * count
            for s, o in enumerate(lay.origin - start):
                local[o : o + 3] = (
                    alignment_names(i)
                    if s == 0
                    else (
                        f"keyframe[{i}][{s}].x_m",
                        f"keyframe[{i}][{s}].y_m",
                        f"keyframe[{i}][{s}].yaw_rad",
                    )
                )
            for j, c in zip(lay.partial, lay.partial_col - start, strict=True):
                local[c] = f"slip[{i}][{j}].{('along', 'across', 'yaw')[tr.knot_comp[j]]}"
            names.extend(local)
            named.extend(range(start, start + 3))
            start += count
        self.layouts = tuple(layouts)
        self.names = tuple(names)
        self.named = np.array(named, dtype=np.intp)
        self.n_fix_rows = [2 * tr.fix_xy.shape[0] for tr in self.tracks]
        self.n_rows = sum(self.n_fix_rows) + sum(tr.knot_index.size for tr in self.tracks)
        self._csr: _CsrPattern | None = None
        self._last_a: tuple[NDArray[np.intp], ...] | None = None

    # ------------------------------------------------------------------ model

    def _state(self, full: _Array, i: int) -> _State:
        tr, lay = self.tracks[i], self.layouts[i]
        real = real_increments(tr.raw, CorrectionFactors.from_vector(full[:7]))
        if lay.partial.size:
            p = lay.partial
            values = full[lay.partial_col]
            comp = tr.knot_comp[p]
            pos = comp < 2
            ang = tr.knot_dir[p][pos] + np.where(comp[pos] == 1, 0.5 * np.pi, 0.0)
            np.add.at(real[:, 0], tr.knot_index[p][pos], values[pos] * np.cos(ang))
            np.add.at(real[:, 1], tr.knot_index[p][pos], values[pos] * np.sin(ang))
            np.add.at(real[:, 2], tr.knot_index[p][~pos], values[~pos])
        # integrate_increments and compose/transform, with the trigonometry done once
        yaw_odo = tr.start_odom[2] + np.concatenate([[0.0], np.cumsum(real[:, 2])])
        mid = yaw_odo[:-1] + 0.5 * real[:, 2]
        c, s = np.cos(mid), np.sin(mid)
        odo_x = np.concatenate([[tr.start_odom[0]], c * real[:, 0] - s * real[:, 1]]).cumsum()
        odo_y = np.concatenate([[tr.start_odom[1]], s * real[:, 0] + c * real[:, 1]]).cumsum()
        origins = full[lay.origin[:, None] + np.arange(3)[None, :]]
        base = np.column_stack([odo_x, odo_y, yaw_odo])[lay.seg_start]
        base[0] = 0.0
        to_map = compose_poses(origins, invert_poses(base))
        seg = lay.seg_of_sample
        tc, ts = np.cos(to_map[:, 2])[seg], np.sin(to_map[:, 2])[seg]
        poses = np.empty((yaw_odo.size, 3))
        poses[:, 0] = to_map[seg, 0] + tc * odo_x - ts * odo_y
        poses[:, 1] = to_map[seg, 1] + ts * odo_x + tc * odo_y
        poses[:, 2] = to_map[seg, 2] + yaw_odo
        ox, oy = full[7], full[8]
        cy, sy = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        hedge = np.column_stack([poses[:, 0] + cy * ox - sy * oy, poses[:, 1] + sy * ox + cy * oy])
        return _State(real, poses, hedge, origins)

    def _fix_model(self, full: _Array, i: int, st: _State) -> _Array:
        tr = self.tracks[i]
        return interpolate_track(tr.t_s, st.hedge, tr.fix_t_s - full[9])

    def _priors(self, full: _Array, i: int, st: _State) -> _Array:
        tr, lay = self.tracks[i], self.layouts[i]
        out = np.empty(tr.knot_index.size)
        out[lay.partial] = full[lay.partial_col] / tr.knot_sigma[lay.partial]
        if lay.full_inc.size:
            delta = _knot_slip(st.poses, st.real, lay.full_inc)
            fk = lay.full_knots
            d = tr.knot_dir[fk[:, 0]]
            c, s = np.cos(d), np.sin(d)
            out[fk[:, 0]] = (c * delta[:, 0] + s * delta[:, 1]) / tr.knot_sigma[fk[:, 0]]
            out[fk[:, 1]] = (c * delta[:, 1] - s * delta[:, 0]) / tr.knot_sigma[fk[:, 1]]
            out[fk[:, 2]] = delta[:, 2] / tr.knot_sigma[fk[:, 2]]
        return out

    def errors(self, full: _Array) -> list[_Array]:
        """Fix minus model, (n, 2) per recording, metres."""
        out = []
        for i, tr in enumerate(self.tracks):
            out.append(tr.fix_xy - self._fix_model(full, i, self._state(full, i)))
        return out

    def whitened(self, full: _Array) -> list[_Array]:
        """Whitened fix residuals, (n, 2) per recording."""
        return [_whiten(tr.chol, e) for tr, e in zip(self.tracks, self.errors(full), strict=True)]

    def residuals(self, full: _Array, states: Sequence[_State] | None = None) -> _Array:
        """The residual vector at the full parameter vector ``full`` (its model: ``states``)."""
        if states is None:
            states = [self._state(full, i) for i in range(len(self.tracks))]
        fixes: list[_Array] = []
        priors: list[_Array] = []
        for i, (tr, st) in enumerate(zip(self.tracks, states, strict=True)):
            fixes.append(_whiten(tr.chol, tr.fix_xy - self._fix_model(full, i, st)).ravel())
            priors.append(self._priors(full, i, st))
        return np.concatenate([*fixes, *priors])

    def initialise(self, full: _Array) -> None:
        """Set the keyframes (in place) to the poses dead-reckoned from the alignments with the
        factors, and the partial knots to zero."""
        factors = CorrectionFactors.from_vector(full[:7])
        for i, tr in enumerate(self.tracks):
            lay = self.layouts[i]
            o = lay.origin
            real = real_increments(tr.raw, factors)
            poses = integrate_increments(compose_poses(full[o[0] : o[0] + 3], tr.start_odom), real)
            full[o[1:, None] + np.arange(3)[None, :]] = poses[lay.seg_start[1:]]
            full[lay.partial_col] = 0.0

    def anchor(self, full: _Array, *, reach: float = ANCHOR_REACH) -> None:
        """Set the alignments and keyframes (in place) from the fixes around each keyframe.

        Each keyframe is the dead-reckoned pose under the rigid alignment
        (:func:`windowed_procrustes`) of the odometry to the fixes within ``reach`` units of
        motion (1 m or 1 rad each); partial knots start at zero. A recording without keyframes
        keeps its alignment.
        """
        factors = CorrectionFactors.from_vector(full[:7])
        for i, tr in enumerate(self.tracks):
            lay = self.layouts[i]
            if lay.full_inc.size == 0:
                continue
            real = real_increments(tr.raw, factors)
            odo = integrate_increments(tr.start_odom, real)
            at = tr.fix_t_s - full[9]
            q = interpolate_track(tr.t_s, hedge_track(odo, full[7:9]), at)
            measure = np.concatenate(
                [[0.0], np.cumsum(np.hypot(real[:, 0], real[:, 1]) + np.abs(real[:, 2]))]
            )
            transforms = windowed_procrustes(
                np.interp(at, tr.t_s, measure), q, tr.fix_xy, measure[lay.seg_start], reach
            )
            origins = compose_poses(transforms, odo[lay.seg_start])
            origins[0] = transforms[0]
            full[lay.origin[:, None] + np.arange(3)[None, :]] = origins
            full[lay.partial_col] = 0.0

    def x_scale(self, align_scale: Sequence[float]) -> _Array:
        """Typical sizes of the local parameters (alignment, keyframe origin, partial slip)."""
        out: list[_Array] = []
        for i, tr in enumerate(self.tracks):
            lay = self.layouts[i]
            n_local = (
                self.layouts[i + 1].origin[0] if i + 1 < len(self.tracks) else len(self.names)
            ) - lay.origin[0]
            xs = np.empty(n_local)
            o = lay.origin - lay.origin[0]
            xs[o[0] : o[0] + 3] = align_scale
            if lay.full_inc.size:
                sig = tr.knot_sigma[lay.full_knots]
                pos = np.maximum(sig[:, 0], sig[:, 1])
                xs[o[1:, None] + np.arange(3)[None, :]] = np.column_stack([pos, pos, sig[:, 2]])
            xs[lay.partial_col - lay.origin[0]] = tr.knot_sigma[lay.partial]
            out.append(xs)
        return np.concatenate(out) if out else np.zeros(0)

    # ------------------------------------------------------------------ Jacobian

    def linearise(self, full: _Array, shared_free: NDArray[np.intp]) -> Linearisation:
        """Residuals, the sparse local Jacobian and the dense shared columns (all analytic)."""
        states = [self._state(full, i) for i in range(len(self.tracks))]
        interp = [self._interpolation(full, i) for i in range(len(self.tracks))]
        fun = self.residuals(full, states)
        local = self._local_jacobian(full, states, interp)
        shared = np.zeros((self.n_rows, shared_free.size))
        row0 = 0
        prior0 = sum(self.n_fix_rows)
        for i, tr in enumerate(self.tracks):
            fix_cols, prior_cols = self._shared_columns(full, i, states[i], shared_free)
            shared[row0 : row0 + self.n_fix_rows[i]] = fix_cols
            shared[prior0 : prior0 + tr.knot_index.size] = prior_cols
            row0 += self.n_fix_rows[i]
            prior0 += tr.knot_index.size
        return Linearisation(fun=fun, local=local, shared=shared)

    def _interpolation(self, full: _Array, i: int) -> tuple[NDArray[np.intp], _Array, _Array]:
        """Per fix: sample a, weight u of sample a + 1, and ∂u/∂(fix time) (0 when clamped)."""
        tr = self.tracks[i]
        at = tr.fix_t_s - full[9]
        a = np.clip(np.searchsorted(tr.t_s, at, side="right") - 1, 0, tr.t_s.size - 2)
        dt = tr.t_s[a + 1] - tr.t_s[a]
        raw_u = (at - tr.t_s[a]) / dt
        u = np.clip(raw_u, 0.0, 1.0)
        du = np.where((raw_u >= 0.0) & (raw_u < 1.0), 1.0 / dt, 0.0)
        return a.astype(np.intp), u, du

    def _shared_columns(
        self, full: _Array, i: int, st: _State, shared_free: NDArray[np.intp]
    ) -> tuple[_Array, _Array]:
        """Whitened fix rows (2n, k) and prior rows (K, k) w.r.t. the free shared parameters
        (factors by :func:`_factor_sums`; the latency slides the interpolation, the offset turns
        with the pose)."""
        tr, lay = self.tracks[i], self.layouts[i]
        n_fix, n_knot = tr.fix_xy.shape[0], tr.knot_index.size
        fix_cols = np.zeros((2 * n_fix, shared_free.size))
        prior_cols = np.zeros((n_knot, shared_free.size))
        a, u, du = self._interpolation(full, i)
        yaw = st.poses[:, 2]
        factor_cols = np.flatnonzero(shared_free < 7)
        if factor_cols.size:
            d_real = real_increments_jacobian(tr.raw, CorrectionFactors.from_vector(full[:7]))
            e = np.ascontiguousarray(d_real[shared_free[factor_cols]])  # (k, M, 3)
            k_full = lay.full_inc
            dm, d_key = _factor_sums(
                e,
                np.ascontiguousarray(st.poses),
                np.ascontiguousarray(st.hedge),
                lay.seg_start,
                k_full,
                a,
                u,
            )  # (n, 2, k) at the fixes, (F, k, 3) at the keyframes
            fix_cols[:, factor_cols] = _whiten(tr.chol, -dm).reshape(2 * n_fix, factor_cols.size)
            if k_full.size:
                d_prev = _slip_jacobian(st.poses[k_full], st.poses[k_full + 1])[1]
                fk = lay.full_knots
                proj = _projection(tr.knot_dir[fk[:, 0]], tr.knot_sigma[fk])
                d_pose = d_key.transpose(0, 2, 1)  # (F, 3, k)
                d_slip = np.einsum("fij,fjk->fik", d_prev, d_pose)
                d_slip -= e[:, k_full].transpose(1, 2, 0)
                cols = np.einsum("fij,fjk->fik", proj, d_slip)  # (F, 3, k)
                prior_cols[np.ix_(fk.ravel(), factor_cols)] = cols.reshape(-1, factor_cols.size)
        for column, j in enumerate(shared_free):
            if j < 7:
                continue
            if j < 9:
                ang = yaw + (0.0 if j == 7 else 0.5 * np.pi)
                dh = np.column_stack([np.cos(ang), np.sin(ang)])
                dmo = (1.0 - u)[:, None] * dh[a] + u[:, None] * dh[a + 1]
                fix_cols[:, column] = _whiten(tr.chol, -dmo).ravel()
            else:
                dml = (st.hedge[a + 1] - st.hedge[a]) * du[:, None]
                fix_cols[:, column] = _whiten(tr.chol, dml).ravel()
        return fix_cols, prior_cols

    def _fix_pattern(self, i: int, a: NDArray[np.intp]) -> _FixPattern:
        """The structure of recording ``i``'s fix rows for fixes between samples a and a + 1."""
        tr, lay = self.tracks[i], self.layouts[i]
        n_samples = tr.t_s.size
        fix = np.concatenate([np.arange(a.size), np.arange(a.size)])
        sample = np.concatenate([a, a + 1])
        order = np.argsort(sample, kind="stable").astype(np.intp)
        fix, sample = fix[order], sample[order]
        seg = lay.seg_of_sample[sample]
        f_parts = [fix, fix, fix]
        c_parts = [lay.origin[seg], lay.origin[seg] + 1, lay.origin[seg] + 2]
        owner = term = np.zeros(0, dtype=np.intp)
        if lay.partial.size:
            k = tr.knot_index[lay.partial]
            seg_end = np.append(lay.seg_start[1:], n_samples)[lay.partial_seg]
            lo = np.searchsorted(sample, k + 1, side="left")
            hi = np.searchsorted(sample, seg_end, side="left")
            owner, term = _ragged(lo.astype(np.intp), hi.astype(np.intp))
            f_parts.append(fix[term])
            c_parts.append(lay.partial_col[owner])
        f = np.concatenate(f_parts)
        col = np.concatenate(c_parts)
        return _FixPattern(
            a=a,
            order=order,
            sample=sample,
            seg=seg,
            owner=owner,
            term=term,
            chol=tr.chol[f],
            rows=np.concatenate([2 * f, 2 * f + 1]).astype(np.intp),
            cols=np.concatenate([col, col]).astype(np.intp),
        )

    def _fix_values(self, i: int, st: _State, pat: _FixPattern, u: _Array) -> _Array:
        """Values of the whitened fix rows' entries, in the order of ``pat``."""
        tr, lay = self.tracks[i], self.layouts[i]
        weight = np.concatenate([1.0 - u, u])[pat.order]
        lever = st.hedge[pat.sample] - st.origins[pat.seg, :2]
        zeros = np.zeros_like(weight)
        d_x = [weight, zeros, -lever[:, 1] * weight]
        d_y = [zeros, weight, lever[:, 0] * weight]
        if pat.owner.size:
            p = lay.partial
            k = tr.knot_index[p]
            comp = tr.knot_comp[p][pat.owner]
            w = weight[pat.term]
            centre = 0.5 * (st.poses[k, :2] + st.poses[k + 1, :2])[pat.owner]
            phi = 0.5 * (st.poses[k, 2] + st.poses[k + 1, 2])[pat.owner] + tr.knot_dir[p][pat.owner]
            phi = phi + np.where(comp == 1, 0.5 * np.pi, 0.0)
            arm = st.hedge[pat.sample[pat.term]] - centre
            head = comp == 2
            d_x.append(np.where(head, -arm[:, 1], np.cos(phi)) * w)
            d_y.append(np.where(head, arm[:, 0], np.sin(phi)) * w)
        dm = np.column_stack([np.concatenate(d_x), np.concatenate(d_y)])
        wt = _whiten(pat.chol, -dm)
        return np.concatenate([wt[:, 0], wt[:, 1]])

    def _csr_pattern(
        self,
        a: Sequence[NDArray[np.intp]],
        pats: tuple[_FixPattern, ...],
        rows: NDArray[np.intp],
        cols: NDArray[np.intp],
    ) -> _CsrPattern:
        """The CSR structure of the local Jacobian with these COO entries, and its map."""
        n_local = len(self.names) - N_SHARED
        key = rows.astype(np.int64) * n_local + (cols - N_SHARED)
        uniq, target = np.unique(key, return_inverse=True)
        indptr = np.searchsorted(uniq // n_local, np.arange(self.n_rows + 1), side="left")
        return _CsrPattern(
            a=tuple(np.array(x, copy=True) for x in a),
            fix=pats,
            target=target.astype(np.intp).ravel(),
            indices=(uniq % n_local).astype(np.int32),
            indptr=indptr.astype(np.int32),
            nnz=int(uniq.size),
        )

    def _local_jacobian(
        self, full: _Array, states: Sequence[_State], interp: Sequence[tuple[Any, _Array, _Array]]
    ) -> Any:
        """The sparse local Jacobian (CSR); its structure is reused while no fix moves across an
        odometry sample (two linearisations in a row alike), refilling only the values."""
        from scipy import sparse  # a slow import: only fits need it

        a = [x[0] for x in interp]
        n_local = len(self.names) - N_SHARED
        shape = (self.n_rows, n_local)
        cached = self._csr
        same = cached is not None and all(
            np.array_equal(x, y) for x, y in zip(cached.a, a, strict=True)
        )
        pats = cached.fix if same and cached is not None else None
        if pats is None:
            pats = tuple(self._fix_pattern(i, ai) for i, ai in enumerate(a))
        vals: list[_Array] = []
        prior0 = sum(self.n_fix_rows)
        for i, tr in enumerate(self.tracks):
            vals.append(self._fix_values(i, states[i], pats[i], interp[i][1]))
            vals.append(self._prior_entries(i, states[i], prior0)[2])
            prior0 += tr.knot_index.size
        values = np.concatenate(vals)
        if same and cached is not None and cached.nnz:
            data = np.bincount(cached.target, weights=values, minlength=cached.nnz)
            return sparse.csr_matrix((data, cached.indices, cached.indptr), shape=shape)
        rows, cols = self._coo_structure(pats, states)
        stable = self._last_a is not None and all(
            np.array_equal(x, y) for x, y in zip(self._last_a, a, strict=True)
        )
        self._last_a = tuple(np.array(x, copy=True) for x in a)
        if stable:
            self._csr = self._csr_pattern(a, pats, rows, cols)
            data = np.bincount(self._csr.target, weights=values, minlength=self._csr.nnz)
            return sparse.csr_matrix((data, self._csr.indices, self._csr.indptr), shape=shape)
        return sparse.csr_matrix((values, (rows, cols - N_SHARED)), shape=shape)

    def _coo_structure(
        self, pats: Sequence[_FixPattern], states: Sequence[_State]
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """COO rows and columns of every entry, in the order :meth:`_local_jacobian` fills them."""
        rows: list[NDArray[np.intp]] = []
        cols: list[NDArray[np.intp]] = []
        row0, prior0 = 0, sum(self.n_fix_rows)
        for i, tr in enumerate(self.tracks):
            rows.append(row0 + pats[i].rows)
            cols.append(pats[i].cols)
            r, c, _ = self._prior_entries(i, states[i], prior0)
            rows.append(r)
            cols.append(c)
            row0 += self.n_fix_rows[i]
            prior0 += tr.knot_index.size
        return np.concatenate(rows), np.concatenate(cols)

    def _prior_entries(
        self, i: int, st: _State, prior0: int
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], _Array]:
        """COO entries of the slip prior rows."""
        tr, lay = self.tracks[i], self.layouts[i]
        rows = [prior0 + lay.partial]
        cols = [lay.partial_col]
        vals = [1.0 / tr.knot_sigma[lay.partial]]
        if lay.full_inc.size:
            k = lay.full_inc
            p0, p1 = st.poses[k], st.poses[k + 1]
            f = k.size
            d_next, d_prev = _slip_jacobian(p0, p1)
            fk = lay.full_knots
            proj = _projection(tr.knot_dir[fk[:, 0]], tr.knot_sigma[fk])
            a_next = proj @ d_next  # w.r.t. the origin of segment s (= pose_k+1)
            a_prev = proj @ d_prev  # w.r.t. pose_k
            # pose_k w.r.t. the origin of segment s − 1
            o_prev = st.origins[:-1]
            m = np.zeros((f, 3, 3))
            m[:, 0, 0] = m[:, 1, 1] = m[:, 2, 2] = 1.0
            m[:, 0, 2] = -(p0[:, 1] - o_prev[:, 1])
            m[:, 1, 2] = p0[:, 0] - o_prev[:, 0]
            blocks = [(a_next, lay.origin[1:]), (a_prev @ m, lay.origin[:-1])]
            for block, origin in blocks:
                rr = np.broadcast_to(prior0 + fk[:, :, None], (f, 3, 3))
                cc = np.broadcast_to(origin[:, None, None] + np.arange(3)[None, None, :], (f, 3, 3))
                rows.append(rr.ravel())
                cols.append(cc.ravel())
                vals.append(block.ravel())
            # pose_k w.r.t. the partial knots of segment s − 1 (those before a full knot)
            has_end = lay.partial_seg < lay.full_inc.size
            if np.any(has_end):
                p = lay.partial[has_end]
                s_end = lay.partial_seg[has_end]  # full knot s_end ends segment s_end
                kp = tr.knot_index[p]
                comp = tr.knot_comp[p]
                centre = 0.5 * (st.poses[kp, :2] + st.poses[kp + 1, :2])
                psi = 0.5 * (st.poses[kp, 2] + st.poses[kp + 1, 2]) + tr.knot_dir[p]
                psi = psi + np.where(comp == 1, 0.5 * np.pi, 0.0)
                end = p0[s_end]
                head = comp == 2
                vec = np.column_stack(
                    [
                        np.where(head, -(end[:, 1] - centre[:, 1]), np.cos(psi)),
                        np.where(head, end[:, 0] - centre[:, 0], np.sin(psi)),
                        np.where(head, 1.0, 0.0),
                    ]
                )
                col_vals = np.einsum("kij,kj->ki", a_prev[s_end], vec)  # (Kp', 3)
                rows.append((prior0 + fk[s_end]).ravel())
                cols.append(np.repeat(lay.partial_col[has_end], 3))
                vals.append(col_vals.ravel())
        return np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)


def windowed_procrustes(
    m: _Array,
    q: _Array,
    p: _Array,
    centres: _Array,
    reach: float,
    *,
    min_spread_m: float = ANCHOR_SPREAD_M,
    rounds: int = 3,
) -> _Array:
    """(S, 3) rigid transforms (x, y, yaw) mapping points q onto p, one per window of m.

    Window s holds the points with ``|m − centres[s]| ≤ reach`` (``m`` non-decreasing), its
    reach doubled until they spread by ``min_spread_m`` RMS or it holds everything; Procrustes
    from running sums, O(n + S). Points beyond max(3 × median, 5 cm) of their nearest window
    are dropped and the sums redone ``rounds`` times. Yaws unwrapped along the windows.
    """
    n = m.size
    keep = np.ones(n, dtype=bool)
    centres = np.asarray(centres, dtype=np.float64)
    out = np.zeros((centres.size, 3))
    near = np.clip(np.searchsorted(centres, m), 0, centres.size - 1)
    prev = np.clip(near - 1, 0, None)
    near = np.where(np.abs(m - centres[prev]) < np.abs(m - centres[near]), prev, near)
    for _ in range(rounds):
        w = keep.astype(np.float64)
        cols = np.column_stack(
            [
                w,
                w * q[:, 0],
                w * q[:, 1],
                w * p[:, 0],
                w * p[:, 1],
                w * q[:, 0] * p[:, 0],
                w * q[:, 0] * p[:, 1],
                w * q[:, 1] * p[:, 0],
                w * q[:, 1] * p[:, 1],
                w * (q[:, 0] ** 2 + q[:, 1] ** 2),
            ]
        )
        cum = np.vstack([np.zeros((1, cols.shape[1])), np.cumsum(cols, axis=0)])
        width = np.full(centres.size, reach)
        sums = np.zeros((centres.size, cols.shape[1]))
        todo = np.ones(centres.size, dtype=bool)
        while np.any(todo):
            lo = np.searchsorted(m, centres[todo] - width[todo], side="left")
            hi = np.searchsorted(m, centres[todo] + width[todo], side="right")
            sums[todo] = cum[hi] - cum[lo]
            cnt = np.maximum(sums[:, 0], 1.0)
            spread2 = (sums[:, 9] - (sums[:, 1] ** 2 + sums[:, 2] ** 2) / cnt) / cnt
            whole = np.zeros(centres.size, dtype=bool)
            whole[todo] = (lo == 0) & (hi == n)
            todo = (todo & ~whole) & ((sums[:, 0] < 3.0) | (spread2 < min_spread_m**2))
            width[todo] *= 2.0
        cnt = np.maximum(sums[:, 0], 1.0)
        qc, pc = sums[:, 1:3] / cnt[:, None], sums[:, 3:5] / cnt[:, None]
        h00 = sums[:, 5] - cnt * qc[:, 0] * pc[:, 0]
        h01 = sums[:, 6] - cnt * qc[:, 0] * pc[:, 1]
        h10 = sums[:, 7] - cnt * qc[:, 1] * pc[:, 0]
        h11 = sums[:, 8] - cnt * qc[:, 1] * pc[:, 1]
        yaw = np.unwrap(np.arctan2(h01 - h10, h00 + h11))
        out = np.column_stack([pc - rotate_xy(yaw, qc), yaw])
        moved = rotate_xy(out[near, 2], q) + out[near, :2]
        d = np.hypot(moved[:, 0] - p[:, 0], moved[:, 1] - p[:, 1])
        new_keep = d <= max(3.0 * float(np.median(d[keep])), 0.05)
        if np.count_nonzero(new_keep) < 3 or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    return out


def _slip_jacobian(p0: _Array, p1: _Array) -> tuple[_Array, _Array]:
    """(F, 3, 3) ∂δ/∂pose_k+1 and ∂δ/∂pose_k of :func:`_knot_slip` at poses p0 = k, p1 = k + 1."""
    phi = 0.5 * (p0[:, 2] + p1[:, 2])
    c, s = np.cos(phi), np.sin(phi)
    dx, dy = p1[:, 0] - p0[:, 0], p1[:, 1] - p0[:, 1]
    vx, vy = c * dx + s * dy, -s * dx + c * dy
    d_next = np.zeros((p0.shape[0], 3, 3))
    d_next[:, 0, 0], d_next[:, 0, 1], d_next[:, 0, 2] = c, s, 0.5 * vy
    d_next[:, 1, 0], d_next[:, 1, 1], d_next[:, 1, 2] = -s, c, -0.5 * vx
    d_next[:, 2, 2] = 1.0
    d_prev = -d_next
    d_prev[:, :2, 2] = d_next[:, :2, 2]
    return d_next, d_prev


def _projection(direction: _Array, sigma: _Array) -> _Array:
    """(F, 3, 3) body (dx, dy, dθ) → (along, across, dθ) / σ for knots with these directions."""
    c, s = np.cos(direction), np.sin(direction)
    proj = np.zeros((direction.size, 3, 3))
    proj[:, 0, 0], proj[:, 0, 1] = c, s
    proj[:, 1, 0], proj[:, 1, 1] = -s, c
    proj[:, 2, 2] = 1.0
    return proj / sigma[:, :, None]


def _knot_slip(poses: _Array, real: _Array, k: NDArray[np.intp]) -> _Array:
    """(F, 3) body-frame slip (dx, dy, dθ) that takes pose k to pose k + 1 given increment k."""
    p0, p1 = poses[k], poses[k + 1]
    phi = 0.5 * (p0[:, 2] + p1[:, 2])
    body = rotate_xy(-phi, p1[:, :2] - p0[:, :2])
    return np.column_stack([body - real[k, :2], p1[:, 2] - p0[:, 2] - real[k, 2]])


class NormalEquations:
    """``JᵀWJ`` of a Jacobian split into local (sparse) and shared (dense) columns.

    Solved by the Schur complement on the shared block: banded Cholesky of the local block B,
    O(P b²); C (local × shared) and D (shared × shared) dense, at most ten columns.
    """

    def __init__(self, local: Any, shared: _Array, row_weights: _Array | None = None) -> None:
        from scipy import sparse

        if row_weights is not None:
            sw = np.sqrt(row_weights)
            local = sparse.diags(sw) @ local
            shared = shared * sw[:, None]
        self.local = local
        self.shared = shared
        b = (local.T @ local).tocoo()
        self.n_local = int(b.shape[0])
        upper = b.row <= b.col
        r, c, v = b.row[upper], b.col[upper], b.data[upper]
        self.band = int(np.max(c - r)) if c.size else 0
        self.ab = np.zeros((self.band + 1, self.n_local))
        np.add.at(self.ab, (self.band + r - c, c), v)
        self.c = np.asarray(local.T @ shared)
        # einsum, not BLAS (docs/joint-calibration.md)
        self.d = np.einsum("ij,ik->jk", shared, shared)

    def diagonal(self) -> tuple[_Array, _Array]:
        """Diagonals of the local and the shared blocks."""
        return self.ab[self.band].copy(), np.diag(self.d).copy()

    def _damped(
        self, mu: float, diag_local: _Array, diag_shared: _Array
    ) -> tuple[_Array, _Array, _Array]:
        """Band, C and D of ``JᵀWJ + μ diag``."""
        ab, d = self.ab.copy(), self.d.copy()
        ab[self.band] += mu * diag_local
        d[np.diag_indices_from(d)] += mu * diag_shared
        return ab, self.c, d

    def solve(
        self,
        rhs_local: _Array,
        rhs_shared: _Array,
        *,
        mu: float = 0.0,
        diag_local: _Array | None = None,
        diag_shared: _Array | None = None,
    ) -> tuple[_Array, _Array]:
        """Solve ``(JᵀWJ + μ diag) x = rhs`` for the local and the shared parts."""
        ns = self.d.shape[0]
        dl = np.zeros(self.n_local) if diag_local is None else diag_local
        ds = np.zeros(ns) if diag_shared is None else diag_shared
        ab, c, d = self._damped(mu, dl, ds)
        cb = _cholesky_banded(ab)
        x = _cho_solve_banded(cb, np.column_stack([c, rhs_local]))
        bc, bg = x[:, :ns], x[:, ns]
        xs = _solve_small(d - c.T @ bc, rhs_shared - c.T @ bg)
        return bg - bc @ xs, xs

    def quadratic(self, step_local: _Array, step_shared: _Array) -> float:
        """``|J p|²`` (weighted) for a step p."""
        jp = self.local @ step_local + np.einsum("ij,j->i", self.shared, step_shared)
        return float(jp @ jp)

    def inverse(self, shared_scale: _Array) -> Inverse:
        """The parts of ``(JᵀWJ)⁻¹`` (:class:`Inverse`); the band of B⁻¹ by selected inversion
        (Takahashi, O(P b²): never formed whole)."""
        cb = _cholesky_banded(self.ab)
        e = _cho_solve_banded(cb, self.c)
        scale = np.outer(shared_scale, shared_scale)
        schur = self.d - np.einsum("ij,ik->jk", self.c, e)  # einsum: see NormalEquations
        s_inv = np.linalg.pinv(schur * scale, hermitian=True) * scale
        return Inverse(factor=cb, e=e, s_inv=s_inv, band=_band_inverse(cb))

    def leverages(self, inv: Inverse) -> _Array:
        """Diagonal of the hat matrix ``√W J (JᵀWJ)⁻¹ Jᵀ √W``: each row's leverage.

        Row i (local part l, shared part s): ``lᵀ B⁻¹ l + yᵀ S⁻¹ y`` with ``y = Eᵀ l − s``;
        the first term needs B⁻¹ only where two local columns share a row, i.e. in its band.
        """
        y = np.asarray(self.local @ inv.e) - self.shared  # sparse: no BLAS
        second = np.einsum("ij,jk,ik->i", y, inv.s_inv, y)
        local = self.local.tocsr()
        first = _row_band_quadratic(
            local.indptr.astype(np.int64),
            local.indices.astype(np.int64),
            np.asarray(local.data, dtype=np.float64),
            inv.band,
        )
        return np.asarray(first + second)

    def inverse_columns(self, inv: Inverse, named_local: NDArray[np.intp]) -> tuple[_Array, _Array]:
        """Columns of ``(JᵀWJ)⁻¹`` for the shared parameters then the named local ones.

        Returns their local rows (P, ns + m) and their shared rows (ns, ns + m).
        """
        unit = np.zeros((self.n_local, named_local.size))
        unit[named_local, np.arange(named_local.size)] = 1.0
        b_unit = _cho_solve_banded(inv.factor, unit)  # B⁻¹ e_l
        shared_of_local = -np.einsum("ij,kj->ik", inv.s_inv, inv.e[named_local])  # −S⁻¹ Eᵀ e_l
        local = np.hstack(
            [
                -np.einsum("ij,jk->ik", inv.e, inv.s_inv),
                b_unit - np.einsum("ij,jk->ik", inv.e, shared_of_local),
            ]
        )
        shared = np.hstack([inv.s_inv, shared_of_local])
        return local, shared


@dataclass(frozen=True)
class Inverse:
    """What the blocks of ``(JᵀWJ)⁻¹`` are made of (:meth:`NormalEquations.inverse`).

    With B the banded local block, C the local × shared block and S = D − Cᵀ B⁻¹ C the Schur
    complement: ``(JᵀWJ)⁻¹ = [[B⁻¹ + E S⁻¹ Eᵀ, −E S⁻¹], [−S⁻¹ Eᵀ, S⁻¹]]`` with E = B⁻¹ C.

    Attributes:
        factor: upper banded Cholesky factor of B.
        e: (P, ns) E = B⁻¹ C.
        s_inv: (ns, ns) S⁻¹ (pseudo-inverse, columns scaled for conditioning).
        band: B⁻¹ within the band of B, in the banded storage of B (selected inversion).
    """

    factor: _Array
    e: _Array
    s_inv: _Array
    band: _Array


def _cholesky_banded(ab: _Array) -> _Array:
    """Upper banded Cholesky factor; a touch of damping if it is numerically singular."""
    factor, ok = _band_factor(ab)
    if not ok:
        ab = ab.copy()
        ab[-1] += 1e-12 * max(float(np.max(ab[-1])), 1e-300)
        factor, ok = _band_factor(ab)
        if not ok:
            msg = "the normal matrix of the keyframes is not positive definite"
            raise np.linalg.LinAlgError(msg)
    return factor


def _cho_solve_banded(factor: _Array, rhs: _Array) -> _Array:
    """Solve ``Uᵀ U x = rhs`` for an upper banded Cholesky factor U and (n, m) right-hand sides."""
    return _band_solve(factor, np.ascontiguousarray(rhs, dtype=np.float64))


@numba.njit(cache=True, nogil=True)
def _factor_sums(
    e: _Array,
    poses: _Array,
    hedge: _Array,
    seg_start: NDArray[np.intp],
    key: NDArray[np.intp],
    a: NDArray[np.intp],
    u: _Array,
) -> tuple[_Array, _Array]:  # pragma: no cover - compiled
    """Derivatives of the hedgehog at the fixes and of the pose at ``key`` w.r.t. factors.

    ``e`` (k, M, 3): ∂ real increment / ∂ factor. A change (ex, ey, eθ) of increment m moves
    every later pose p of its segment by R(φ_m) (ex, ey) + eθ R90 (p − c_m) (φ_m, c_m: mid
    heading and mid point of increment m): running sums of R(φ) e, eθ and eθ c, reset at the
    start of each segment. Returns (n, 2, k) dx, dy of the hedgehog interpolated at the
    fixes (between samples ``a`` and ``a + 1``, weight ``u`` of the second) and (F, k, 3) dx,
    dy, dθ of the pose at the samples ``key`` (increasing).
    """
    k, m = e.shape[0], e.shape[1]
    n = m + 1
    d_hedge = np.zeros((n, k, 2))
    d_key = np.zeros((key.size, k, 3))
    acc = np.zeros((k, 5))
    s_next, key_next = 0, 0
    for j in range(n):
        if s_next < seg_start.size and seg_start[s_next] == j:
            acc[:, :] = 0.0
            s_next += 1
        hx, hy = hedge[j, 0], hedge[j, 1]
        for f in range(k):
            d_hedge[j, f, 0] = acc[f, 0] - acc[f, 2] * hy + acc[f, 4]
            d_hedge[j, f, 1] = acc[f, 1] + acc[f, 2] * hx - acc[f, 3]
        if key_next < key.size and key[key_next] == j:
            px, py = poses[j, 0], poses[j, 1]
            for f in range(k):
                d_key[key_next, f, 0] = acc[f, 0] - acc[f, 2] * py + acc[f, 4]
                d_key[key_next, f, 1] = acc[f, 1] + acc[f, 2] * px - acc[f, 3]
                d_key[key_next, f, 2] = acc[f, 2]
            key_next += 1
        if j < m:
            phi = 0.5 * (poses[j, 2] + poses[j + 1, 2])
            c, s = math.cos(phi), math.sin(phi)
            cx = 0.5 * (poses[j, 0] + poses[j + 1, 0])
            cy = 0.5 * (poses[j, 1] + poses[j + 1, 1])
            for f in range(k):
                ex, ey, et = e[f, j, 0], e[f, j, 1], e[f, j, 2]
                acc[f, 0] += c * ex - s * ey
                acc[f, 1] += s * ex + c * ey
                acc[f, 2] += et
                acc[f, 3] += et * cx
                acc[f, 4] += et * cy
    dm = np.empty((a.size, 2, k))
    for i in range(a.size):
        j, w = a[i], u[i]
        for f in range(k):
            dm[i, 0, f] = (1.0 - w) * d_hedge[j, f, 0] + w * d_hedge[j + 1, f, 0]
            dm[i, 1, f] = (1.0 - w) * d_hedge[j, f, 1] + w * d_hedge[j + 1, f, 1]
    return dm, d_key


# The banded Cholesky as compiled loops, one thread, not LAPACK (docs/joint-calibration.md).
# Storage as LAPACK's upper form: A[i, j] at ab[b + i − j, j].


@numba.njit(cache=True, nogil=True)
def _band_factor(ab: _Array) -> tuple[_Array, bool]:  # pragma: no cover - compiled
    b = ab.shape[0] - 1
    n = ab.shape[1]
    u = ab.copy()
    for j in range(n):
        s = u[b, j]
        for k in range(max(0, j - b), j):
            v = u[b + k - j, j]
            s -= v * v
        if not s > 0.0:
            return u, False
        d = math.sqrt(s)
        u[b, j] = d
        for i in range(j + 1, min(n, j + b + 1)):
            s = u[b + j - i, i]
            for k in range(max(0, i - b), j):
                s -= u[b + k - j, j] * u[b + k - i, i]
            u[b + j - i, i] = s / d
    return u, True


@numba.njit(cache=True, nogil=True)
def _band_solve(u: _Array, rhs: _Array) -> _Array:  # pragma: no cover - compiled
    b = u.shape[0] - 1
    n = u.shape[1]
    m = rhs.shape[1]
    x = rhs.copy()
    for j in range(n):  # Uᵀ y = rhs
        d = u[b, j]
        for k in range(max(0, j - b), j):
            v = u[b + k - j, j]
            for c in range(m):
                x[j, c] -= v * x[k, c]
        for c in range(m):
            x[j, c] /= d
    for j in range(n - 1, -1, -1):  # U x = y
        d = u[b, j]
        for i in range(j + 1, min(n, j + b + 1)):
            v = u[b + j - i, i]
            for c in range(m):
                x[j, c] -= v * x[i, c]
        for c in range(m):
            x[j, c] /= d
    return x


@numba.njit(cache=True, nogil=True)
def _band_inverse(u: _Array) -> _Array:  # pragma: no cover - compiled
    """A⁻¹ within the band, for A = UᵀU with U upper banded (Takahashi's recursion).

    From U Σ = U⁻ᵀ (lower, diagonal 1/u_jj): Σ_ji = (δ_ij / u_jj − Σ_k>j u_jk Σ_ki) / u_jj for
    i ≥ j, from the last column back; every Σ_ki it needs lies in the band.
    """
    b = u.shape[0] - 1
    n = u.shape[1]
    s = np.zeros_like(u)
    for j in range(n - 1, -1, -1):
        d = u[b, j]
        top = min(n - 1, j + b)
        for i in range(top, j, -1):
            acc = 0.0
            for k in range(j + 1, top + 1):
                v = s[b + k - i, i] if k <= i else s[b + i - k, k]
                acc += u[b + j - k, k] * v
            s[b + j - i, i] = -acc / d
        acc = 0.0
        for k in range(j + 1, top + 1):
            acc += u[b + j - k, k] * s[b + j - k, k]
        s[b, j] = 1.0 / (d * d) - acc / d
    return s


@numba.njit(cache=True, nogil=True)
def _row_band_quadratic(
    indptr: NDArray[np.int64], indices: NDArray[np.int64], data: _Array, band: _Array
) -> _Array:  # pragma: no cover - compiled
    """``lᵀ Σ l`` for every CSR row l, Σ symmetric given within its band (upper storage)."""
    b = band.shape[0] - 1
    rows = indptr.size - 1
    out = np.zeros(rows)
    for r in range(rows):
        acc = 0.0
        for p in range(indptr[r], indptr[r + 1]):
            i, vi = indices[p], data[p]
            for q in range(indptr[r], indptr[r + 1]):
                j = indices[q]
                lo, hi = (i, j) if i <= j else (j, i)
                acc += vi * data[q] * band[b + lo - hi, hi]
        out[r] = acc
    return out


def _solve_small(a: _Array, b: _Array) -> _Array:
    """Solve a small symmetric system, by least squares if it is singular."""
    if a.size == 0:
        return np.zeros(0)
    try:
        return np.asarray(np.linalg.solve(a, b))
    except np.linalg.LinAlgError:
        return np.asarray(np.linalg.lstsq(a, b, rcond=None)[0])
