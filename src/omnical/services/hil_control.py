"""Hardware in the loop: a closed-loop controller on a serial base, in wall-clock time, recorded.

:func:`run_serial_controller` runs any controller (e.g. seed 003's
:func:`~omnical.control.centred.task_controller`) through
:func:`~omnical.control.loop.run_controller` on a
:class:`~omnical.drivers.wheeltec_serial.WheeltecRobot` with the host's clock
(:class:`~omnical.services.hil.HostClock`), closed on the driver's odometry (integrated from the
vehicle controller's status frames: a serial robot has no dead-wheel topics, so the seed 003
estimate cannot close the loop). It records what :class:`~omnical.services.hil.SerialRig` records
for a motion script — ``/cmd_vel`` (the commands the loop sent), ``/omnical/events`` (the loop's
start, target changes and end), ``/odom`` and ``/imu`` from the status frames, the hedgehog
topics — with the same time base, lead-in and tail at rest.

The loop is stopped at once (zero command, reason ``emergency_stop``) when the controller raises
its stop flag. A status stream that falls silent (the odometry closing the loop would be frozen)
is the driver's safety stop (:class:`~omnical.errors.SafetyStopError`, from the driver's thread within
a status period of its limit). Either that or a ``KeyboardInterrupt`` (Ctrl-C, SIGTERM turned
into one by the CLI, an abort key) stops the robot and is handed back in the result for the
caller to re-raise once the bag is kept.

:func:`check_task_path` is the safety check of a task before it moves: its reference polyline
(the goals from the start pose) placed at the robot's start in the map must stay ``margin_m``
inside the beacon coverage and the allowed area (:func:`check_polyline`).

:func:`navigate_serial` drives planned legs (``omnical navigate --robot serial:…``) on a serial
base, localised by the driver's odometry fused with the live hedgehog's fixes
(:class:`~omnical.estimation.fusion.FusedPoseSource` on a :class:`HedgeFixSource`); there is no
live LiDAR driver, so no scan matching. Each leg is planned from the localised pose and its path
checked against the coverage and the area before it moves; the hedgehog localises it, so a
silent hedgehog is a safety stop too.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from omnical.control.limits import CommandLimits
from omnical.control.loop import Controller, ControlLog, ControlOutput, run_controller
from omnical.drivers.compensation import CompensatingRobot
from omnical.drivers.hedgehog import SerialHedgehog
from omnical.drivers.safety import Area, PathCheck, check_points
from omnical.drivers.wheeltec_serial import WheeltecRobot
from omnical.errors import RunStop, SafetyStopError
from omnical.estimation.fusion import IpsFix
from omnical.estimation.se2 import Pose2, between, between_poses, transform_points
from omnical.experiment.ports import RobotState
from omnical.experiment.rig import LEAD_IN_S, RowSink
from omnical.ips.beacons import BeaconMap
from omnical.kinematics.correction import CorrectionFactors
from omnical.services.hil import (
    HostClock,
    _hold,
    _MonoClock,
    _Recorder,
    abort_keys,
)

if TYPE_CHECKING:
    from omnical.estimation.fusion import FusionParams
    from omnical.navigation.inflation import InflatedMap
    from omnical.navigation.prm import PlanParams, PlanResult, Roadmap
    from omnical.services.seed003 import TestErrors

__all__ = [
    "HedgeFixSource",
    "HilControlRun",
    "HilLeg",
    "HilNavigationRun",
    "check_polyline",
    "check_task_path",
    "leg_controller",
    "navigate_serial",
    "run_serial_controller",
    "task_errors",
]

StateT = TypeVar("StateT")

TASK_TAIL_S = 2.0
"""Standing time recorded after the loop stops (as ``closed_loop_run`` on the twin)."""


@dataclass
class HilControlRun:
    """What a closed-loop run on a serial base produced.

    Attributes:
        control: the loop's log (times: robot seconds since the run's start, the bag's origin).
        odometry_path: (N, 4) t_s, x, y, yaw of the driver's odometry in the path frame (the
            odometry pose the loop read first), from the loop's start to its end.
        messages: rows written per topic.
        t0_wall_ns: the wall-clock time of the run's start (t_s = 0).
        stopped_because: why the loop stopped the robot early ("" unless ``emergency_stop``).
        aborted_by_key: an abort key on the terminal stopped the run.
    """

    control: ControlLog
    odometry_path: NDArray[np.float64]
    messages: dict[str, int] = field(default_factory=dict)
    t0_wall_ns: int = 0
    stopped_because: str = ""
    aborted_by_key: bool = False

    @property
    def interrupted(self) -> bool:
        """The run was cut by Ctrl-C, SIGTERM or an abort key."""
        return self.control.reason == "interrupted"


class _TeeSink:
    """Passes rows on and keeps the ``/odom`` rows (the odometry path of the run's measures)."""

    def __init__(self, inner: RowSink) -> None:
        self.inner = inner
        self.odom: list[tuple[NDArray[np.int64], NDArray[np.float64]]] = []

    def write_rows(self, topic: str, t_ns: Any, **columns: Any) -> None:
        self.inner.write_rows(topic, t_ns, **columns)
        if topic == "/odom":
            pose = np.column_stack([columns["x_m"], columns["y_m"], columns["yaw_rad"]])
            self.odom.append((np.asarray(t_ns, dtype=np.int64), pose.astype(np.float64)))


class _OdometryOrigin:
    """The loop's pose source: the odometry relative to the first reading (kept for the log)."""

    def __init__(self) -> None:
        self.origin: Pose2 | None = None

    def __call__(self, state: RobotState) -> Pose2:
        if self.origin is None:
            self.origin = state.odom_pose
        return between(self.origin, state.odom_pose)


def run_serial_controller(
    controller: Controller[StateT],
    robot: WheeltecRobot,
    hedge: SerialHedgehog | None,
    sink: RowSink,
    *,
    limits: CommandLimits,
    compensation: CorrectionFactors | None = None,
    rate_hz: float = 20.0,
    max_duration_s: float = 600.0,
    lead_in_s: float = LEAD_IN_S,
    tail_s: float = TASK_TAIL_S,
    clock: HostClock | None = None,
    abort_key: bool = True,
    on_tick: Callable[[float, ControlOutput], None] | None = None,
    on_warning: Callable[[str], None] | None = None,
) -> HilControlRun:
    """Run ``controller`` closed on the driver's odometry, in robot time, writing every topic.

    Args:
        controller: the control law, goals in the path frame (the robot's pose at the loop's
            first tick).
        robot: the open driver (its odometry closes the loop).
        hedge: the open hedgehog (recorded only: its gaps are marked and said to
            ``on_warning``), or None.
        sink: where the rows go (``BagRecorder``).
        limits: the command output stage (velocity saturation, acceleration limiting).
        compensation: factors applied host-side (:class:`CompensatingRobot`): compensated
            commands out, counter-compensated odometry in; an ``installed_factors`` event.
        rate_hz: control rate.
        max_duration_s: robot time after which the loop gives up (reason ``timeout``).
        lead_in_s, tail_s: standing time recorded before and after the loop.
        clock: the host's robot-time clock (default: real time); the driver and the hedgehog
            must stamp with the same one.
        abort_key: space, q or Esc on the terminal stop the run as Ctrl-C does.
        on_tick: called after each tick with the controller time and its output.

    Returns:
        The run; ``interrupted`` when Ctrl-C / SIGTERM / an abort key / a safety stop ended
        it (the caller keeps the bag and re-raises ``control.interruption``).
    """
    host = clock if clock is not None else HostClock()
    t0 = host.now_s()
    runner_clock = _MonoClock(t0, host)
    tee = _TeeSink(sink)
    rec = _Recorder(tee, robot, hedge, t0, host, on_warning=on_warning)
    port: Any = robot if compensation is None else CompensatingRobot(robot, compensation)
    source = _OdometryOrigin()
    why: list[str] = []
    stop_now = _stop_flag(robot, why)

    def tick(t_s: float, output: ControlOutput) -> None:
        rec.maybe_drain()
        if on_tick is not None:
            on_tick(t_s, output)

    control: ControlLog | None = None
    by_key = False
    try:
        with abort_keys(abort_key) as watch:
            try:
                _hold(robot, runner_clock, lead_in_s, rec)
                control = run_controller(
                    controller,
                    port,
                    runner_clock,
                    rate_hz=rate_hz,
                    pose_source=source,
                    max_duration_s=max_duration_s,
                    limits=limits,
                    emergency_stop=stop_now,
                    on_tick=tick,
                )
                if control.reason in ("done", "timeout"):
                    _hold(robot, runner_clock, tail_s, rec)
            finally:
                by_key = watch is not None and watch.pressed
    finally:
        robot.stop()
        rec.drain()
        if isinstance(port, CompensatingRobot):
            port.release()
        if control is not None:
            _write_control(rec, control, compensation)
    path = _odometry_path(tee, rec.wall0_ns, source.origin, control)
    return HilControlRun(control, path, rec.counts, rec.wall0_ns, "; ".join(why[:1]), by_key)


def _write_control(
    rec: _Recorder, control: ControlLog, installed: CorrectionFactors | None
) -> None:
    import json

    cmd = control.cmd_vel
    rec.write_rows("/cmd_vel", cmd[:, 0], vx_mps=cmd[:, 1], vy_mps=cmd[:, 2], wz_radps=cmd[:, 3])
    events = list(control.events)
    if installed is not None:
        text = json.dumps({"omnical": "installed_factors", "factors": installed.as_dict()})
        events.insert(0, (0.0, text))
    rec.write_events(events)


def _stop_flag(robot: WheeltecRobot, why: list[str]) -> Callable[[float], bool]:
    """The loops' emergency stop: the controller's stop flag (the reason appended to ``why``)."""

    def stop_now(_t: float) -> bool:
        if robot.read_state().stop_flag:
            why.append("the controller raised its stop flag (E-stop or low battery)")
        return bool(why)

    return stop_now


def _odometry_path(
    tee: _TeeSink, wall0_ns: int, origin: Pose2 | None, control: ControlLog
) -> NDArray[np.float64]:
    """(N, 4) the recorded odometry in the path frame over the loop's time span."""
    if not tee.odom or origin is None:
        return np.zeros((0, 4))
    t = (np.concatenate([t for t, _ in tee.odom]) - wall0_ns) / 1e9
    pose = np.concatenate([p for _, p in tee.odom])
    keep = (t >= control.t_s[0] - 0.1) & (t <= control.t_s[-1] + 1e-9)
    return np.column_stack([t[keep], between_poses(np.asarray(origin), pose[keep])])


def check_polyline(
    points_map: NDArray[np.float64],
    beacons: BeaconMap,
    *,
    margin_m: float = 0.3,
    allowed: Area | None = None,
    name: str = "the path",
    start_xy_m: tuple[float, float] | None = None,
) -> PathCheck:
    """Check a polyline in the map (its corners, (P, 2)), sampled every 2 cm: it must stay
    ``margin_m`` inside the convex hull of the beacons and inside ``allowed`` if given
    (:func:`~omnical.drivers.safety.check_points`)."""
    ref = np.asarray(points_map, dtype=np.float64).reshape(-1, 2)
    dense = [ref[:1]]
    for a, b in itertools.pairwise(ref):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) / 0.02))
        u = np.linspace(0.0, 1.0, n + 1)[1:, None]
        dense.append(a + u * (b - a))
    return check_points(
        np.concatenate(dense),
        beacons,
        margin_m=margin_m,
        allowed=allowed,
        name=name,
        start_xy_m=start_xy_m,
    )


