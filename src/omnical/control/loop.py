"""The closed control loop: pose in, limited body twist out, at a fixed rate (the edge of control).

:func:`run_controller` is the loop of seed 001 §4.1 / seed 000 §2.3 (Fig. 4): at every tick it
reads the robot state, takes a pose from the chosen source (wheel odometry, or any callable such
as a fused IPS + odometry estimate), asks the controller for a body twist, passes it through the
command output stage (velocity saturation and acceleration limiting, :mod:`.limits`) and sends
it. Two manual switches act on the output stage as in seed 000: *pause* holds a zero command
(reached at the acceleration limits) and freezes the controller and its time until released;
*emergency stop* sends zero at once, bypassing the limits, and ends the run. The robot is stopped
at the end, whatever the reason.

:func:`closed_loop_run` runs a controller on a fresh digital twin and assembles everything into
one :class:`~omnical.recording.recording.Recording` (commands, events, and the twin's odometry,
ground truth, IMU and post-hoc simulated IPS via :func:`omnical.twin.session.twin_recording`).

Frames: controllers work in a *path frame*. With ``pose_source="odometry"`` the path frame is
the odometry frame at the start of the loop (the first odometry pose read becomes the origin).
A callable pose source returns poses in the path frame itself.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray

from omnical.control.limits import DEFAULT_COMMAND_LIMITS, CommandLimits, limit_command
from omnical.errors import ConfigError
from omnical.estimation.se2 import Pose2, Twist, between
from omnical.experiment.ports import Clock, Robot, RobotState

if TYPE_CHECKING:
    from omnical.estimation.fusion import FusionParams, OnlineIpsParams
    from omnical.ips.beacons import BeaconMap
    from omnical.recording.recording import Recording
    from omnical.robot.description import RobotDescription
    from omnical.twin.params import TwinParams
    from omnical.twin.simulator import TwinLog

__all__ = [
    "ClosedLoopRun",
    "ControlLog",
    "ControlOutput",
    "Controller",
    "PoseSource",
    "StopReason",
    "closed_loop_recording",
    "closed_loop_run",
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
    """

    t_s: NDArray[np.float64]
    pose: NDArray[np.float64]
    command: NDArray[np.float64]
    raw_command: NDArray[np.float64]
    target_index: NDArray[np.int64]
    mode: tuple[str, ...]
    reason: StopReason
    events: tuple[tuple[float, str], ...] = ()

    @property
    def cmd_vel(self) -> NDArray[np.float64]:
        """(N, 4) t_s, vx_mps, vy_mps, wz_radps: the /cmd_vel rows."""
        return np.column_stack([self.t_s, self.command])

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
        rate_hz: control rate (seed 000/001 ran their Simulink nodes at tens of Hz).
        pose_source: ``"odometry"`` (``read_state().odom_pose`` relative to the first reading) or
            a callable ``RobotState → pose`` in the path frame (e.g. a fused IPS estimate).
        max_duration_s: clock time after which the loop gives up (reason ``"timeout"``).
        limits: the command output stage (velocity saturation, acceleration limiting).
        pause: clock time ``t_s → bool``; while true the command is ramped to zero at the acceleration
            limits and the controller (and its time) is frozen; it resumes when false.
        emergency_stop: clock time ``t_s → bool``; when true the robot is stopped at once (zero command,
            no ramp) and the loop ends (reason ``"emergency_stop"``).
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
    rows_t: list[float] = []
    rows_pose: list[Pose2] = []
    rows_cmd: list[Twist] = []
    rows_raw: list[Twist] = []
    rows_idx: list[int] = []
    rows_mode: list[str] = []
    events: list[tuple[float, str]] = [(start, _event(name, "start"))]
    previous: Twist = (0.0, 0.0, 0.0)
    controller_t = 0.0
    paused = False
    last_index: int | None = None
    reason: StopReason = "timeout"
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
                rows_t.append(t)
                rows_pose.append(pose)
                rows_cmd.append(previous)
                rows_raw.append(previous)
                rows_idx.append(last_index if last_index is not None else -1)
                rows_mode.append("emergency_stop")
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
            robot.send_twist(*command)
            previous = command
            rows_t.append(t)
            rows_pose.append(pose)
            rows_cmd.append(command)
            rows_raw.append(raw)
            rows_idx.append(output.target_index)
            rows_mode.append(output.mode)
            if on_tick is not None:
                on_tick(controller_t, output)
            if output.done:
                reason = "done"
                break
            k += 1
            clock.sleep_until(start + k * dt)
    except KeyboardInterrupt:
        reason = "interrupted"
    finally:
        robot.stop()
    t_end = clock.now_s()
    events.append((t_end, _event(name, "end", reason=reason)))
    rows_t.append(t_end)
    rows_pose.append(nan_pose)
    rows_cmd.append((0.0, 0.0, 0.0))
    rows_raw.append((0.0, 0.0, 0.0))
    rows_idx.append(last_index if last_index is not None else -1)
    rows_mode.append("stop")
    return ControlLog(
        t_s=np.array(rows_t, dtype=np.float64),
        pose=np.array(rows_pose, dtype=np.float64).reshape(-1, 3),
        command=np.array(rows_cmd, dtype=np.float64).reshape(-1, 3),
        raw_command=np.array(rows_raw, dtype=np.float64).reshape(-1, 3),
        target_index=np.array(rows_idx, dtype=np.int64),
        mode=tuple(rows_mode),
        reason=reason,
        events=tuple(events),
    )


