"""Tracking error measures of seed 000 Table 4, and their evaluation on a recording.

Measures (:class:`TrackingMetrics`), over the M associated and aligned pairs with errors
e_i = p̂_i − p_i:

- ``rmse_m`` = sqrt(Σ‖e_i‖² / M), the RMSE of the position — the Euclidean distance, the same
  number as evo's APE translation RMSE;
- ``rmse_x_m`` = sqrt(Σ e_x,i² / M) and ``rmse_y_m`` = sqrt(Σ e_y,i² / M), per axis of the
  reference frame, so rmse_m² = rmse_x_m² + rmse_y_m²;
- ``max_m`` = max ‖e_i‖ (seed 000 §4.2 "maximum deviation", 0.2 m for uncalibrated odometry);
- ``final_m`` = ‖e_M‖, the error at the last associated sample.

Seed 000 Table 4's "position" row is not the Euclidean RMSE: all four of its columns equal
sqrt((rmse_x² + rmse_y²) / 2) to the printed digits (e.g. IPS uncalibrated:
sqrt((0.1518² + 0.0445²) / 2) = 0.1119), i.e. the RMSE over the x and y residuals pooled.
That number is :attr:`TrackingMetrics.rmse_per_axis_m` (= rmse_m / √2); compare it, not
``rmse_m``, with the paper's position row.

The estimates of a recording (:func:`track_recording`): ``odometry`` (``/odom``, frame
``odom``), ``ips`` (the vendor's valid ``/hedge_pos_ang`` fixes, ``map``), ``multilateration``
(omnical's fixes with status ok or degraded, ``map``) and ``ground_truth`` (``/ground_truth``,
``map``, twin only). Alignment defaults: see :mod:`omnical.evaluation.alignment`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import GeometryError, RecordingError
from omnical.estimation.se2 import transform_points
from omnical.evaluation.alignment import (
    DEFAULT_ALIGN_IPS,
    DEFAULT_ALIGN_ODOMETRY,
    Alignment,
    AlignMode,
    align,
)
from omnical.evaluation.association import Association, Trajectory, associate, paired_xy
from omnical.ips.from_recording import locate
from omnical.ips.solve import Fixes, FixStatus
from omnical.recording.recording import Recording
from omnical.recording.topics import BEACON_RAW_DISTANCE, GROUND_TRUTH, HEDGE_POS_ANG, ODOM

__all__ = [
    "ESTIMATES",
    "GROUND_TRUTH_KEY",
    "IPS_KEY",
    "METRIC_KEYS",
    "MULTILATERATION_KEY",
    "ODOMETRY_KEY",
    "Tracked",
    "TrackingMetrics",
    "estimates_of",
    "metrics_json",
    "metrics_of",
    "reference_of",
    "shift_to_hedgehog",
    "track",
    "track_recording",
    "tracking_metrics",
]

FloatArray = NDArray[np.float64]

ODOMETRY_KEY: Final = "odometry"
IPS_KEY: Final = "ips"
MULTILATERATION_KEY: Final = "multilateration"
GROUND_TRUTH_KEY: Final = "ground_truth"
ESTIMATES: Final[tuple[str, ...]] = (ODOMETRY_KEY, IPS_KEY, MULTILATERATION_KEY, GROUND_TRUTH_KEY)
"""Names of the estimates :func:`track_recording` knows, in output order."""
METRIC_KEYS: Final[tuple[str, ...]] = ("rmse_m", "rmse_x_m", "rmse_y_m", "max_m", "final_m")
"""The keys of :meth:`TrackingMetrics.as_dict` (and of each entry of :func:`metrics_json`)."""

_FIX_UNAVAILABLE = 0x01


@dataclass(frozen=True)
class TrackingMetrics:
    """Position errors of an estimate against its reference (metres; see the module docstring).

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
    """

    association: Association
    alignment: Alignment
    metrics: TrackingMetrics

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


def _fixes_trajectory(fixes: Fixes, t0_ns: int) -> Trajectory | None:
    """The usable fixes (ok or degraded, finite) of the most frequent hedgehog, time-sorted."""
    if len(fixes) == 0:
        return None
    if fixes.t_ns is None:
        raise GeometryError("the multilateration fixes carry no times (t_ns)")
    p = fixes.positions_map_m
    usable = (fixes.status <= FixStatus.DEGRADED) & np.isfinite(p[:, 0]) & np.isfinite(p[:, 1])
    if fixes.address_hedge is not None and np.any(usable):
        usable &= fixes.address_hedge == _most_frequent(fixes.address_hedge[usable])
    if not np.any(usable):
        return None
    t = (fixes.t_ns[usable] - np.int64(t0_ns)).astype(np.float64) / 1e9
    order = np.argsort(t, kind="stable")
    cov = fixes.covariance_xy_m2[usable][order]
    return Trajectory(t[order], p[usable][order, :2], None, "map", cov)


def estimates_of(
    recording: Recording, *, fixes: Fixes | None = None, names: Collection[str] = ESTIMATES
) -> dict[str, Trajectory]:
    """The estimated trajectories a recording holds, by name (see :data:`ESTIMATES`).

    Times are seconds from the recording's first message. An estimate whose topic is missing
    or has no usable sample is left out. With several hedgehogs, the one with most valid
    positions is taken (likewise for the fixes).

    Args:
        recording: the run.
        fixes: omnical's multilateration of the run; None: computed with
            :func:`omnical.ips.from_recording.locate` when the recording has raw distances.
        names: the estimates wanted (a subset of :data:`ESTIMATES`).
    """
    t0 = recording.start_ns
    out: dict[str, Trajectory] = {}
    if ODOMETRY_KEY in names and recording.has(ODOM):
        odom = recording.topic(ODOM)
        xy = np.column_stack([odom["x_m"], odom["y_m"]])
        out[ODOMETRY_KEY] = Trajectory(odom.t_s(t0), xy, odom["yaw_rad"], "odom")
    if IPS_KEY in names and recording.has(HEDGE_POS_ANG):
        pos = recording.topic(HEDGE_POS_ANG)
        valid = ((pos["flags"] & _FIX_UNAVAILABLE) == 0) & np.isfinite(pos["x_m"])
        valid &= np.isfinite(pos["y_m"])
        if np.any(valid):
            pos = pos.take(valid)
            pos = pos.take(pos["address"] == _most_frequent(pos["address"]))
            xy = np.column_stack([pos["x_m"], pos["y_m"]])
            out[IPS_KEY] = Trajectory(pos.t_s(t0), xy, None, "map")
    if MULTILATERATION_KEY not in names:
        fixes = None
    elif fixes is None and recording.has(BEACON_RAW_DISTANCE):
        fixes, _ = locate(recording)
    if fixes is not None:
        fixed = _fixes_trajectory(fixes, t0)
        if fixed is not None:
            out[MULTILATERATION_KEY] = fixed
    if GROUND_TRUTH_KEY in names and recording.has(GROUND_TRUTH):
        gt = recording.topic(GROUND_TRUTH)
        xy = np.column_stack([gt["x_m"], gt["y_m"]])
        out[GROUND_TRUTH_KEY] = Trajectory(gt.t_s(t0), xy, gt["yaw_rad"], "map")
    return out


def track_recording(
    recording: Recording,
    reference: Trajectory | tuple[ArrayLike, ArrayLike] | None = None,
    *,
    align: AlignMode = DEFAULT_ALIGN_IPS,
    odometry_align: AlignMode = DEFAULT_ALIGN_ODOMETRY,
    fixes: Fixes | None = None,
    max_gap_s: float | None = 1.0,
    hedge_offset_m: ArrayLike | None = None,
) -> dict[str, Tracked]:
    """Evaluate odometry, vendor IPS, multilateration and ground truth against the reference.

    Each estimate is associated with the reference by linear interpolation at its own times
    (samples outside the reference, or inside reference gaps longer than ``max_gap_s``,
    dropped), aligned, and measured (:class:`TrackingMetrics`, in the reference frame). The
    result keeps the associations and alignments (for figures); :func:`metrics_of` reduces it
    to the measures.

    Args:
        recording: the run.
        reference: ``(t_s, xy)`` — t_s (N,) seconds from the recording's first message, xy
            (N, 2) positions or (N, 3) poses with yaw — or a :class:`Trajectory`; None: the
            recording's ``/ground_truth`` (twin), with headings.
        align: alignment of the map-frame estimates (ips, multilateration, ground_truth):
            ``se2`` by default (the reference frame is unrelated to the beacon map); ``none``
            when the reference is in ``map`` and the offset of the IPS should count as error.
        odometry_align: alignment of the odometry: ``origin`` by default (seed 000 §4.2:
            odometry starts at the start of the reference).
        fixes: omnical's multilateration; None: computed from ``/beacon_raw_distance``.
        max_gap_s: largest reference gap interpolated across (None: no limit).
        hedge_offset_m: (x, y[, z]) of the hedgehog in ``base_link``. When given and the
            reference has headings, the IPS estimates are compared with the reference moved
            to the hedgehog (the point the IPS measures) instead of the robot centre.

    Returns:
        Estimate name → evaluation, in the order of :data:`ESTIMATES`; estimates the recording
        lacks are left out.

    Raises:
        RecordingError: no reference given and no ``/ground_truth``, or no estimate at all.
        GeometryError: an estimate has no sample inside the reference, or cannot be aligned.
    """
    ref = reference_of(recording, reference)
    ref_hedge = ref
    if hedge_offset_m is not None and ref.yaw_rad is not None:
        ref_hedge = shift_to_hedgehog(ref, hedge_offset_m)
    results: dict[str, Tracked] = {}
    for name, estimate in estimates_of(recording, fixes=fixes).items():
        mode = odometry_align if name == ODOMETRY_KEY else align
        target = ref_hedge if name in (IPS_KEY, MULTILATERATION_KEY) else ref
        try:
            results[name] = track(estimate, target, align_mode=mode, max_gap_s=max_gap_s)
        except GeometryError as err:
            raise GeometryError(f"{name} against the reference: {err}") from None
    if not results:
        msg = (
            "nothing to evaluate: the recording has no /odom, no valid /hedge_pos_ang, no usable "
            "multilateration fix and no /ground_truth"
        )
        raise RecordingError(msg)
    return results


def metrics_of(tracked: Mapping[str, Tracked]) -> dict[str, TrackingMetrics]:
    """The measures of each evaluated estimate (the output of :func:`track_recording`)."""
    return {name: result.metrics for name, result in tracked.items()}


def metrics_json(results: Mapping[str, TrackingMetrics]) -> str:
    """``{"odometry": {"rmse_m": …, "rmse_x_m": …, "rmse_y_m": …, "max_m": …, "final_m": …}, …}``.

    Keys in the order of ``results``; values in metres, full float precision; a value that is
    not finite (an overflowing error) is written as ``null``, so the file stays strict JSON.
    """
    clean = {
        name: {k: v if math.isfinite(v) else None for k, v in m.as_dict().items()}
        for name, m in results.items()
    }
    return json.dumps(clean, indent=2, allow_nan=False) + "\n"
