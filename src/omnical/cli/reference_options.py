"""Options shared by ``omnical evaluate``, ``calibrate estimate`` and ``fleet``: reference and
odometry, declared once; checked into one value and read by :mod:`omnical.services.sources`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, TypeAlias

import typer

from omnical.choices import OdometrySource
from omnical.cli.options import choice_metavar

__all__ = [
    "DeadWheelTopic",
    "FactorsFile",
    "Odometry",
    "Reference",
    "ReferenceChild",
    "ReferenceFile",
    "ReferenceSigma",
    "ReferenceTopic",
    "WheelTopic",
]

Reference: TypeAlias = Annotated[
    str,
    typer.Option(
        help="REF.csv (t_ns or t_s, x_m, y_m[, yaw_rad]), REF.tum, lissajous, circle or "
        "square; default: /ground_truth. File times: t_ns and seconds ≥ 1e8 are absolute "
        "bag time, smaller seconds relative to the bag's first message (the rule applied "
        "is printed; by omnical fleet in each row's reference_times)."
    ),
]
FactorsFile: TypeAlias = Annotated[
    Path | None,
    typer.Option(
        "--factors",
        help="factors.yaml to correct the odometry with (e.g. from calibrate estimate on "
        "another run): its RMSE is then the calibrated one.",
    ),
]
ReferenceTopic: TypeAlias = Annotated[
    str | None,
    typer.Option(
        "--reference-topic",
        metavar="TOPIC",
        help="External reference from a topic of the bag: geometry_msgs/PoseStamped, "
        "PoseWithCovarianceStamped, nav_msgs/Odometry, TransformStamped or tf (motion capture).",
    ),
]
ReferenceChild: TypeAlias = Annotated[
    str | None,
    typer.Option(
        "--reference-child",
        metavar="FRAME",
        help="Child frame of the robot in a tf / TransformStamped / Odometry reference topic.",
    ),
]
ReferenceFile: TypeAlias = Annotated[
    Path | None,
    typer.Option(
        "--reference-file",
        help="External reference from a file: TUM (.tum/.txt: t x y z qx qy qz qw) or CSV "
        "(t_ns or t_s, x_m, y_m[, yaw_rad]; omnical export's CSV and TUM files too). Times: t_ns "
        "is absolute bag time; seconds ≥ 1e8 are absolute bag time (e.g. Unix time), smaller "
        "ones are relative to the bag's first message. The rule applied is printed (by omnical "
        "fleet: in each row's reference_times).",
    ),
]
ReferenceSigma: TypeAlias = Annotated[
    float,
    typer.Option(
        "--reference-sigma",
        min=1e-5,
        max=1.0,
        help="One-sigma noise of a reference position, 1e-5 to 1 m (motion capture: a few mm).",
    ),
]
WheelTopic: TypeAlias = Annotated[
    str | None,
    typer.Option(
        "--wheel-topic",
        metavar="TOPIC",
        help="sensor_msgs/JointState topic of the driven wheels' encoders: odometry from them "
        "through the robot's kinematics (joints, counts per revolution: the robot YAML's "
        "wheel_encoders).",
    ),
]
Odometry: TypeAlias = Annotated[
    str | None,
    typer.Option(
        "--odometry",
        metavar=choice_metavar(OdometrySource),
        help="Odometry used: odom (the bag's /odom), wheels (from --wheel-topic) or seed003 "
        "(dead wheels + IMU + magnetometer); default wheels with --wheel-topic, else odom.",
    ),
]
DeadWheelTopic: TypeAlias = Annotated[
    str,
    typer.Option(
        "--dead-wheel-topic",
        metavar="TOPIC",
        help="JointState topic of the dead wheels (--odometry seed003).",
    ),
]
