"""The closed control loop: pose in, limited body twist out, at a fixed rate (the edge of control).

:func:`run_controller` runs a controller on any ``Robot`` and ``Clock``, poses from the odometry
(path frame: its first pose) or a callable; *pause* holds zero, *emergency stop* ends at once.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray

from omnical.control.limits import DEFAULT_COMMAND_LIMITS, CommandLimits, limit_command
from omnical.errors import ConfigError, RunStop, SafetyStopError
from omnical.estimation.se2 import Pose2, Twist, between
from omnical.experiment.ports import Clock, Robot, RobotState

__all__ = [
    "ControlLog",
    "ControlOutput",
    "Controller",
    "PoseSource",
    "StopReason",
    "run_controller",
]

StateT = TypeVar("StateT")

PoseSource = Callable[[RobotState], Pose2]
"""Maps the latest robot state to the pose (x m, y m, yaw rad) of base_link in the path frame."""

StopReason = Literal["done", "timeout", "emergency_stop", "interrupted"]


@dataclass(frozen=True)
class ControlOutput:
    """What a controller answers at one tick.

    Attributes:
        twist: (vx m/s, vy m/s, wz rad/s) command in base_link, before the output stage.
        target_index: index of the way-point (or goal) being approached; −1 when not applicable.
        mode: short label of the controller's phase ("turn", "drive", "track", "done", ...).
        done: the controller has finished; the loop stops the robot and returns.
    """

    twist: Twist
    target_index: int = -1
    mode: str = ""
    done: bool = False


class Controller(Protocol[StateT]):
    """A control law with its own small state record, stepped by :func:`run_controller`.

    Implementations keep their parameters frozen and return a new state at every step.
    """

    @property
    def name(self) -> str:
        """Label used in logs and events."""

    def initial_state(self) -> StateT:
        """State before the first step."""

    def step(
        self, state: StateT, t_s: float, pose: Pose2, dt_s: float
    ) -> tuple[ControlOutput, StateT]:
        """One control update.

        Args:
            state: state after the previous step.
            t_s: controller time since the start of the loop (pauses excluded).
            pose: (x m, y m, yaw rad) of base_link in the path frame.
            dt_s: time since the previous step.

        Returns:
            ``(output, new_state)``.
        """


@dataclass(frozen=True, eq=False)
class ControlLog:
    """What the loop did, one row per tick (plus a final stop row).

    Attributes:
        t_s: (N,) clock time of each row.
        pose: (N, 3) pose used by the controller, path frame (NaN on the final stop row).
        command: (N, 3) twist sent, after the output stage (vx, vy, wz).
        raw_command: (N, 3) twist the controller asked for (zero while paused and when stopping).
        target_index: (N,) way-point index (−1 when not applicable).
        mode: (N,) controller phase per row ("paused", "stop" and "emergency_stop" from the loop).
        reason: why the loop ended.
        events: (t_s, JSON text) of target changes, pauses, resumptions and the end.
        interruption: the ``KeyboardInterrupt`` (or subclass: SIGTERM) or the safety stop that
            ended the loop, for the caller to re-raise once what was recorded is kept.
    """

    t_s: NDArray[np.float64]
    pose: NDArray[np.float64]
    command: NDArray[np.float64]
    raw_command: NDArray[np.float64]
    target_index: NDArray[np.int64]
    mode: tuple[str, ...]
    reason: StopReason
    events: tuple[tuple[float, str], ...] = ()
    interruption: RunStop | None = field(default=None, compare=False, repr=False)

    @property
    def cmd_vel(self) -> NDArray[np.float64]:
        """(N, 4) t_s, vx_mps, vy_mps, wz_radps: the /cmd_vel rows, a repeated row dropped."""
        rows = np.column_stack([self.t_s, self.command])
        repeat = np.zeros(len(rows), dtype=bool)
        repeat[1:] = np.all(rows[1:] == rows[:-1], axis=1)
        return rows[~repeat]

    def final_pose(self) -> NDArray[np.float64]:
        """(3,) the last pose the controller saw."""
        poses = self.pose[np.all(np.isfinite(self.pose), axis=1)]
        if poses.shape[0] == 0:
            return np.full(3, np.nan)
        return np.asarray(poses[-1], dtype=np.float64)


def _event(controller: str, kind: str, **extra: object) -> str:
    return json.dumps({"controller": controller, "event": kind, **extra}, separators=(",", ":"))


class _OdometrySource:
    """Odometry pose relative to the first one read (odometry frame = path frame at the start)."""

    def __init__(self) -> None:
        self._origin: Pose2 | None = None

    def __call__(self, state: RobotState) -> Pose2:
        if self._origin is None:
            self._origin = state.odom_pose
        return between(self._origin, state.odom_pose)


def run_controller(
    controller: Controller[StateT],
    robot: Robot,
    clock: Clock,
    *,
    rate_hz: float = 20.0,
    pose_source: Literal["odometry"] | PoseSource = "odometry",
    max_duration_s: float = 600.0,
    limits: CommandLimits = DEFAULT_COMMAND_LIMITS,
    pause: Callable[[float], bool] | None = None,
    emergency_stop: Callable[[float], bool] | None = None,
    on_tick: Callable[[float, ControlOutput], None] | None = None,
) -> ControlLog:
    """Run ``controller`` in closed loop on ``robot`` until it is done, times out or is stopped.

    Args:
        controller: the control law (e.g. :class:`~omnical.control.waypoint.WaypointController`).
        robot: any Robot port (twin, serial, ROS).
        clock: the matching clock (simulated for the twin).
        rate_hz: control rate.
        pose_source: ``"odometry"`` (``read_state().odom_pose`` relative to the first reading) or
            a callable ``RobotState → pose`` in the path frame (e.g. a fused IPS estimate).
        max_duration_s: clock time after which the loop gives up (reason ``"timeout"``).
        limits: the command output stage (velocity saturation, acceleration limiting).
        pause: ``t_s → bool``; while true the command ramps to zero at the acceleration limits
            and the controller and its time are frozen.
        emergency_stop: ``t_s → bool``; when true the robot stops at once (no ramp) and the loop
            ends (reason ``"emergency_stop"``).
        on_tick: called after each tick with the controller time and its output.

    Returns:
        The control log; its last row is the stop command sent at the end.

    Raises:
        ConfigError: a non-positive rate or duration, an unknown pose source name.
    """
    if not (math.isfinite(rate_hz) and rate_hz > 0.0):
        msg = f"control rate must be finite and > 0, got {rate_hz}"
        raise ConfigError(msg)
    if not max_duration_s > 0.0:
        msg = f"max_duration_s must be > 0, got {max_duration_s}"
        raise ConfigError(msg)
    source: PoseSource
    if isinstance(pose_source, str):
        if pose_source != "odometry":
            msg = f"unknown pose source {pose_source!r}; use 'odometry' or a callable"
            raise ConfigError(msg)
        source = _OdometrySource()
    else:
        source = pose_source
    dt = 1.0 / rate_hz
    start = clock.now_s()
    name = controller.name
    state = controller.initial_state()
    # one row a tick (t, pose, command, raw command, target index, mode), appended whole before
    # the command is sent: a stop (a signal's exception can fall between any two lines) never
    # leaves a command the robot took out of the log, nor the columns of unequal length
    rows: list[tuple[float, Pose2, Twist, Twist, int, str]] = []
    events: list[tuple[float, str]] = [(start, _event(name, "start"))]
    previous: Twist = (0.0, 0.0, 0.0)
    controller_t = 0.0
    paused = False
    last_index: int | None = None
    reason: StopReason = "timeout"
    interruption: RunStop | None = None
    nan_pose: Pose2 = (math.nan, math.nan, math.nan)
    k = 0
    try:
        while True:
            t = start + k * dt
            if t - start > max_duration_s + 1e-9:
                reason = "timeout"
                break
            robot_state = robot.read_state()
            pose = source(robot_state)
            if emergency_stop is not None and emergency_stop(t):
                robot.stop()
                previous = (0.0, 0.0, 0.0)
                reason = "emergency_stop"
                events.append((t, _event(name, "emergency_stop")))
                index = last_index if last_index is not None else -1
                rows.append((t, pose, previous, previous, index, "emergency_stop"))
                break
            want_pause = pause is not None and pause(t)
            if want_pause != paused:
                paused = want_pause
                events.append((t, _event(name, "pause" if paused else "resume")))
            if paused:
                raw: Twist = (0.0, 0.0, 0.0)
                output = ControlOutput(raw, last_index if last_index is not None else -1, "paused")
            else:
                output, state = controller.step(state, controller_t, pose, dt)
                raw = output.twist
                controller_t += dt
            if output.target_index != last_index:
                if last_index is not None:
                    events.append((t, _event(name, "target", index=output.target_index)))
                last_index = output.target_index
            command = (0.0, 0.0, 0.0) if output.done else limit_command(limits, previous, raw, dt)
            rows.append((t, pose, command, raw, output.target_index, output.mode))
            robot.send_twist(*command)
            previous = command
            if on_tick is not None:
                on_tick(controller_t, output)
            if output.done:
                reason = "done"
                break
            k += 1
            clock.sleep_until(start + k * dt)
    except (KeyboardInterrupt, SafetyStopError) as err:
        reason = "interrupted"
        interruption = err
    finally:
        robot.stop()
    t_end = clock.now_s()
    events.append((t_end, _event(name, "end", reason=reason)))
    zero: Twist = (0.0, 0.0, 0.0)
    rows.append((t_end, nan_pose, zero, zero, last_index if last_index is not None else -1, "stop"))
    rows_t, rows_pose, rows_cmd, rows_raw, rows_idx, rows_mode = zip(*rows, strict=True)
    return ControlLog(
        t_s=np.array(rows_t, dtype=np.float64),
        pose=np.array(rows_pose, dtype=np.float64).reshape(-1, 3),
        command=np.array(rows_cmd, dtype=np.float64).reshape(-1, 3),
        raw_command=np.array(rows_raw, dtype=np.float64).reshape(-1, 3),
        target_index=np.array(rows_idx, dtype=np.int64),
        mode=tuple(rows_mode),
        reason=reason,
        events=tuple(events),
        interruption=interruption,
    )
