"""Tracking error measures of seed 000 Table 4, and their evaluation on a recording.

:class:`TrackingMetrics` (the paper's "position" row is ``rmse_per_axis_m`` = rmse_m / √2);
:func:`track_recording` measures odometry, ips, multilateration, smoothed and ground truth.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import GeometryError, RecordingError
from omnical.estimation.handover import Handover, taken
from omnical.estimation.se2 import transform_points
from omnical.estimation.seed003_estimator import seed003_samples_of, seed003_track
from omnical.estimation.smoother import SmoothedTrack, SmootherParams, smooth_track
from omnical.evaluation.alignment import (
    DEFAULT_ALIGN_IPS,
    DEFAULT_ALIGN_ODOMETRY,
    Alignment,
    AlignMode,
    align,
)
from omnical.evaluation.association import Association, Trajectory, associate, paired_xy
from omnical.ips.from_recording import locate
from omnical.ips.solve.fixes import Fixes, FixStatus, mahalanobis_sq
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import (
    BEACON_RAW_DISTANCE,
    BEACONS_POS_A,
    DEAD_WHEELS,
    GROUND_TRUTH,
    HEDGE_POS_ANG,
    IMU,
    ODOM,
    START,
)
from omnical.robot.description import DeadWheel

__all__ = [
    "ESTIMATES",
    "FIGURE_ROWS",
    "GROUND_TRUTH_KEY",
    "IPS_KEY",
    "METRIC_KEYS",
    "MULTILATERATION_KEY",
    "ODOMETRY_KEY",
    "SEED003_KEY",
    "SMOOTHED_KEY",
    "Handover",
    "Tracked",
    "TrackingMetrics",
    "estimates_of",
    "figure_rows",
    "lean_tracked",
    "let_go",
    "metrics_json",
    "metrics_of",
    "reference_of",
    "shift_to_hedgehog",
    "smoothing_summary",
    "track",
    "track_recording",
    "tracking_metrics",
    "trusted_fixes",
]

FloatArray = NDArray[np.float64]

ODOMETRY_KEY: Final = "odometry"
IPS_KEY: Final = "ips"
MULTILATERATION_KEY: Final = "multilateration"
SMOOTHED_KEY: Final = "smoothed"
GROUND_TRUTH_KEY: Final = "ground_truth"
SEED003_KEY: Final = "seed003"
"""Seed 003's dead-wheel + IMU + magnetometer estimate (robots with dead wheels, e.g. omni-x)."""
ESTIMATES: Final[tuple[str, ...]] = (
    ODOMETRY_KEY,
    SEED003_KEY,
    IPS_KEY,
    MULTILATERATION_KEY,
    SMOOTHED_KEY,
    GROUND_TRUTH_KEY,
)
"""Names of the estimates :func:`track_recording` knows, in output order."""
METRIC_KEYS: Final[tuple[str, ...]] = ("rmse_m", "rmse_x_m", "rmse_y_m", "max_m", "final_m")
"""The keys of :meth:`TrackingMetrics.as_dict` (and of each entry of :func:`metrics_json`)."""

_FIX_UNAVAILABLE = 0x01
_CHI2_2DOF_99: Final = 9.2103
"""χ²(2) quantile 0.99: a degraded fix farther than this from its trusted neighbours is left out."""
_NEIGHBOURS_S: Final = 0.5


@dataclass(frozen=True)
class TrackingMetrics:
    """Position errors of an estimate against its reference (metres; docs/DESIGN-NOTES.md).

    Attributes:
        rmse_m: RMSE of the position (Euclidean; evo's APE translation RMSE).
        rmse_x_m: RMSE of x in the reference frame.
        rmse_y_m: RMSE of y in the reference frame.
        max_m: largest position error.
        final_m: position error at the last associated sample.
        n: number of associated samples.
    """

    rmse_m: float
    rmse_x_m: float
    rmse_y_m: float
    max_m: float
    final_m: float
    n: int

    @property
    def rmse_per_axis_m(self) -> float:
        """sqrt((rmse_x² + rmse_y²) / 2): the "position" convention of seed 000 Table 4."""
        return float(np.sqrt(0.5 * (self.rmse_x_m**2 + self.rmse_y_m**2)))

    def as_dict(self) -> dict[str, float]:
        """``rmse_m, rmse_x_m, rmse_y_m, max_m, final_m`` as plain floats."""
        return {key: float(getattr(self, key)) for key in METRIC_KEYS}