def check_task_path(
    reference_m: Sequence[Sequence[float]],
    start_pose_map: Pose2,
    beacons: BeaconMap,
    *,
    margin_m: float = 0.3,
    allowed: Area | None = None,
    name: str = "the task",
) -> PathCheck:
    """Check a task's reference path (path frame, start point first) placed at the start pose
    (:func:`check_polyline`)."""
    ref = np.asarray(reference_m, dtype=np.float64).reshape(-1, 2)
    corners = transform_points(np.asarray(start_pose_map, dtype=np.float64), ref)
    return check_polyline(
        corners,
        beacons,
        margin_m=margin_m,
        allowed=allowed,
        name=repr(name),
        start_xy_m=(float(start_pose_map[0]), float(start_pose_map[1])),
    )


def task_errors(
    slug: str, path: NDArray[np.float64], reference_m: NDArray[np.float64], control: ControlLog
) -> TestErrors:
    """Seed 003's measures of a task (labels in ``services.seed003.ERROR_LABELS``) on a path.

    Args:
        slug: the task's test ("square", ...).
        path: (N, 4) t_s, x, y, yaw in the path frame (e.g. :attr:`HilControlRun.odometry_path`).
        reference_m: (P, 2) the task's reference path, start point first.
        control: the loop's log (which leg was driven when).
    """
    from omnical.services.seed003 import _errors

    return _errors(slug, path, reference_m, control)


