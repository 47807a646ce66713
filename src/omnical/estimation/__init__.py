"""Estimation: planar poses, odometry + IPS fusion, and seed 003's dead-wheel odometry."""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
    from omnical.estimation.fusion import (
        FixSource,
        FusedPoseSource,
        FusionParams,
        FusionState,
        IpsFix,
        fuse_track,
        fusion_predict,
        fusion_update,
        initial_pose_from_fixes,
    )
    from omnical.estimation.se2 import (
        Pose2,
        Twist,
        between,
        compose,
        invert,
        rotate,
        transform_point,
        wrap_angle,
    )

_EXPORTS: dict[str, str] = {
    "FixSource": "omnical.estimation.fusion",
    "FusedPoseSource": "omnical.estimation.fusion",
    "FusionParams": "omnical.estimation.fusion",
    "FusionState": "omnical.estimation.fusion",
    "IpsFix": "omnical.estimation.fusion",
    "Pose2": "omnical.estimation.se2",
    "Twist": "omnical.estimation.se2",
    "between": "omnical.estimation.se2",
    "compose": "omnical.estimation.se2",
    "fuse_track": "omnical.estimation.fusion",
    "fusion_predict": "omnical.estimation.fusion",
    "fusion_update": "omnical.estimation.fusion",
    "initial_pose_from_fixes": "omnical.estimation.fusion",
    "invert": "omnical.estimation.se2",
    "rotate": "omnical.estimation.se2",
    "transform_point": "omnical.estimation.se2",
    "wrap_angle": "omnical.estimation.se2",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

__all__ = [
    "FixSource",
    "FusedPoseSource",
    "FusionParams",
    "FusionState",
    "IpsFix",
    "Pose2",
    "Twist",
    "between",
    "compose",
    "fuse_track",
    "fusion_predict",
    "fusion_update",
    "initial_pose_from_fixes",
    "invert",
    "rotate",
    "transform_point",
    "wrap_angle",
]


__getattr__ = lazy_getattr(__name__, _EXPORTS)
