"""Where a recording's odometry and external reference come from (``evaluate``, ``calibrate
estimate`` and their fleets): the options as one checked value (:class:`Sources`), and the
odometry and reference they name, read and said the same way for every caller.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from omnical.choices import OdometrySource
from omnical.errors import ConfigError, RecordingError
from omnical.services.voice import SILENT, Voice

if TYPE_CHECKING:
    from omnical.evaluation.association import Trajectory
    from omnical.recording.recording import Recording
    from omnical.robot.description import RobotDescription

__all__ = [
    "ReadReference",
    "Sources",
    "check_installed",
    "check_reference_options",
    "odometry_choice",
    "odometry_for",
    "reference_for",
    "reference_from_spec",
    "same_topic",
]


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


def check_installed(installed: Path | None, odometry: OdometrySource) -> None:
    """Installed factors (``--installed``) go only with the bag's /odom.

    Raises:
        ConfigError: odometry computed here, with the nominal kinematics (nothing installed).
    """
    from omnical.errors import ConfigError

    if installed is not None and odometry is not OdometrySource.ODOM:
        msg = (
            f"--installed: odometry from {odometry} is computed with the nominal "
            "kinematics (nothing installed); drop --installed"
        )
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


@dataclass(frozen=True)
class ReadReference:
    """A reference as read, and what it is.

    Attributes:
        trajectory: its poses, times from the recording's first message (None: the
            recording's own ``/ground_truth``).
        label: the topic (and the child frame it holds), the file or built-in path as given.
        times: the rule its times were read by, as the single commands print it ("" for
            ``/ground_truth``).
    """

    trajectory: Trajectory | None
    label: str
    times: str = ""


def odometry_for(
    recording: Recording,
    sources: Sources,
    robot: RobotDescription,
    *,
    name: str,
    voice: Voice = SILENT,
) -> Recording:
    """``recording`` (the bag ``name``) with ``/odom`` from ``sources``; says what was used
    (another than the bag's /odom) and warns of any repair."""
    from omnical.estimation.odometry_sources import with_odometry

    try:
        out, used = with_odometry(
            recording,
            sources.odometry,
            robot,
            wheel_topic=sources.wheel_topic,
            dead_wheel_topic=sources.dead_wheel_topic,
        )
    except (ConfigError, RecordingError) as err:  # which recording: one of a fleet's
        if type(err) not in (ConfigError, RecordingError) or str(err).startswith(name):
            raise
        raise type(err)(f"{name}: {err}") from None
    if sources.odometry is not OdometrySource.ODOM:
        voice.say(f"{name}: {used.describe()}")
    for note in used.notes:
        voice.warn(note)
    return out


def reference_from_spec(
    name: str, recording: Recording, spec: str, voice: Voice = SILENT
) -> ReadReference:
    """The reference file or built-in path ``spec`` for ``recording`` (the bag ``name``); says
    what was read and the rule its times were taken by, in one line."""
    from omnical.evaluation.reference_input import BUILTIN_REFERENCES, read_reference

    loaded = read_reference(spec, recording)
    kind = "built-in path" if spec in BUILTIN_REFERENCES else f"{len(loaded.trajectory.t_s)} poses"
    times = loaded.times_note(recording.start_ns)
    voice.say(f"{name}: reference {spec} ({kind}); {times}")
    return ReadReference(loaded.trajectory, spec, times.removeprefix("reference times: "))


def same_topic(a: str, b: str) -> bool:
    """Whether two topic names are the same topic (a leading ``/`` is optional)."""
    return a.lstrip("/") == b.lstrip("/")


def reference_for(
    bag: Path, recording: Recording, sources: Sources, voice: Voice = SILENT
) -> ReadReference | None:
    """The external reference of ``bag`` (``recording`` is the bag as read) that ``sources``
    name, said as it is read; None without one. Times are seconds from the recording's first
    message."""
    from omnical.evaluation.reference_input import reference_from_poses

    if sources.reference_file is not None:
        return reference_from_spec(bag.name, recording, str(sources.reference_file), voice)
    topic = sources.reference_topic
    if topic is None:
        return None
    from omnical.bags.reference_topics import read_pose_topic

    poses = read_pose_topic(bag, topic, child_frame=sources.reference_child)
    for note in poses.notes:
        voice.warn(note)
    frames = poses.frame_id + (f" → {poses.child_frame_id}" if poses.child_frame_id else "")
    rate = (len(poses.table) - 1) / max(float(poses.table.t_s()[-1]), 1e-9)
    voice.say(
        f"{bag.name}: reference {topic} ({poses.msgtype.replace('/msg/', '/')}, "
        f"{frames or 'no frame'}): {len(poses.table)} poses, {rate:.0f} Hz"
    )
    label = topic + (f" ({poses.child_frame_id})" if poses.child_frame_id else "")
    trajectory = reference_from_poses(poses.table, recording.start_ns)
    return ReadReference(trajectory, label, "message stamps (bag time)")