# --------------------------------------------------------------------------- twin runs


@dataclass(frozen=True, eq=False)
class ClosedLoopRun:
    """A closed-loop run on the digital twin.

    Attributes:
        recording: /cmd_vel, /omnical/events and the twin topics (odometry, ground truth, IMU,
            post-hoc simulated IPS), stamped from :data:`omnical.twin.session.EPOCH_NS`.
        control: the loop's own log (poses used, commands, way-point indices).
        twin_log: the twin's sensor and truth arrays (seconds).
        path_origin_map: pose of the path frame in the map frame (the robot's start pose).
        odom_origin: odometry pose at the start of the loop (the path frame in the odom frame).
        pose_source: which pose closed the loop ("odometry", "fused" or "ground_truth").
        estimates: (M, 4) t_s, x, y, yaw of the fused estimate in the map frame ("fused" only).
    """

    recording: Recording
    control: ControlLog
    twin_log: TwinLog
    path_origin_map: Pose2
    odom_origin: Pose2
    pose_source: str
    estimates: NDArray[np.float64] | None = field(default=None)

    def ground_truth_path(self) -> NDArray[np.float64]:
        """(N, 4) t_s, x, y, yaw: the true pose in the path frame."""
        return _in_frame(self.path_origin_map, self.twin_log.ground_truth[:, :4])

    def odometry_path(self) -> NDArray[np.float64]:
        """(N, 4) t_s, x, y, yaw: the odometry pose in the path frame."""
        return _in_frame(self.odom_origin, self.twin_log.odom[:, :4])

    def final_error_m(self, target_xy_m: tuple[float, float], source: str) -> float:
        """Distance from the final pose (``"odometry"``, ``"ground_truth"`` or ``"control"``) to a target.

        Raises:
            ConfigError: an unknown source.
        """
        if source == "odometry":
            final = self.odometry_path()[-1, 1:3]
        elif source == "ground_truth":
            final = self.ground_truth_path()[-1, 1:3]
        elif source == "control":
            final = self.control.final_pose()[:2]
        else:
            msg = f"unknown pose source {source!r}; use odometry, ground_truth or control"
            raise ConfigError(msg)
        return math.hypot(float(final[0]) - target_xy_m[0], float(final[1]) - target_xy_m[1])