def tracking_metrics(estimate_xy_m: ArrayLike, reference_xy_m: ArrayLike) -> TrackingMetrics:
    """The measures of paired positions, both (M, 2) in the same frame.

    Raises:
        GeometryError: shapes differ, there is no pair, or a value is not finite.
    """
    est, ref = paired_xy(estimate_xy_m, reference_xy_m, "tracking_metrics")
    err = est - ref
    if not np.all(np.isfinite(err)):
        raise GeometryError("metrics need finite positions")
    dist = np.hypot(err[:, 0], err[:, 1])
    return TrackingMetrics(
        rmse_m=float(np.sqrt(np.mean(dist**2))),
        rmse_x_m=float(np.sqrt(np.mean(err[:, 0] ** 2))),
        rmse_y_m=float(np.sqrt(np.mean(err[:, 1] ** 2))),
        max_m=float(dist.max()),
        final_m=float(dist[-1]),
        n=int(est.shape[0]),
    )


@dataclass(frozen=True, eq=False)
class Tracked:
    """One estimate evaluated against the reference.

    Attributes:
        association: estimate samples paired with the interpolated reference.
        alignment: the estimate carried into the reference frame.
        metrics: the error measures of the aligned pairs.
        smoothing: for the ``smoothed`` estimate, what the smoother found (latency, odometry
            corrections, per-pose covariances); None for the others.
        own_sigma_rms_m: :attr:`sigma_rms_m` over every sample, kept by :func:`lean_tracked`;
            None: computed from the association.
    """

    association: Association
    alignment: Alignment
    metrics: TrackingMetrics
    smoothing: SmoothedTrack | None = None
    own_sigma_rms_m: float | None = None

    @property
    def sigma_rms_m(self) -> float | None:
        """sqrt(mean(σ_x² + σ_y²)) of the estimate's own 1σ over the associated samples, or None."""
        if self.own_sigma_rms_m is not None:
            return self.own_sigma_rms_m
        cov = self.association.estimate_covariance_xy_m2
        if cov is None:
            return None
        return float(np.sqrt(np.mean(cov[:, 0, 0] + cov[:, 1, 1])))

    @property
    def errors_m(self) -> FloatArray:
        """(M,) position error of every associated sample."""
        d = self.alignment.xy_m - self.association.reference_xy_m
        out: FloatArray = np.hypot(d[:, 0], d[:, 1])
        return out

    @property
    def covariance_xy_m2(self) -> FloatArray | None:
        """(M, 2, 2) covariances of the estimate turned into the reference frame (R Σ Rᵀ), or None."""
        cov = self.association.estimate_covariance_xy_m2
        if cov is None:
            return None
        r = self.alignment.transform.rotation_matrix
        out: FloatArray = r @ cov @ r.T
        return out


def track(
    estimate: Trajectory,
    reference: Trajectory,
    *,
    align_mode: AlignMode,
    max_gap_s: float | None = None,
) -> Tracked:
    """Associate (interpolating the reference), align, measure.

    Raises:
        GeometryError: nothing to associate, or the alignment is undetermined.
    """
    association = associate(estimate, reference, max_gap_s=max_gap_s)
    alignment = align(association, align_mode)
    return Tracked(
        association, alignment, tracking_metrics(alignment.xy_m, association.reference_xy_m)
    )


FIGURE_ROWS: Final = 20_000
"""Samples of an estimate kept for the figures on a long run (:func:`lean_tracked`)."""
_FIGURE_BINS: Final = 1000


