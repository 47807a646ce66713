"""Odometry from the driven wheels' encoders (``sensor_msgs/JointState``) through the kinematics.

Wheel angles → body increments J⁺ Δθ, composed at mid-step with the nominal kinematics, replacing
``/odom``; bad times are refused, counter resets repaired and counted in the notes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError, RecordingError
from omnical.estimation.se2 import rotate_xy, wrap_angles
from omnical.kinematics.jacobian import forward_jacobian, inverse_jacobian
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import ODOM
from omnical.robot.description import RobotDescription, Wheel, WheelEncoders

__all__ = [
    "MAX_WHEEL_RATE_FACTOR",
    "MIN_JUMP_RATE_RADPS",
    "WheelOdometry",
    "odometry_table",
    "repair_counter_jumps",
    "wheel_angles_of",
    "wheel_odometry",
    "wheel_odometry_of",
    "with_wheel_odometry",
]

F64 = NDArray[np.float64]

MAX_WHEEL_RATE_FACTOR = 3.0
"""A step faster than this many times the robot's fastest wheel rate is a counter reset."""
MIN_JUMP_RATE_RADPS = 60.0
"""Floor of the reset threshold, rad/s (≈ 570 rpm at the wheel)."""


@dataclass(frozen=True)
class WheelOdometry:
    """Odometry computed from wheel encoders.

    Attributes:
        t_ns: (N,) bag times of the encoder messages used, ns.
        poses: (N, 3) x_m, y_m, yaw_rad of base_link in ``odom`` (yaw unwrapped, from 0).
        twist: (N, 3) vx_mps, vy_mps, wz_radps in base_link over the step ending at each sample
            (0 at the first).
        notes: what was repaired or left out, one line each.
    """

    t_ns: NDArray[np.int64]
    poses: F64
    twist: F64
    notes: tuple[str, ...] = ()


def _max_wheel_rate_radps(robot: RobotDescription) -> float:
    """The fastest wheel rate the robot's twist limits ask for, rad/s."""
    J = inverse_jacobian(robot.wheels)
    return float(np.max(np.abs(J) @ robot.limits.max_twist))


def wheel_angles_of(
    names: ArrayLike, positions: ArrayLike, encoders: WheelEncoders, topic: str
) -> tuple[NDArray[np.intp], F64]:
    """Each wheel's angle (rad) in the JointState rows that name every wheel joint.

    Args:
        names: (N, k) joint names of each message.
        positions: (N, k) positions (ticks or radians, :class:`WheelEncoders`).
        encoders: the joints of the wheels, their counts per revolution and signs.
        topic: for messages.

    Returns:
        The indices of the rows used (M,) and the angles (M, n), wheels in description order.

    Raises:
        ConfigError: a wheel's joint is in no message (the message lists the joints found).
        RecordingError: the messages carry no positions.
    """
    nm = np.asarray(names, dtype=object)
    pos = np.asarray(positions, dtype=np.float64)
    if nm.ndim != 2 or nm.shape[0] == 0:
        msg = f"{topic}: no JointState message with joint names"
        raise RecordingError(msg)
    if pos.ndim != 2 or pos.shape != nm.shape:
        msg = (
            f"{topic}: the JointState messages carry {pos.shape[-1] if pos.ndim == 2 else 0} "
            f"positions for {nm.shape[1]} joints; wheel odometry needs a position per joint"
        )
        raise RecordingError(msg)
    columns = []
    present = np.ones(nm.shape[0], dtype=bool)
    for joint in encoders.joints:
        hit = nm == joint
        count = hit.sum(axis=1)
        if not np.any(count == 1):
            found = ", ".join(sorted({str(v) for v in nm.ravel()})) or "none"
            msg = (
                f"{topic}: no joint named {joint!r} (joints: {found}); map the wheels to the "
                "joints in the robot description's wheel_encoders.joints"
            )
            raise ConfigError(msg)
        present &= count == 1
        columns.append(np.argmax(hit, axis=1))
    rows = np.flatnonzero(present)
    index = np.column_stack(columns)[rows]
    angles: F64 = pos[rows[:, None], index] * encoders.radians_per_unit()
    return rows.astype(np.intp), angles


