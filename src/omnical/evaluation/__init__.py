"""Evaluation: association, alignment and error measures of trajectories.

- :mod:`~omnical.evaluation.association`: the reference interpolated at the estimate's times.
- :mod:`~omnical.evaluation.alignment`: none / origin / least-squares SE(2) alignment.
- :mod:`~omnical.evaluation.metrics`: seed 000 Table 4 measures, on arrays or a recording.
- :mod:`~omnical.evaluation.odometry`: wheel odometry against the twin's ground truth.
"""

from omnical.evaluation.alignment import (
    ALIGN_MODES,
    DEFAULT_ALIGN_IPS,
    DEFAULT_ALIGN_ODOMETRY,
    Alignment,
    AlignMode,
    Transform2D,
    align,
    align_positions,
    fit_se2,
    origin_transform,
)
from omnical.evaluation.association import Association, Trajectory, associate, write_tum_pair
from omnical.evaluation.metrics import (
    ESTIMATES,
    METRIC_KEYS,
    Tracked,
    TrackingMetrics,
    estimates_of,
    evaluate_recording,
    metrics_json,
    reference_of,
    shift_to_hedgehog,
    track,
    track_recording,
    tracking_metrics,
)
from omnical.evaluation.odometry import OdometryErrors, odometry_vs_ground_truth

__all__ = [
    "ALIGN_MODES",
    "DEFAULT_ALIGN_IPS",
    "DEFAULT_ALIGN_ODOMETRY",
    "ESTIMATES",
    "METRIC_KEYS",
    "AlignMode",
    "Alignment",
    "Association",
    "OdometryErrors",
    "Tracked",
    "TrackingMetrics",
    "Trajectory",
    "Transform2D",
    "align",
    "align_positions",
    "associate",
    "estimates_of",
    "evaluate_recording",
    "fit_se2",
    "metrics_json",
    "odometry_vs_ground_truth",
    "origin_transform",
    "reference_of",
    "shift_to_hedgehog",
    "track",
    "track_recording",
    "tracking_metrics",
    "write_tum_pair",
]
