"""Estimation: planar poses, odometry + IPS fusion, and seed 003's dead-wheel odometry."""

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