def _in_frame(origin: Pose2, rows: NDArray[np.float64]) -> NDArray[np.float64]:
    c, s = math.cos(origin[2]), math.sin(origin[2])
    dx, dy = rows[:, 1] - origin[0], rows[:, 2] - origin[1]
    return np.column_stack([rows[:, 0], c * dx + s * dy, -s * dx + c * dy, rows[:, 3] - origin[2]])


def closed_loop_run(
    controller: Controller[StateT],
    robot: RobotDescription,
    params: TwinParams,
    *,
    seed: int = 0,
    pose_source: Literal["odometry", "fused", "ground_truth"] = "odometry",
    rate_hz: float = 20.0,
    max_duration_s: float = 600.0,
    limits: CommandLimits | None = None,
    ips: OnlineIpsParams | None = None,
    fusion: FusionParams | None = None,
    beacons: BeaconMap | None = None,
    pause: Callable[[float], bool] | None = None,
    emergency_stop: Callable[[float], bool] | None = None,
    lead_in_s: float = 1.0,
    tail_s: float = 2.0,
) -> ClosedLoopRun:
    """Run ``controller`` in closed loop on a fresh twin and record everything.

    The robot stands still for ``lead_in_s`` (the fused source initialises its position from
    the IPS fixes of that time, its yaw from the known start heading), the loop runs from there,
    and the twin keeps simulating ``tail_s`` after the stop so the robot comes to rest. The path
    frame is the robot's start pose ``params.start_pose_map``.

    Args:
        controller: the control law, path-frame targets.
        robot: robot description.
        params: twin parameters (e.g. ``TwinParams.ideal_twin()`` or ``default_twin(robot)``).
        seed: twin seed; the online IPS uses ``seed`` too, the post-hoc IPS its own stream.
        pose_source: what closes the loop: wheel odometry, the fused IPS + odometry estimate
            (:class:`~omnical.estimation.fusion.FusedPoseSource` with an online
            :class:`~omnical.estimation.fusion.TwinIpsSource`) or the true pose.
        rate_hz: control rate.
        max_duration_s: loop time-out.
        limits: output stage; None = the robot's limits tightened by the default command limits.
        ips: online IPS fixes for ``"fused"`` (None = derived from ``params.ips``).
        fusion: filter parameters for ``"fused"`` (None = defaults with the robot's hedge offset).
        beacons: beacon map of the post-hoc simulated IPS in the recording.
        pause: pause switch, see :func:`run_controller`.
        emergency_stop: emergency stop switch, see :func:`run_controller`.
        lead_in_s: standing time before the loop starts.
        tail_s: simulated time after the loop stops.

    Returns:
        The run: recording, control log, twin log and frames.

    Raises:
        ConfigError: an unknown pose source, a bad rate or duration.
    """
    from omnical.estimation.fusion import (  # the twin imports control: import late
        FusedPoseSource,
        FusionParams,
        OnlineIpsParams,
        TwinIpsSource,
        initial_pose_from_fixes,
    )
    from omnical.recording.recording import RecordingBuilder
    from omnical.twin.clock import TwinClock
    from omnical.twin.session import EPOCH_NS, twin_recording
    from omnical.twin.simulator import DigitalTwin

    twin = DigitalTwin(robot, params, seed=seed)
    clock = TwinClock(twin)
    origin_map: Pose2 = tuple(float(v) for v in params.start_pose_map)  # type: ignore[assignment]
    out_limits = limits or CommandLimits.from_robot(robot.limits).tightened(DEFAULT_COMMAND_LIMITS)
    source: Literal["odometry"] | PoseSource
    fused: FusedPoseSource | None = None
    if pose_source == "odometry":
        twin.advance_to(lead_in_s)
        source = "odometry"
    elif pose_source == "ground_truth":
        twin.advance_to(lead_in_s)

        def truth(_: RobotState) -> Pose2:
            return between(origin_map, twin.ground_truth_pose)

        source = truth
    elif pose_source == "fused":
        ips_params = ips or OnlineIpsParams.from_ips_params(params.ips)
        fusion_params = fusion or FusionParams(
            hedge_offset_m=(robot.hedge_offset_m[0], robot.hedge_offset_m[1]),
            ips_sigma_m=max(ips_params.sigma_m, 0.005),
        )
        ips_source = TwinIpsSource(twin, ips_params, seed=seed)
        fixes = []
        n_lead = max(1, round(lead_in_s * rate_hz))
        for k in range(n_lead + 1):
            twin.advance_to(k * lead_in_s / n_lead)
            fixes += ips_source.poll()
        start_pose = initial_pose_from_fixes(fixes, origin_map[2], fusion_params.hedge_offset_m)
        fused = FusedPoseSource(
            fusion_params,
            ips_source,
            start_pose,
            path_origin_map=origin_map,
            initial_sigma=(
                ips_params.sigma_m / math.sqrt(max(len(fixes), 1)) + 0.005,
                ips_params.sigma_m / math.sqrt(max(len(fixes), 1)) + 0.005,
                fusion_params.initial_yaw_sigma_rad,
            ),
        )
        source = fused
    else:
        msg = f"unknown pose source {pose_source!r}; use odometry, fused or ground_truth"
        raise ConfigError(msg)
    odom_origin = twin.read_state().odom_pose
    control = run_controller(
        controller,
        twin,
        clock,
        rate_hz=rate_hz,
        pose_source=source,
        max_duration_s=max_duration_s,
        limits=out_limits,
        pause=pause,
        emergency_stop=emergency_stop,
    )
    twin.advance_to(twin.t_s + tail_s)
    log = twin.log()

    def ns(t_s: NDArray[np.float64]) -> NDArray[np.int64]:
        return EPOCH_NS + np.round(np.asarray(t_s) * 1e9).astype(np.int64)

    builder = RecordingBuilder()
    cmd = control.cmd_vel
    builder.add_many(
        "/cmd_vel", ns(cmd[:, 0]), vx_mps=cmd[:, 1], vy_mps=cmd[:, 2], wz_radps=cmd[:, 3]
    )
    t_ev = np.array([t for t, _ in control.events], dtype=np.float64)
    builder.add_many(
        "/omnical/events", ns(t_ev), text=np.array([e for _, e in control.events], dtype=object)
    )
    twin_recording(builder, log, robot, params, seed=seed, beacons=beacons)
    return ClosedLoopRun(
        recording=builder.build(),
        control=control,
        twin_log=log,
        path_origin_map=origin_map,
        odom_origin=odom_origin,
        pose_source=pose_source,
        estimates=fused.estimates() if fused is not None else None,
    )