def repair_counter_jumps(
    t_s: ArrayLike, angles_rad: ArrayLike, max_rate_radps: float
) -> tuple[F64, int]:
    """Wheel angle increments (N−1, n) with counter resets and wraps replaced.

    A step whose |Δθ| / Δt exceeds ``max_rate_radps`` is replaced by the wheel's mean rate over
    the nearest good steps before and after it (0 when there is none) times the step.

    Returns:
        The increments and the number of (step, wheel) entries replaced.
    """
    t = np.asarray(t_s, dtype=np.float64)
    inc = np.diff(np.asarray(angles_rad, dtype=np.float64), axis=0)
    dt = np.diff(t)
    rate = inc / dt[:, None]
    bad = np.abs(rate) > max_rate_radps
    count = int(np.count_nonzero(bad))
    if count == 0:
        return inc, 0
    steps = np.arange(inc.shape[0])
    for w in range(inc.shape[1]):
        good = ~bad[:, w]
        if not np.any(good):
            inc[:, w] = 0.0
            continue
        fill = np.interp(steps[~good], steps[good], rate[good, w])
        inc[~good, w] = fill * dt[~good]
    return inc, count


def wheel_odometry(
    t_s: ArrayLike,
    angles_rad: ArrayLike,
    wheels: Sequence[Wheel],
    *,
    max_rate_radps: float = np.inf,
) -> tuple[F64, F64, int]:
    """Poses and twists from wheel angles through the forward kinematics (docs/DESIGN-NOTES.md).

    Args:
        t_s: (N,) strictly increasing times, s.
        angles_rad: (N, n) wheel angles, rad, wheels in the order of ``wheels``.
        wheels: the robot's wheels (:class:`omnical.robot.description.Wheel`).
        max_rate_radps: wheel rates above this are counter resets (:func:`repair_counter_jumps`).

    Returns:
        Poses (N, 3) x, y, yaw from the origin; twists (N, 3) in base_link; repairs made.

    Raises:
        RecordingError: fewer than 2 samples, a non-finite value, or times that do not increase.
    """
    t = np.asarray(t_s, dtype=np.float64)
    ang = np.asarray(angles_rad, dtype=np.float64)
    if ang.ndim != 2 or t.ndim != 1 or ang.shape[0] != t.shape[0]:
        msg = f"wheel angles must be (N, wheels) with N times, got {ang.shape} and {t.shape}"
        raise RecordingError(msg)
    if t.shape[0] < 2:
        msg = f"wheel odometry needs 2 or more encoder samples, got {t.shape[0]}"
        raise RecordingError(msg)
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(ang))):
        msg = "wheel encoder samples must be finite (a NaN or infinite time or position)"
        raise RecordingError(msg)
    if np.any(np.diff(t) <= 0.0):
        k = int(np.argmax(np.diff(t) <= 0.0)) + 1
        msg = f"wheel encoder times must increase: sample {k} is at {t[k]:.6f} s, after {t[k - 1]:.6f} s"
        raise RecordingError(msg)
    J_plus = forward_jacobian(inverse_jacobian(wheels))
    inc, repaired = repair_counter_jumps(t, ang, max_rate_radps)
    body = inc @ J_plus.T
    yaw = np.concatenate([[0.0], np.cumsum(body[:, 2])])
    step = rotate_xy(yaw[:-1] + 0.5 * body[:, 2], body[:, :2])
    xy = np.vstack([np.zeros((1, 2)), np.cumsum(step, axis=0)])
    twist = np.vstack([np.zeros((1, 3)), body / np.diff(t)[:, None]])
    return np.column_stack([xy, yaw]), twist, repaired


