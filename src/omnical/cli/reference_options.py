"""Options shared by ``omnical evaluate`` and ``calibrate estimate``: reference and odometry.

:func:`reference_for` and :func:`odometry_for` read, check and report them the same way for both.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, TypeAlias

import typer

from omnical.choices import OdometrySource
from omnical.cli.options import choice_metavar

if TYPE_CHECKING:
    from omnical.evaluation.association import Trajectory
    from omnical.recording.recording import Recording
    from omnical.robot.description import RobotDescription

__all__ = [
    "DeadWheelTopic",
    "FactorsFile",
    "Odometry",
    "Reference",
    "ReferenceChild",
    "ReferenceFile",
    "ReferenceSigma",
    "ReferenceTopic",
    "Sources",
    "WheelTopic",
    "check_reference_options",
    "odometry_choice",
    "odometry_for",
    "reference_for",
    "reference_from_spec",
    "same_topic",
    "warn",
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


def warn(note: str) -> None:
    """One warning line on stderr (what reading or computing cleaned or repaired)."""
    typer.echo(f"omnical: warning: {note}", err=True)


def odometry_choice(text: str | None, wheel_topic: str | None) -> OdometrySource:
    """The odometry source named by ``--odometry`` (default: wheels with a wheel topic, else odom).

    Raises:
        ChoiceError: an unknown name.
        ConfigError: ``wheels`` without ``--wheel-topic``, or ``--wheel-topic`` with another source.
    """
    from omnical.choices import parse_choice
    from omnical.errors import ConfigError

    if text is None:
        return OdometrySource.WHEELS if wheel_topic is not None else OdometrySource.ODOM
    source = parse_choice(OdometrySource, text, "--odometry")
    if source is OdometrySource.WHEELS and wheel_topic is None:
        msg = "--odometry wheels needs --wheel-topic (the JointState topic of the wheel encoders)"
        raise ConfigError(msg)
    if source is not OdometrySource.WHEELS and wheel_topic is not None:
        msg = f"--wheel-topic gives the wheels' odometry; it does not go with --odometry {source}"
        raise ConfigError(msg)
    return source


def check_reference_options(
    topic: str | None, child: str | None, file: Path | None, *others: str | None
) -> None:
    """At most one reference; a child frame only with a topic.

    ``others`` are further reference options of the command (given or None), e.g. ``--reference``.

    Raises:
        ConfigError: two references, or ``--reference-child`` without ``--reference-topic``.
    """
    from omnical.errors import ConfigError

    given = [x for x in (topic, file, *others) if x is not None]
    if len(given) > 1:
        msg = "give one reference: a topic (--reference-topic) or a file (--reference-file)"
        raise ConfigError(msg)
    if child is not None and topic is None:
        msg = "--reference-child selects a frame of --reference-topic; give the topic too"
        raise ConfigError(msg)


@dataclass(frozen=True)
class Sources:
    """Where the odometry and the external reference come from: the options of the same names
    as one value, checked (:meth:`of`); ``factors`` is evaluate's, the σ calibrate's."""

    odometry: OdometrySource
    wheel_topic: str | None
    dead_wheel_topic: str
    reference_topic: str | None
    reference_child: str | None
    reference_file: Path | None
    factors: Path | None = None
    reference_sigma_m: float = 0.002

    @classmethod
    def of(
        cls,
        odometry: str | None,
        wheel_topic: str | None,
        dead_wheel_topic: str,
        reference_topic: str | None,
        reference_child: str | None,
        reference_file: Path | None,
        *others: str | None,
        factors: Path | None = None,
        reference_sigma_m: float = 0.002,
    ) -> Sources:
        """The options as given, checked (:func:`check_reference_options` with ``others``, the
        command's further reference options, and :func:`odometry_choice`)."""
        check_reference_options(reference_topic, reference_child, reference_file, *others)
        source = odometry_choice(odometry, wheel_topic)
        return cls(source, wheel_topic, dead_wheel_topic, reference_topic, reference_child,
                   reference_file, factors, reference_sigma_m)  # fmt: skip

    @property
    def external(self) -> bool:
        """Whether the reference is external (a topic or a file), not the IPS."""
        return self.reference_topic is not None or self.reference_file is not None

    def options(self) -> str:
        """The odometry and reference options as given, for a file's comment."""
        parts = []
        if self.wheel_topic is not None:
            parts.append(f"--wheel-topic {self.wheel_topic}")
        elif self.odometry != "odom":
            parts.append(f"--odometry {self.odometry}")
        if self.reference_topic is not None:
            parts.append(f"--reference-topic {self.reference_topic}")
            if self.reference_child is not None:
                parts.append(f"--reference-child {self.reference_child}")
        if self.reference_file is not None:
            parts.append(f"--reference-file {self.reference_file}")
        return "".join(f" {p}" for p in parts)


def odometry_for(
    recording: Recording,
    source: OdometrySource,
    robot: RobotDescription,
    *,
    wheel_topic: str | None,
    dead_wheel_topic: str,
    name: str,
) -> Recording:
    """``recording`` with ``/odom`` from ``source``; prints what was used and any repair."""
    from omnical.cli.output import say
    from omnical.estimation.odometry_sources import with_odometry

    out, used = with_odometry(
        recording, source, robot, wheel_topic=wheel_topic, dead_wheel_topic=dead_wheel_topic
    )
    if source is not OdometrySource.ODOM:
        say(f"{name}: {used.describe()}")
    for note in used.notes:
        warn(note)
    return out


def reference_from_spec(name: str, recording: Recording, spec: str) -> Trajectory:
    """The reference file or built-in path ``spec`` for ``recording`` (the bag ``name``); prints
    what was read and the rule its times were taken by, in one line."""
    from omnical.cli.output import say
    from omnical.evaluation.reference_input import BUILTIN_REFERENCES, read_reference

    loaded = read_reference(spec, recording)
    kind = "built-in path" if spec in BUILTIN_REFERENCES else f"{len(loaded.trajectory.t_s)} poses"
    say(f"{name}: reference {spec} ({kind}); {loaded.times_note(recording.start_ns)}")
    return loaded.trajectory


def same_topic(a: str, b: str) -> bool:
    """Whether two topic names are the same topic (a leading ``/`` is optional)."""
    return a.lstrip("/") == b.lstrip("/")


def reference_for(
    bag: Path, recording: Recording, topic: str | None, child: str | None, file: Path | None
) -> Trajectory | None:
    """The external reference of ``bag`` (``recording`` is the bag as read), or None.

    Times are seconds from the recording's first message.
    """
    from omnical.cli.output import say
    from omnical.evaluation.reference_input import reference_from_poses

    if file is not None:
        return reference_from_spec(bag.name, recording, str(file))
    if topic is None:
        return None
    from omnical.bags.reference_topics import read_pose_topic

    poses = read_pose_topic(bag, topic, child_frame=child)
    for note in poses.notes:
        warn(note)
    frames = poses.frame_id + (f" → {poses.child_frame_id}" if poses.child_frame_id else "")
    rate = (len(poses.table) - 1) / max(float(poses.table.t_s()[-1]), 1e-9)
    say(
        f"{bag.name}: reference {topic} ({poses.msgtype.replace('/msg/', '/')}, "
        f"{frames or 'no frame'}): {len(poses.table)} poses, {rate:.0f} Hz"
    )
    return reference_from_poses(poses.table, recording.start_ns)