# ----------------------------------------------------------------------------- navigation


class HedgeFixSource:
    """A :class:`~omnical.estimation.fusion.FixSource` on a live hedgehog: its newest position,
    once per position (measured at the device-mapped stamp; a second fix arriving between two
    polls is skipped — the hedgehog streams at 8–25 Hz, the loop polls at 20 Hz)."""

    def __init__(self, hedge: SerialHedgehog, clock: HostClock) -> None:
        self.hedge, self.clock = hedge, clock
        self._last_t: float | None = None
        self.polled = 0

    def poll(self) -> list[IpsFix]:
        """The fix that arrived since the previous poll, if any."""
        fix = self.hedge.latest_fix()
        if fix is None or fix.t_s == self._last_t:
            return []
        self._last_t = fix.t_s
        self.polled += 1
        return [IpsFix(fix.t_s, self.clock.now_s(), fix.x_m, fix.y_m)]


@dataclass(frozen=True, eq=False)
class HilLeg:
    """One leg driven over serial.

    Attributes:
        goal_m: the goal (map frame).
        plan: the leg's plan from the localised pose at its start.
        control: the loop's log (None: not driven).
        controller: "waypoint" or "tracking".
        end_pose: the localised pose (fused, map frame) at rest after the leg (NaN if not driven).
    """

    goal_m: tuple[float, float]
    plan: PlanResult
    control: ControlLog | None
    controller: str
    end_pose: Pose2 = (math.nan, math.nan, math.nan)

    @property
    def estimated_error_m(self) -> float:
        """Distance from the localised end pose to the goal (the ground truth is not known)."""
        return math.hypot(self.end_pose[0] - self.goal_m[0], self.end_pose[1] - self.goal_m[1])