def figure_rows(series: Sequence[FloatArray], max_rows: int | None = None) -> NDArray[np.intp]:
    """The rows of equally long series a figure draws the same way, in order.

    Every row when there are at most ``max_rows`` (default :data:`FIGURE_ROWS`); else every
    k-th row, the last, and each series' lowest and highest in each of 1000 bins.
    """
    max_rows = FIGURE_ROWS if max_rows is None else max_rows
    n = int(series[0].shape[0]) if series else 0
    if n <= max_rows:
        return np.arange(n, dtype=np.intp)
    picks = [np.arange(0, n, -(-n // max_rows), dtype=np.intp), np.array([n - 1], dtype=np.intp)]
    size = -(-n // _FIGURE_BINS)
    bins = -(-n // size)
    first = np.arange(bins, dtype=np.intp) * size
    for values in series:
        v = np.asarray(values, dtype=np.float64)
        if not np.all(np.isfinite(v)):
            continue
        padded = np.concatenate([v, np.full(bins * size - n, v[-1])]).reshape(bins, size)
        picks.append(first + np.argmin(padded, axis=1))
        picks.append(first + np.argmax(padded, axis=1))
    out: NDArray[np.intp] = np.unique(np.minimum(np.concatenate(picks), n - 1))
    return out


def lean_tracked(tracked: Tracked, max_rows: int | None = None) -> Tracked:
    """``tracked`` reduced to the rows the figures draw (:func:`figure_rows`); measures and the
    own 1σ unchanged (computed over every sample first)."""
    max_rows = FIGURE_ROWS if max_rows is None else max_rows
    asc, al = tracked.association, tracked.alignment
    if len(asc) <= max_rows:
        return tracked
    rows = figure_rows(
        (
            al.xy_m[:, 0],
            al.xy_m[:, 1],
            asc.reference_xy_m[:, 0],
            asc.reference_xy_m[:, 1],
        ),
        max_rows,
    )

    def cut(values: FloatArray | None) -> FloatArray | None:
        return None if values is None else np.ascontiguousarray(values[rows])

    sigma = tracked.sigma_rms_m
    association = Association(
        t_s=asc.t_s[rows],
        index=asc.index[rows],
        estimate_xy_m=asc.estimate_xy_m[rows],
        reference_xy_m=asc.reference_xy_m[rows],
        estimate_yaw_rad=cut(asc.estimate_yaw_rad),
        reference_yaw_rad=cut(asc.reference_yaw_rad),
        estimate_covariance_xy_m2=cut(asc.estimate_covariance_xy_m2),
    )
    alignment = replace(al, xy_m=al.xy_m[rows], yaw_rad=cut(al.yaw_rad))
    smoothing = tracked.smoothing
    if smoothing is not None:  # the samples kept (index: the smoothed track's rows)
        kept = asc.index[rows]
        smoothing = replace(
            smoothing,
            t_s=smoothing.t_s[kept],
            poses=smoothing.poses[kept],
            covariance=smoothing.covariance[kept],
        )
    return Tracked(association, alignment, tracked.metrics, smoothing, sigma)


_TOPICS_OF: Final[dict[str, tuple[str, ...]]] = {
    ODOMETRY_KEY: (ODOM,),
    IPS_KEY: (HEDGE_POS_ANG,),
    GROUND_TRUTH_KEY: (GROUND_TRUTH,),
}
"""The tables an estimate is the last to read, in the order of :data:`ESTIMATES`."""


def let_go(recording: Recording, *names: str) -> Recording:
    """The recording without the topics ``names``, its start kept (a one-row
    :data:`~omnical.recording.topics.START` table stands in when needed)."""
    if not any(n in recording.tables for n in names):
        return recording
    start = recording.start_ns
    kept = recording.without(*names)
    if not any(len(t) and int(t.t_ns[0]) == start for t in kept.tables.values()):
        kept = kept.with_table(START, Table(np.array([start], dtype=np.int64), {}))
    return kept


def shift_to_hedgehog(reference: Trajectory, hedge_offset_m: ArrayLike) -> Trajectory:
    """The reference moved from ``base_link`` to the hedgehog: p + R(yaw) (offset_x, offset_y).

    Raises:
        GeometryError: the reference has no headings.
    """
    if reference.yaw_rad is None:
        raise GeometryError("moving the reference to the hedgehog needs its headings")
    off = np.asarray(hedge_offset_m, dtype=np.float64).reshape(-1)[:2]
    xy = transform_points(np.column_stack([reference.xy_m, reference.yaw_rad]), off)
    return Trajectory(reference.t_s, xy, reference.yaw_rad, reference.frame)


def reference_of(
    recording: Recording, reference: Trajectory | tuple[ArrayLike, ArrayLike] | None = None
) -> Trajectory:
    """The reference trajectory: the one given, else the recording's ``/ground_truth``.

    Args:
        recording: the run (its first message is the time origin).
        reference: a :class:`Trajectory`, or ``(t_s, xy)`` with t_s (N,) seconds from the
            recording's first message and xy (N, 2) positions or (N, 3) poses x, y, yaw.

    Raises:
        RecordingError: no reference given and the recording has no ``/ground_truth``.
        GeometryError: the reference arrays are malformed.
    """
    if isinstance(reference, Trajectory):
        return reference
    if reference is None:
        if not recording.has(GROUND_TRUTH):
            raise RecordingError(
                "no reference trajectory given and the recording has no /ground_truth"
            )
        gt = recording.topic(GROUND_TRUTH)
        t0 = recording.start_ns
        return Trajectory(gt.t_s(t0), np.column_stack([gt["x_m"], gt["y_m"]]), gt["yaw_rad"], "map")
    t_s, values = reference
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise GeometryError(f"reference positions must be (N, 2) or (N, 3), got {arr.shape}")
    yaw = arr[:, 2] if arr.shape[1] == 3 else None
    return Trajectory(np.asarray(t_s, dtype=np.float64), arr[:, :2], yaw, "reference")


def _most_frequent(addresses: NDArray[np.int64]) -> int:
    values, counts = np.unique(addresses, return_counts=True)
    return int(values[int(np.argmax(counts))])


def trusted_fixes(fixes: Fixes) -> NDArray[np.bool_]:
    """Mask of the fixes an evaluation can trust.

    Every fix with status ok; a degraded fix only when its covariance agrees with its trusted
    neighbours: its squared Mahalanobis distance (under its own covariance plus theirs) from
    the median of the ok fixes within ±0.5 s is below the χ²(2) 99 % quantile
    (docs/DESIGN-NOTES.md). Positions must be finite.
    """
    p = fixes.positions_map_m
    finite = np.isfinite(p[:, 0]) & np.isfinite(p[:, 1])
    finite &= np.all(np.isfinite(fixes.covariance_xy_m2), axis=(1, 2))
    ok = finite & (fixes.status == FixStatus.OK)
    degraded = np.flatnonzero(finite & (fixes.status == FixStatus.DEGRADED))
    trusted: NDArray[np.bool_] = ok.copy()
    if degraded.size == 0 or fixes.t_ns is None or not np.any(ok):
        return trusted
    t = fixes.t_ns.astype(np.float64) / 1e9
    ok_idx = np.flatnonzero(ok)
    order = ok_idx[np.argsort(t[ok_idx], kind="stable")]
    t_ok = t[order]
    lo = np.searchsorted(t_ok, t[degraded] - _NEIGHBOURS_S, side="left")
    hi = np.searchsorted(t_ok, t[degraded] + _NEIGHBOURS_S, side="right")
    for i, a, b in zip(degraded.tolist(), lo.tolist(), hi.tolist(), strict=True):
        if b - a < 3:
            continue
        near = order[a:b]
        centre = np.median(p[near, :2], axis=0)
        cov = fixes.covariance_xy_m2[i] + np.median(fixes.covariance_xy_m2[near], axis=0) / (b - a)
        d2 = mahalanobis_sq(cov[None], (p[i, :2] - centre)[None])
        trusted[i] = bool(d2[0] <= _CHI2_2DOF_99)
    return trusted


def _fixes_trajectory(fixes: Fixes, t0_ns: int) -> Trajectory | None:
    """The trusted fixes (:func:`trusted_fixes`) of the most frequent hedgehog, time-sorted."""
    if len(fixes) == 0:
        return None
    if fixes.t_ns is None:
        raise GeometryError("the multilateration fixes carry no times (t_ns)")
    p = fixes.positions_map_m
    usable = trusted_fixes(fixes)
    if fixes.address_hedge is not None and np.any(usable):
        usable &= fixes.address_hedge == _most_frequent(fixes.address_hedge[usable])
    if not np.any(usable):
        return None
    t = (fixes.t_ns[usable] - np.int64(t0_ns)).astype(np.float64) / 1e9
    order = np.argsort(t, kind="stable")
    cov = fixes.covariance_xy_m2[usable][order]
    return Trajectory(t[order], p[usable][order, :2], None, "map", cov)


def _smoothed_trajectory(smoothing: SmoothedTrack) -> Trajectory:
    return Trajectory(
        smoothing.t_s,
        smoothing.poses[:, :2],
        smoothing.poses[:, 2],
        "map",
        smoothing.covariance[:, :2, :2],
    )


def _smoothed(
    recording: Recording,
    fixed: Trajectory | None,
    *,
    hedge_offset_m: ArrayLike | None,
    params: SmootherParams | None,
) -> SmoothedTrack | None:
    """The batch-smoothed trajectory of a run: ``/odom``, the trusted fixes' trajectory
    (:func:`_fixes_trajectory`) and the ``/imu`` yaw rate; None without ``/odom`` or with fewer
    than 3 trusted fixes (or when the smoother fails on them)."""
    if fixed is None or len(fixed) < 3 or fixed.covariance_xy_m2 is None:
        return None
    inputs = _smoother_inputs(recording)
    if inputs is None:
        return None
    odom, gyro = inputs
    return _smoothed_from(
        odom,
        gyro,
        fixed.t_s,
        fixed.xy_m,
        fixed.covariance_xy_m2,
        hedge_offset_m=hedge_offset_m,
        params=params,
    )


def _smoother_odometry(recording: Recording) -> FloatArray:
    """The smoother's odometry (N, 4) t (from the recording's start), x, y, yaw."""
    od = recording.topic(ODOM)
    out: FloatArray = np.column_stack(
        [od.t_s(recording.start_ns), od["x_m"], od["y_m"], od["yaw_rad"]]
    )
    return out


_READ_AGAIN: Final = (GROUND_TRUTH, HEDGE_POS_ANG)
"""The full-rate tables let go through the smoothing when they can be read again (``reread``)."""


def _smoother_inputs(recording: Recording) -> tuple[FloatArray, FloatArray | None] | None:
    """The smoother's odometry (:func:`_smoother_odometry`) and gyro (G, 2) t, yaw rate (or
    None) of a recording; None without two odometry samples."""
    if not recording.has(ODOM) or len(recording.topic(ODOM)) < 2:
        return None
    gyro = None
    if recording.has(IMU) and len(recording.topic(IMU)) >= 2:
        imu = recording.topic(IMU)
        gyro = np.column_stack([imu.t_s(recording.start_ns), imu["gyro_z_radps"]])
    return _smoother_odometry(recording), gyro


def _smoothed_from(
    odom: FloatArray | Callable[[], FloatArray],
    gyro: FloatArray | Handover[FloatArray] | None,
    fix_t: FloatArray | Handover[FloatArray],
    fix_xy: FloatArray | Handover[FloatArray],
    fix_cov: FloatArray | Handover[FloatArray],
    *,
    hedge_offset_m: ArrayLike | None,
    params: SmootherParams | None,
) -> SmoothedTrack | None:
    """:func:`smooth_track` with the robot's lever arm (None: it failed: too few fixes)."""
    settings = params or SmootherParams()
    if hedge_offset_m is not None:
        off = np.asarray(hedge_offset_m, dtype=np.float64).reshape(-1)[:2]
        settings = replace(settings, hedge_offset_m=(float(off[0]), float(off[1])))
    try:
        return smooth_track(settings, odom, fix_t, fix_xy, fix_cov, gyro=gyro)
    except GeometryError:
        return None


def estimates_of(
    recording: Recording,
    *,
    fixes: Fixes | None = None,
    names: Collection[str] = ESTIMATES,
    hedge_offset_m: ArrayLike | None = None,
    smoothing: SmoothedTrack | None = None,
    dead_wheels: Sequence[DeadWheel] = (),
) -> dict[str, Trajectory]:
    """The estimated trajectories a recording holds, by name (see :data:`ESTIMATES`).

    Times in seconds from the recording's first message; an estimate without a usable sample
    is left out; with several hedgehogs, the one with most valid positions is taken.

    Args:
        recording: the run.
        fixes: omnical's multilateration of the run; None: computed with
            :func:`omnical.ips.from_recording.locate` when the recording has raw distances.
        names: the estimates wanted (a subset of :data:`ESTIMATES`).
        hedge_offset_m: the hedgehog's lever arm in base_link, for the smoother.
        smoothing: the smoothed track already computed; None: computed when wanted.
        dead_wheels: the robot's dead wheels: with them and ``/dead_wheels``, ``/imu`` and
            ``/imu/mag``, seed 003's estimate (odometry frame) is evaluated too.
    """
    need_fixes = MULTILATERATION_KEY in names or (SMOOTHED_KEY in names and smoothing is None)
    if need_fixes and fixes is None and recording.has(BEACON_RAW_DISTANCE):
        fixes, _ = locate(recording)
    fixed = None
    if need_fixes and fixes is not None:
        fixed = _fixes_trajectory(fixes, recording.start_ns)
    return _estimates(
        recording,
        fixed,
        names=names,
        hedge_offset_m=hedge_offset_m,
        smoothing=smoothing,
        dead_wheels=dead_wheels,
    )


def _estimates(
    recording: Recording,
    fixed: Trajectory | None,
    *,
    names: Collection[str],
    hedge_offset_m: ArrayLike | None,
    smoothing: SmoothedTrack | None,
    dead_wheels: Sequence[DeadWheel],
) -> dict[str, Trajectory]:
    """:func:`estimates_of` from the trusted fixes' trajectory (computed once)."""
    t0 = recording.start_ns
    out: dict[str, Trajectory] = {}
    if ODOMETRY_KEY in names and recording.has(ODOM):
        odom = recording.topic(ODOM)
        xy = np.column_stack([odom["x_m"], odom["y_m"]])
        out[ODOMETRY_KEY] = Trajectory(odom.t_s(t0), xy, odom["yaw_rad"], "odom")
    if SEED003_KEY in names and dead_wheels and recording.has(DEAD_WHEELS):
        samples = seed003_samples_of(recording, dead_wheels)
        track = seed003_track(samples, dead_wheels)
        out[SEED003_KEY] = Trajectory(track[:, 0], track[:, 1:3], track[:, 3], "odom")
    if IPS_KEY in names and recording.has(HEDGE_POS_ANG):
        pos = recording.topic(HEDGE_POS_ANG)
        valid = ((pos["flags"] & _FIX_UNAVAILABLE) == 0) & np.isfinite(pos["x_m"])
        valid &= np.isfinite(pos["y_m"])
        if np.any(valid):
            pos = pos.take(valid)
            pos = pos.take(pos["address"] == _most_frequent(pos["address"]))
            xy = np.column_stack([pos["x_m"], pos["y_m"]])
            out[IPS_KEY] = Trajectory(pos.t_s(t0), xy, None, "map")
    if MULTILATERATION_KEY in names and fixed is not None:
        out[MULTILATERATION_KEY] = fixed
    if SMOOTHED_KEY in names:
        if smoothing is None:
            smoothing = _smoothed(recording, fixed, hedge_offset_m=hedge_offset_m, params=None)
        if smoothing is not None:
            out[SMOOTHED_KEY] = _smoothed_trajectory(smoothing)
    if GROUND_TRUTH_KEY in names and recording.has(GROUND_TRUTH):
        gt = recording.topic(GROUND_TRUTH)
        xy = np.column_stack([gt["x_m"], gt["y_m"]])
        out[GROUND_TRUTH_KEY] = Trajectory(gt.t_s(t0), xy, gt["yaw_rad"], "map")
    return out


def track_recording(
    recording: Recording | Handover[Recording],
    reference: Trajectory | tuple[ArrayLike, ArrayLike] | None = None,
    *,
    align: AlignMode = DEFAULT_ALIGN_IPS,
    odometry_align: AlignMode = DEFAULT_ALIGN_ODOMETRY,
    fixes: Fixes | Handover[Fixes] | None = None,
    max_gap_s: float | None = 1.0,
    hedge_offset_m: ArrayLike | None = None,
    smooth: bool = True,
    smoother: SmootherParams | None = None,
    dead_wheels: Sequence[DeadWheel] = (),
    ground_truth_alone: bool = False,
    lean: bool = False,
    reread: Callable[[tuple[str, ...]], Recording] | None = None,
) -> dict[str, Tracked]:
    """Evaluate odometry, vendor IPS, multilateration, the smoothed track and ground truth.

    Each estimate is associated with the reference (:func:`track`), aligned and measured in
    the reference frame; :func:`metrics_of` reduces the result to the measures.

    Args:
        recording: the run.
        reference: ``(t_s, xy)`` (seconds from the recording's first message; (N, 2) positions
            or (N, 3) poses) or a :class:`Trajectory`; None: the recording's ``/ground_truth``.
        align: alignment of the map-frame estimates (``se2`` by default; ``none`` when the
            reference is in ``map`` and the IPS's offset should count as error).
        odometry_align: alignment of the odometry (``origin`` by default, seed 000 §4.2).
        fixes: omnical's multilateration (or a :class:`Handover` of it); None: computed from
            ``/beacon_raw_distance``.
        max_gap_s: largest reference gap interpolated across (None: no limit).
        hedge_offset_m: (x, y[, z]) of the hedgehog in ``base_link``: the smoother models the
            lever arm, and the IPS estimates are compared with the reference moved to the
            hedgehog when it has headings.
        smooth: compute the ``smoothed`` estimate (needs ``/odom`` and trusted fixes).
        smoother: the smoother's noise model (default :class:`SmootherParams`).
        dead_wheels: the robot's dead wheels (seed 003's estimate, :func:`estimates_of`).
        ground_truth_alone: ``/ground_truth`` is the reference: evaluate it only when there is
            no other estimate.
        lean: each result reduced to what the figures draw (:func:`lean_tracked`), same
            measures. Tables are let go of once unneeded; hand the recording over
            (:class:`Handover`) for that to free them.
        reread: with ``lean``, a reader of the named topics' tables again: the truth and the
            vendor IPS are then let go through the smoothing and read again after it.

    Returns:
        Estimate name → evaluation, in the order of :data:`ESTIMATES`; estimates the recording
        lacks are left out. The ``smoothed`` entry carries the smoother's result
        (:attr:`Tracked.smoothing`).

    Raises:
        RecordingError: no reference given and no ``/ground_truth``, or no estimate at all.
        GeometryError: an estimate has no sample inside the reference, or cannot be aligned.
    """
    hand = recording if isinstance(recording, Handover) else Handover(recording)
    del recording
    return _track(
        hand,
        reference,
        fixes,
        modes=(align, odometry_align),
        max_gap_s=max_gap_s,
        hedge_offset_m=hedge_offset_m,
        smoother=(smoother or SmootherParams()) if smooth else None,
        dead_wheels=dead_wheels,
        ground_truth_alone=ground_truth_alone,
        reduce=lean_tracked if lean else lambda tracked: tracked,
        reread=reread if lean else None,
    )


_NOTHING: Final = (
    "nothing to evaluate: the recording has no /odom, no valid /hedge_pos_ang, no usable "
    "multilateration fix and no /ground_truth"
)


def _tracked(
    name: str,
    estimate: Trajectory,
    target: Trajectory,
    mode: AlignMode,
    max_gap_s: float | None,
    smoothing: SmoothedTrack | None,
) -> Tracked:
    """:func:`track` of one estimate, its name in the message of an error."""
    try:
        tracked = track(estimate, target, align_mode=mode, max_gap_s=max_gap_s)
    except GeometryError as err:
        raise GeometryError(f"{name} against the reference: {err}") from None
    if name == SMOOTHED_KEY:
        tracked = replace(tracked, smoothing=smoothing)
    return tracked


def _track(
    hand: Handover[Recording],
    reference: Trajectory | tuple[ArrayLike, ArrayLike] | None,
    fixes: Fixes | Handover[Fixes] | None,
    *,
    modes: tuple[AlignMode, AlignMode],
    max_gap_s: float | None,
    hedge_offset_m: ArrayLike | None,
    smoother: SmootherParams | None,
    dead_wheels: Sequence[DeadWheel],
    ground_truth_alone: bool,
    reduce: Callable[[Tracked], Tracked],
    reread: Callable[[tuple[str, ...]], Recording] | None = None,
) -> dict[str, Tracked]:
    """:func:`track_recording` (``smoother`` None: no smoothing; ``reduce`` each result).

    The order keeps the least held at the smoothing (docs/DESIGN-NOTES.md).
    """
    recording = hand.take()
    fixes = None if fixes is None else taken(fixes)
    align_mode, odometry_mode = modes
    if reference is None:
        reference_of(recording)  # no /ground_truth: the error now, before the work
    away: list[str] = []  # tables let go through the smoothing, read again when needed

    def back(*names: str) -> None:
        """The tables ``names`` let go of (``away``) read again."""
        nonlocal recording
        wanted = tuple(n for n in away if n in names)
        if wanted and reread is not None:
            tables = {**recording.tables, **reread(wanted).tables}  # read again, put back
            recording = Recording(tables, recording.skipped_topics, recording.notes)
            away[:] = [n for n in away if n not in wanted]

    def hedged(ref: Trajectory) -> Trajectory:
        """The reference moved to the hedgehog (the IPS estimates')."""
        if hedge_offset_m is not None and ref.yaw_rad is not None:
            return shift_to_hedgehog(ref, hedge_offset_m)
        return ref

    if fixes is None and recording.has(BEACON_RAW_DISTANCE):
        fixes, _ = locate(recording)
    fixed = None if fixes is None else _fixes_trajectory(fixes, recording.start_ns)
    del fixes
    recording = let_go(recording, BEACON_RAW_DISTANCE, BEACONS_POS_A)
    results: dict[str, Tracked] = {}
    if fixed is not None:
        estimate = fixed
        ref_hedge = hedged(reference_of(recording, reference))
        results[MULTILATERATION_KEY] = reduce(
            _tracked(MULTILATERATION_KEY, estimate, ref_hedge, align_mode, max_gap_s, None)
        )
        del ref_hedge, estimate
    smoothing = None
    inputs = None if smoother is None else _smoother_inputs(recording)
    if not dead_wheels:  # else seed 003's estimate reads it
        recording = let_go(recording, IMU)
    if inputs is not None and fixed is not None and len(fixed) >= 3:
        gyro = None if inputs[1] is None else Handover(inputs[1])
        del inputs
        fix_t, fix_xy, fix_cov = fixed.t_s, fixed.xy_m, fixed.covariance_xy_m2
        fixed = None
        if fix_cov is not None:
            handed = (Handover(fix_t), Handover(fix_xy), Handover(fix_cov))
            del fix_t, fix_xy, fix_cov
            calls = 0

            def odometry() -> FloatArray:
                """The smoother's odometry; once first asked for, :data:`_READ_AGAIN` is let go."""
                nonlocal recording, calls
                calls += 1
                out = _smoother_odometry(recording)
                if calls == 1 and reread is not None:  # the others, once set up
                    away.extend(n for n in _READ_AGAIN if recording.has(n))
                    recording = let_go(recording, *away)
                return out

            smoothing = _smoothed_from(
                odometry,
                gyro,
                *handed,
                hedge_offset_m=hedge_offset_m,
                params=smoother,
            )
            del handed
        del gyro
    inputs = fixed = None
    if reference is None:
        back(GROUND_TRUTH)
    ref = reference_of(recording, reference)
    if ground_truth_alone and results:  # the truth is not evaluated: the reference has it
        recording = let_go(recording, GROUND_TRUTH)
        away[:] = [n for n in away if n != GROUND_TRUTH]
    # the smoothed track first: reduced to its lean copy, its full rate is not held meanwhile
    names = [SMOOTHED_KEY] if smoothing is not None else []
    names += [n for n in ESTIMATES if n not in (MULTILATERATION_KEY, SMOOTHED_KEY)]
    for name in names:
        if name == GROUND_TRUTH_KEY and ground_truth_alone and results:
            continue
        back(*_TOPICS_OF.get(name, ()))
        one = _estimates(
            recording,
            None,
            names=(name,),
            hedge_offset_m=None,
            smoothing=smoothing,
            dead_wheels=dead_wheels,
        ).get(name)
        if one is not None:
            mode = odometry_mode if name in (ODOMETRY_KEY, SEED003_KEY) else align_mode
            target = hedged(ref) if name == IPS_KEY else ref
            results[name] = reduce(_tracked(name, one, target, mode, max_gap_s, smoothing))
            del one, target
        if name == SMOOTHED_KEY:
            smoothing = None  # its lean copy is in the result
        recording = let_go(recording, *_TOPICS_OF.get(name, ()))
    if not results:
        raise RecordingError(_NOTHING)
    return {name: results[name] for name in ESTIMATES if name in results}


def metrics_of(tracked: Mapping[str, Tracked]) -> dict[str, TrackingMetrics]:
    """The measures of each evaluated estimate (the output of :func:`track_recording`)."""
    return {name: result.metrics for name, result in tracked.items()}


def smoothing_summary(tracked: Tracked) -> dict[str, float]:
    """What the ``smoothed`` estimate's report states besides its measures (empty for others).

    The own 1σ RMS, the latency, fix counts and residual, iterations, each shared parameter
    with its ``_sigma``, the self-check as ``check_*`` and ``quote`` (1: the estimate to quote);
    flags as 1.0 or 0.0.
    """
    sm = tracked.smoothing
    if sm is None:
        return {}
    out: dict[str, float] = {
        "sigma_rms_m": float(tracked.sigma_rms_m or 0.0),
        "latency_s": sm.latency_s,
        "latency_sigma_s": sm.latency_sigma_s,
        "fixes_used": float(sm.fixes_used),
        "fixes_downweighted": float(sm.fixes_downweighted),
        "fix_residual_rms_m": sm.fix_residual_rms_m,
        "iterations": float(sm.iterations),
        "converged": 1.0 if sm.converged else 0.0,
    }
    for name, (value, sigma) in sm.shared_dict().items():
        if name != "latency_s":
            out[name] = value
            out[f"{name}_sigma"] = sigma
    check = sm.check
    if check is not None:
        out["check_fix_chi2_per_dof"] = check.fix_chi2_per_dof
        out["check_fixes_in_band_95"] = check.fixes_in_band_95
        out["check_odometry_noise_scale"] = check.odometry_noise_scale
        out["check_fix_noise_scale"] = check.fix_noise_scale
        out["check_passed"] = 1.0 if check.passed else 0.0
    out["quote"] = 1.0 if sm.trustworthy else 0.0
    return out


def metrics_json(
    results: Mapping[str, TrackingMetrics],
    details: Mapping[str, Mapping[str, float]] | None = None,
) -> str:
    """``{"odometry": {"rmse_m": …, "rmse_x_m": …, "rmse_y_m": …, "max_m": …, "final_m": …}, …}``.

    Keys in the order of ``results``, metres at full precision, a non-finite value as ``null``
    (strict JSON); ``details`` adds keys after the measures of the estimates it names.
    """
    extra = details or {}
    clean = {
        name: {
            k: v if math.isfinite(v) else None
            for k, v in {**m.as_dict(), **extra.get(name, {})}.items()
        }
        for name, m in results.items()
    }
    return json.dumps(clean, indent=2, allow_nan=False) + "\n"
