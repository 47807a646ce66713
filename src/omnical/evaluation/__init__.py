"""Evaluation: association, alignment and error measures of trajectories.

``association`` (the reference at the estimate's times), ``alignment`` (none, origin, SE(2)),
``metrics`` (seed 000 Table 4, on arrays or a recording), ``odometry`` (against ground truth).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
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
    from omnical.evaluation.association import (
        Association,
        Trajectory,
        associate,
        write_tum_pair,
    )
    from omnical.evaluation.metrics import (
        ESTIMATES,
        METRIC_KEYS,
        Tracked,
        TrackingMetrics,
        estimates_of,
        metrics_json,
        reference_of,
        shift_to_hedgehog,
        track,
        track_recording,
        tracking_metrics,
    )
    from omnical.evaluation.odometry import (
        OdometryErrors,
        odometry_vs_ground_truth,
    )

_EXPORTS: dict[str, str] = {
    "ALIGN_MODES": "omnical.evaluation.alignment",
    "AlignMode": "omnical.evaluation.alignment",
    "Alignment": "omnical.evaluation.alignment",
    "Association": "omnical.evaluation.association",
    "DEFAULT_ALIGN_IPS": "omnical.evaluation.alignment",
    "DEFAULT_ALIGN_ODOMETRY": "omnical.evaluation.alignment",
    "ESTIMATES": "omnical.evaluation.metrics",
    "METRIC_KEYS": "omnical.evaluation.metrics",
    "OdometryErrors": "omnical.evaluation.odometry",
    "Tracked": "omnical.evaluation.metrics",
    "TrackingMetrics": "omnical.evaluation.metrics",
    "Trajectory": "omnical.evaluation.association",
    "Transform2D": "omnical.evaluation.alignment",
    "align": "omnical.evaluation.alignment",
    "align_positions": "omnical.evaluation.alignment",
    "associate": "omnical.evaluation.association",
    "estimates_of": "omnical.evaluation.metrics",
    "fit_se2": "omnical.evaluation.alignment",
    "metrics_json": "omnical.evaluation.metrics",
    "odometry_vs_ground_truth": "omnical.evaluation.odometry",
    "origin_transform": "omnical.evaluation.alignment",
    "reference_of": "omnical.evaluation.metrics",
    "shift_to_hedgehog": "omnical.evaluation.metrics",
    "track": "omnical.evaluation.metrics",
    "track_recording": "omnical.evaluation.metrics",
    "tracking_metrics": "omnical.evaluation.metrics",
    "write_tum_pair": "omnical.evaluation.association",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

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


__getattr__ = lazy_getattr(__name__, _EXPORTS)
