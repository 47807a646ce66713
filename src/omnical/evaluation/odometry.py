"""Wheel odometry against ground truth, on a recording of the twin.

Ground truth interpolated at the odometry times, the odometry origin-aligned into ``map``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from omnical.errors import GeometryError
from omnical.estimation.se2 import wrap_angle
from omnical.evaluation.metrics import GROUND_TRUTH_KEY, ODOMETRY_KEY, estimates_of, track
from omnical.recording.recording import Recording
from omnical.recording.topics import GROUND_TRUTH, ODOM

__all__ = ["OdometryErrors", "odometry_vs_ground_truth"]


@dataclass(frozen=True)
class OdometryErrors:
    """How far the wheel odometry drifted from the truth.

    Attributes:
        distance_odom_m: path length by odometry.
        distance_true_m: path length by ground truth.
        rmse_m: root-mean-square position error over the run.
        max_m: largest position error.
        final_m: position error at the end.
        final_heading_rad: heading error at the end (odometry − truth), wrapped to [−π, π].
        errors_m: (N,) position error at every associated odometry sample.
    """

    distance_odom_m: float
    distance_true_m: float
    rmse_m: float
    max_m: float
    final_m: float
    final_heading_rad: float
    errors_m: NDArray[np.float64]


def _path_length(xy: NDArray[np.float64]) -> float:
    return float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))


def odometry_vs_ground_truth(recording: Recording) -> OdometryErrors:
    """Compare ``/odom`` with ``/ground_truth`` (origin-aligned, interpolated at odometry times).

    Raises:
        RecordingError: the recording lacks ``/odom`` or ``/ground_truth``.
        GeometryError: no odometry sample lies inside the ground truth's time span.
    """
    recording.topic(ODOM)
    recording.topic(GROUND_TRUTH)
    trajectories = estimates_of(recording, names=(ODOMETRY_KEY, GROUND_TRUTH_KEY))
    odom, truth = trajectories[ODOMETRY_KEY], trajectories[GROUND_TRUTH_KEY]
    tracked = track(odom, truth, align_mode="origin")
    aligned_yaw, truth_yaw = tracked.alignment.yaw_rad, tracked.association.reference_yaw_rad
    if aligned_yaw is None or truth_yaw is None:
        raise GeometryError("odometry and ground truth must both carry headings")
    heading = wrap_angle(float(aligned_yaw[-1] - truth_yaw[-1]))
    m = tracked.metrics
    return OdometryErrors(
        distance_odom_m=_path_length(odom.xy_m),
        distance_true_m=_path_length(truth.xy_m),
        rmse_m=m.rmse_m,
        max_m=m.max_m,
        final_m=m.final_m,
        final_heading_rad=heading,
        errors_m=tracked.errors_m,
    )