@dataclass
class HilNavigationRun:
    """Navigating between points on a serial robot.

    Attributes:
        legs: one per goal driven or refused (the run stops at the first failed leg).
        estimates: (N, 4) t_s, x, y, yaw of the localised pose (map frame) at every tick.
        fixes_accepted, fixes_rejected: hedgehog fixes the filter used and gated out.
        messages: rows written per topic.
        t0_wall_ns: the wall-clock time of the run's start (t_s = 0).
        stopped_because: why the run stopped early ("" if it did not, or was interrupted).
        interruption: the ``KeyboardInterrupt`` (or SIGTERM) that stopped it, to re-raise.
    """

    legs: list[HilLeg]
    estimates: NDArray[np.float64]
    fixes_accepted: int = 0
    fixes_rejected: int = 0
    messages: dict[str, int] = field(default_factory=dict)
    t0_wall_ns: int = 0
    stopped_because: str = ""
    interruption: RunStop | None = None

    @property
    def reached(self) -> bool:
        """Every leg planned and its loop done."""
        return (
            not self.stopped_because
            and self.interruption is None
            and all(
                leg.plan.status == "ok" and leg.control is not None and leg.control.reason == "done"
                for leg in self.legs
            )
        )


def leg_controller(
    choice: str, path_m: NDArray[np.float64], pose: Pose2, tracking_speed_mps: float = 0.2
) -> Any:
    """The controller of a leg, as on the twin (``services.navigation.navigate``): seed 001's
    way-point controller along the path's points, or the holonomic tracker at constant heading."""
    from omnical.control.tracking import TrackingController
    from omnical.control.waypoint import SEED001_AZIMUTH_PID, WaypointController
    from omnical.trajectory.references import waypoints as waypoint_reference

    if choice == "tracking":
        points = [(float(pose[0]), float(pose[1]))]
        points += [(float(x), float(y)) for x, y in path_m[1:]]
        return TrackingController(
            waypoint_reference(
                points, speed_mps=tracking_speed_mps, accel_mps2=0.2, heading_rad=float(pose[2])
            ),
            settle_s=2.0,
        )
    return WaypointController(
        tuple((float(x), float(y)) for x, y in path_m[1:]),
        azimuth_pid=SEED001_AZIMUTH_PID,
        final_tolerance_m=0.01,
    )


