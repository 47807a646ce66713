"""Calibration: geometric fits of IPS tracks and segmentation of runs from the commanded twist."""

from omnical.calibration.geometry import (
    ArcThroughPoints,
    CircleFit,
    Loss,
    MeanPosition,
    arc_length,
    circle_through_three_points,
    fit_circle,
    heading_from_positions,
    mean_position,
    three_point_arc,
)
from omnical.calibration.segments import (
    Segment,
    SegmentKind,
    segment_commands,
    segment_mask,
    settled,
)

__all__ = [
    "ArcThroughPoints",
    "CircleFit",
    "Loss",
    "MeanPosition",
    "Segment",
    "SegmentKind",
    "arc_length",
    "circle_through_three_points",
    "fit_circle",
    "heading_from_positions",
    "mean_position",
    "segment_commands",
    "segment_mask",
    "settled",
    "three_point_arc",
]