def closed_loop_recording(
    controller: Controller[StateT],
    robot: RobotDescription,
    params: TwinParams,
    *,
    seed: int = 0,
    pose_source: Literal["odometry", "fused", "ground_truth"] = "odometry",
    rate_hz: float = 20.0,
    max_duration_s: float = 600.0,
    limits: CommandLimits | None = None,
    ips: OnlineIpsParams | None = None,
    fusion: FusionParams | None = None,
    beacons: BeaconMap | None = None,
    pause: Callable[[float], bool] | None = None,
    emergency_stop: Callable[[float], bool] | None = None,
    lead_in_s: float = 1.0,
    tail_s: float = 2.0,
) -> Recording:
    """The full recording of a closed-loop twin run, for figures and reports.

    Same arguments as :func:`closed_loop_run`; the recording holds /cmd_vel, /omnical/events
    (JSON: start, target changes, pause, resume, emergency stop, end) and the twin topics.
    """
    return closed_loop_run(
        controller,
        robot,
        params,
        seed=seed,
        pose_source=pose_source,
        rate_hz=rate_hz,
        max_duration_s=max_duration_s,
        limits=limits,
        ips=ips,
        fusion=fusion,
        beacons=beacons,
        pause=pause,
        emergency_stop=emergency_stop,
        lead_in_s=lead_in_s,
        tail_s=tail_s,
    ).recording