def navigate_serial(
    robot: WheeltecRobot,
    hedge: SerialHedgehog,
    sink: RowSink,
    *,
    inflated: InflatedMap,
    roadmap: Roadmap,
    plan_params: PlanParams,
    goals: Sequence[tuple[float, float]],
    choices: Sequence[str],
    start_yaw_rad: float,
    hedge_offset_m: tuple[float, float],
    limits: CommandLimits,
    beacons: BeaconMap,
    margin_m: float = 0.3,
    allowed: Area | None = None,
    fusion: FusionParams | None = None,
    max_leg_s: float = 600.0,
    lead_in_s: float = LEAD_IN_S,
    tail_s: float = 1.0,
    clock: HostClock | None = None,
    abort_key: bool = True,
    on_leg: Callable[[HilLeg], None] | None = None,
) -> HilNavigationRun:
    """Plan and drive each leg on a serial robot, localised by odometry fused with hedgehog fixes.

    The start pose is the hedgehog's mean position over the lead-in (the robot at rest, minus the
    turned hedgehog offset) with the heading ``start_yaw_rad``; from there the filter
    (:class:`~omnical.estimation.fusion.FusedPoseSource`) predicts with the driver's odometry and
    corrects with every new fix. There is no scan matching: no live LiDAR driver exists. Each leg
    is planned from the localised pose, its path checked against the beacon coverage and the
    allowed area (a leg that does not fit stops the run before it moves), and followed by its
    controller (:func:`leg_controller`). The stop flag stops the robot; a silent status stream
    or hedgehog is a safety stop.

    Returns:
        The run; ``interruption`` is set when Ctrl-C / SIGTERM / an abort key / a safety stop
        ended it.
    """
    from omnical.estimation.fusion import FusedPoseSource, FusionParams, initial_pose_from_fixes
    from omnical.navigation.prm import plan

    host = clock if clock is not None else HostClock()
    t0 = host.now_s()
    runner_clock = _MonoClock(t0, host)
    rec = _Recorder(sink, robot, hedge, t0, host)
    params = fusion or FusionParams(hedge_offset_m=hedge_offset_m)
    fixes = HedgeFixSource(hedge, host)
    why: list[str] = []
    legs: list[HilLeg] = []
    logs: list[ControlLog] = []
    fused: FusedPoseSource | None = None
    interruption: RunStop | None = None
    stop_now = _stop_flag(robot, why)
    rec.watch_gaps = False  # required: a silence is a safety stop, not a gap
    robot.require(hedge)

    def tick(_t: float, _output: ControlOutput) -> None:
        rec.maybe_drain()

    try:
        with abort_keys(abort_key):
            at_rest = []
            end = runner_clock.now_s() + lead_in_s
            while runner_clock.now_s() < end:
                robot.send_twist(0.0, 0.0, 0.0)
                at_rest += fixes.poll()
                rec.maybe_drain()
                runner_clock.sleep_until(min(end, runner_clock.now_s() + 0.05))
            at_rest = _inliers(at_rest)
            if len(at_rest) < 3:
                why.append(f"{len(at_rest)} hedgehog fixes in {lead_in_s:.1f} s at rest (need 3)")
            else:
                start = initial_pose_from_fixes(at_rest, start_yaw_rad, params.hedge_offset_m)
                sigma = params.ips_sigma_m / math.sqrt(len(at_rest)) + 0.005
                fused = FusedPoseSource(
                    params,
                    fixes,
                    start,
                    initial_sigma=(sigma, sigma, params.initial_yaw_sigma_rad),
                )
                fused(robot.read_state())
            for goal, choice in zip(goals if fused is not None else (), choices, strict=False):
                assert fused is not None
                here = fused.state.pose
                res = plan(
                    inflated, np.array(here[:2]), np.array(goal), plan_params, roadmap=roadmap
                )
                if res.status != "ok":
                    legs.append(HilLeg(goal, res, None, choice))
                    break
                verdict = check_polyline(
                    res.path_m, beacons, margin_m=margin_m, allowed=allowed,
                    name=f"the leg to ({goal[0]:.2f}, {goal[1]:.2f})",
                )  # fmt: skip
                if not verdict.ok:
                    legs.append(HilLeg(goal, res, None, choice))
                    why.append(f"refused: {verdict.reason}")
                    break
                log = run_controller(
                    leg_controller(choice, res.path_m, here),
                    robot,
                    runner_clock,
                    pose_source=fused,
                    max_duration_s=max_leg_s,
                    limits=limits,
                    emergency_stop=stop_now,
                    on_tick=tick,
                )
                logs.append(log)
                if log.reason == "interrupted":
                    interruption = log.interruption or KeyboardInterrupt()
                    legs.append(HilLeg(goal, res, log, choice, fused.state.pose))
                    break
                _hold(robot, runner_clock, 0.5, rec)
                pose = fused(robot.read_state())
                leg = HilLeg(goal, res, log, choice, pose)
                legs.append(leg)
                if on_leg is not None:
                    on_leg(leg)
                if log.reason != "done":
                    break
            if interruption is None:
                _hold(robot, runner_clock, tail_s, rec)
    except (KeyboardInterrupt, SafetyStopError) as err:  # at rest (lead-in, between legs, tail)
        interruption = err
    finally:
        robot.stop()
        robot.release(hedge)
        rec.drain()
        _write_logs(rec, logs)
    estimates = fused.estimates() if fused is not None else np.zeros((0, 4))
    if len(estimates):
        estimates[:, 0] -= t0
    return HilNavigationRun(
        legs,
        estimates,
        fused.accepted if fused is not None else 0,
        fused.rejected if fused is not None else 0,
        rec.counts,
        rec.wall0_ns,
        "; ".join(why[:1]),
        interruption,
    )


def _write_logs(rec: _Recorder, logs: Sequence[ControlLog]) -> None:
    if not logs:
        return
    cmd = np.vstack([log.cmd_vel for log in logs])
    rec.write_rows("/cmd_vel", cmd[:, 0], vx_mps=cmd[:, 1], vy_mps=cmd[:, 2], wz_radps=cmd[:, 3])
    rec.write_events([e for log in logs for e in log.events])


def _inliers(fixes: list[IpsFix], radius_m: float = 0.1) -> list[IpsFix]:
    """The fixes within ``radius_m`` of their median (an IPS outlier must not move the start)."""
    if not fixes:
        return []
    mx = float(np.median([f.x_m for f in fixes]))
    my = float(np.median([f.y_m for f in fixes]))
    return [f for f in fixes if math.hypot(f.x_m - mx, f.y_m - my) <= radius_m]
