"""Which odometry a recording is evaluated or calibrated with: ``/odom``, wheel ticks or seed 003.

:func:`with_odometry` returns the recording with ``/odom`` replaced by ``wheels`` (JointState
encoders through the kinematics) or ``seed003`` (dead wheels, ``/imu`` and ``/imu/mag``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from omnical.choices import OdometrySource
from omnical.errors import ConfigError, RecordingError
from omnical.estimation.se2 import body_increments, integrate_increments
from omnical.estimation.seed003_estimator import seed003_samples_of, seed003_track
from omnical.estimation.wheel_odometry import odometry_table, with_wheel_odometry
from omnical.kinematics.correction import (
    CorrectionFactors,
    compensate_twist,
    counter_compensate_twist,
)
from omnical.recording.recording import Recording
from omnical.recording.topics import DEAD_WHEELS, ODOM
from omnical.robot.description import RobotDescription

__all__ = [
    "OdometrySource",
    "OdometryUsed",
    "corrected_odometry",
    "seed003_odometry_of",
    "with_odometry",
]


@dataclass(frozen=True)
class OdometryUsed:
    """What :func:`with_odometry` did: the source, the topic it read, and notes (one line each)."""

    source: OdometrySource
    topic: str
    samples: int
    notes: tuple[str, ...] = ()

    def describe(self) -> str:
        """One line for the user: which odometry, from which topic."""
        what = {
            OdometrySource.ODOM: "the recording's /odom",
            OdometrySource.WHEELS: f"wheel encoders on {self.topic} through the robot's kinematics",
            OdometrySource.SEED003: f"seed 003's dead wheels ({self.topic}) + /imu + /imu/mag",
        }[self.source]
        return f"odometry: {what} ({self.samples} samples)"


def seed003_odometry_of(
    recording: Recording, robot: RobotDescription, topic: str = DEAD_WHEELS
) -> Recording:
    """``recording`` with ``/odom`` = seed 003's estimate from the dead wheels on ``topic``.

    Raises:
        ConfigError: the robot has no dead wheels, or a topic is missing.
    """
    if not robot.dead_wheels:
        msg = f"robot {robot.name} has no dead wheels: seed 003's odometry needs them"
        raise ConfigError(msg)
    samples = seed003_samples_of(recording, robot.dead_wheels, dead_wheel_topic=topic)
    if len(samples) < 2:
        msg = f"{topic}: {len(samples)} usable seed 003 sample(s); the odometry needs 2 or more"
        raise RecordingError(msg)
    track = seed003_track(samples, robot.dead_wheels)
    t_ns = np.int64(recording.start_ns) + np.round(track[:, 0] * 1e9).astype(np.int64)
    keep = np.concatenate([[True], np.diff(t_ns) > 0])
    t_ns, poses = t_ns[keep], track[keep, 1:4]
    dt = np.diff(t_ns).astype(np.float64) / 1e9
    twist = np.zeros_like(poses)
    twist[1:] = body_increments(poses) / dt[:, None]
    return recording.with_table(ODOM, odometry_table(t_ns, poses, twist))


def with_odometry(
    recording: Recording,
    source: OdometrySource,
    robot: RobotDescription,
    *,
    wheel_topic: str | None = None,
    dead_wheel_topic: str = DEAD_WHEELS,
) -> tuple[Recording, OdometryUsed]:
    """``recording`` with ``/odom`` from ``source`` (docs/DESIGN-NOTES.md).

    Args:
        recording: the run.
        source: which odometry.
        robot: the robot description (wheels and their encoders, dead wheels).
        wheel_topic: the JointState topic of the driven wheels (source ``wheels``).
        dead_wheel_topic: the JointState topic of the dead wheels (source ``seed003``).

    Raises:
        ConfigError: ``wheels`` without a wheel topic; a robot without dead wheels for
            ``seed003``; a wheel joint not in the messages.
        RecordingError: the topics the source needs are missing or unusable.
    """
    if source is OdometrySource.ODOM:
        if not recording.has(ODOM):
            joints = _joint_state_topics(recording, dead_wheel_topic)
            how = (
                f"its wheel encoders are on {', '.join(joints)}: --wheel-topic {joints[0]} "
                "computes the odometry from them"
                if joints
                else "compute the odometry from the wheel encoders (--wheel-topic TOPIC, a "
                "sensor_msgs/JointState topic; the recording has none)"
            )
            dead = recording.has(dead_wheel_topic) and bool(robot.dead_wheels)
            msg = f"the recording has no /odom; {how}" + (
                f", or --odometry seed003 from its dead wheels ({dead_wheel_topic})" if dead else ""
            )
            raise RecordingError(msg)
        return recording, OdometryUsed(source, ODOM, len(recording.topic(ODOM)))
    if source is OdometrySource.WHEELS:
        if wheel_topic is None:
            msg = "odometry from the wheels needs the JointState topic of their encoders (--wheel-topic)"
            raise ConfigError(msg)
        out, odo = with_wheel_odometry(recording, wheel_topic, robot)
        return out, OdometryUsed(source, wheel_topic, int(odo.t_ns.shape[0]), odo.notes)
    out = seed003_odometry_of(recording, robot, dead_wheel_topic)
    return out, OdometryUsed(source, dead_wheel_topic, len(out.topic(ODOM)))


def _joint_state_topics(recording: Recording, dead_wheel_topic: str) -> list[str]:
    """The recording's JointState topics with samples, other than the dead wheels'."""
    return [
        t
        for t in recording.topics
        if t != dead_wheel_topic
        and recording.has(t)
        and {"name", "position_rad"} <= set(recording.topic(t).columns)
    ]


def _increments_and_dt(
    recording: Recording,
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    odom = recording.topic(ODOM)
    keep = np.concatenate([[True], np.diff(odom.t_ns) > 0])
    t_ns = odom.t_ns[keep]
    poses = np.column_stack([odom["x_m"], odom["y_m"], odom["yaw_rad"]])[keep].astype(np.float64)
    return t_ns, poses, body_increments(poses)


def corrected_odometry(
    recording: Recording,
    factors: CorrectionFactors,
    installed: CorrectionFactors | None = None,
) -> Recording:
    """``recording`` with its ``/odom`` corrected by ``factors`` (a calibration's result).

    Each increment between consecutive samples (body frame, heading at mid-step) is taken back to
    what the nominal kinematics measured (undoing ``installed``, the factors the odometry was
    compensated with; default none, as for odometry computed from the wheels), then corrected
    with ``factors`` (:func:`~omnical.kinematics.correction.counter_compensate_twist`), and
    composed again from the first pose.

    Raises:
        RecordingError: no ``/odom`` or fewer than 2 samples.
    """
    if not recording.has(ODOM) or len(recording.topic(ODOM)) < 2:
        msg = "correcting the odometry needs /odom with 2 or more samples"
        raise RecordingError(msg)
    t_ns, poses, inc = _increments_and_dt(recording)
    raw = compensate_twist(inc, installed) if installed is not None else inc
    real = counter_compensate_twist(raw, factors)
    dt = np.diff(t_ns).astype(np.float64) / 1e9
    twist = np.vstack([np.zeros((1, 3)), real / dt[:, None]])
    return recording.with_table(
        ODOM, odometry_table(t_ns, integrate_increments(poses[0], real), twist)
    )