def wheel_odometry_of(recording: Recording, topic: str, robot: RobotDescription) -> WheelOdometry:
    """The odometry of ``recording``'s wheel encoders on ``topic`` (a JointState topic).

    Raises:
        RecordingError: no such topic, messages without positions, two messages at one time
            with different positions, fewer than 2 usable messages.
        ConfigError: a wheel's joint is in no message.
    """
    if not recording.has(topic):
        have = ", ".join(t for t in recording.topics if recording.has(t)) or "none"
        msg = f"no wheel encoder messages on {topic} (topics: {have})"
        raise RecordingError(msg)
    table = recording.topic(topic)
    rows, angles = wheel_angles_of(table["name"], table["position_rad"], robot.encoders, topic)
    notes: list[str] = []
    if rows.size < len(table):
        notes.append(
            f"{topic}: {len(table) - rows.size} message(s) without every wheel joint left out"
        )
    t_ns = table.t_ns[rows]
    same = np.flatnonzero(np.diff(t_ns) == 0)
    if same.size:
        k = int(same[0]) + 1
        msg = (
            f"{topic}: {same.size} message(s) at the same bag time as the one before with "
            f"different positions (first at message {int(rows[k])}); one encoder, one message "
            "per time"
        )
        raise RecordingError(msg)
    t_s = (t_ns - t_ns[0]).astype(np.float64) / 1e9
    limit = max(MAX_WHEEL_RATE_FACTOR * _max_wheel_rate_radps(robot), MIN_JUMP_RATE_RADPS)
    poses, twist, repaired = wheel_odometry(t_s, angles, robot.wheels, max_rate_radps=limit)
    _refuse_counts_read_as_radians(topic, angles, repaired, robot)
    if repaired:
        notes.append(
            f"{topic}: {repaired} encoder step(s) faster than {limit:.0f} rad/s taken as counter "
            "resets or wraps and bridged"
        )
    return WheelOdometry(t_ns.astype(np.int64), poses, twist, tuple(notes))


def _refuse_counts_read_as_radians(
    topic: str, angles: F64, repaired: int, robot: RobotDescription
) -> None:
    """Refuse whole-number positions whose steps are mostly too fast for radians (counts read
    without ``counts_per_rev``).

    Raises:
        ConfigError: so; the message names ``wheel_encoders.counts_per_rev``.
    """
    if robot.encoders.counts_per_rev is not None or len(angles) < 3:
        return
    whole = bool(np.all(angles == np.round(angles)))
    steps = (len(angles) - 1) * (angles.shape[1] if angles.ndim == 2 else 1)  # every wheel's
    if whole and repaired > 0.01 * steps:
        moving = np.abs(np.diff(angles, axis=0))
        typical = float(np.median(moving[moving > 0])) if np.any(moving > 0) else 0.0
        msg = (
            f"{topic}: the wheel positions are whole numbers stepping by {typical:g} a message "
            f"({repaired} of {steps} wheel steps too fast for radians): encoder counts, not "
            f"radians; give wheel_encoders.counts_per_rev for the robot {robot.name}: in its "
            "robot YAML, or for a preset a YAML file of two lines, 'base: PRESET' and "
            "'wheel_encoders: {counts_per_rev: N}', given as --robot FILE"
        )
        raise ConfigError(msg)


def odometry_table(t_ns: ArrayLike, poses: ArrayLike, twist: ArrayLike) -> Table:
    """An ``/odom`` table (columns of :data:`omnical.recording.topics.TOPICS`, yaw wrapped)."""
    p = np.asarray(poses, dtype=np.float64)
    v = np.asarray(twist, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or v.shape != p.shape:
        msg = f"poses and twists must both be (N, 3), got {p.shape} and {v.shape}"
        raise ConfigError(msg)
    return Table(
        np.asarray(t_ns, dtype=np.int64),
        {
            "x_m": p[:, 0],
            "y_m": p[:, 1],
            "yaw_rad": wrap_angles(p[:, 2]),
            "vx_mps": v[:, 0],
            "vy_mps": v[:, 1],
            "wz_radps": v[:, 2],
        },
    )


def with_wheel_odometry(
    recording: Recording, topic: str, robot: RobotDescription
) -> tuple[Recording, WheelOdometry]:
    """``recording`` with ``/odom`` computed from the wheel encoders on ``topic`` (replacing any)."""
    odo = wheel_odometry_of(recording, topic, robot)
    return recording.with_table(ODOM, odometry_table(odo.t_ns, odo.poses, odo.twist)), odo
