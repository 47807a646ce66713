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
from omnical.control.loop import ControlLog, ControlOutput, run_controller
from omnical.drivers.hedgehog import SerialHedgehog
from omnical.drivers.safety import Area, PathCheck, check_points
from omnical.drivers.wheeltec_serial import WheeltecRobot
from omnical.errors import RunStop, SafetyStopError
from omnical.estimation.fusion import IpsFix
from omnical.estimation.se2 import Pose2, transform_points
from omnical.experiment.rig import LEAD_IN_S, RowSink
from omnical.ips.beacons import BeaconMap
from omnical.services.hil import (
    HedgeFixSource,
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

__all__ = [
    "HilLeg",
    "HilNavigationRun",
    "check_polyline",
    "check_task_path",
    "leg_controller",
    "navigate_serial",
]

StateT = TypeVar("StateT")

TASK_TAIL_S = 2.0
"""Standing time recorded after the loop stops (as ``closed_loop_run`` on the twin)."""


def _stop_flag(robot: WheeltecRobot, why: list[str]) -> Callable[[float], bool]:
    """The loops' emergency stop: the controller's stop flag (the reason appended to ``why``)."""

    def stop_now(_t: float) -> bool:
        if robot.read_state().stop_flag:
            why.append("the controller raised its stop flag (E-stop or low battery)")
        return bool(why)

    return stop_now


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


# ----------------------------------------------------------------------------- navigation


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
