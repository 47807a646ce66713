"""Navigation (seed 001 §4.2.3): a mapping tour with SLAM, and legs between points on the map.

:func:`mapping_tour`, :func:`navigate` (the twin), :func:`navigate_on` (any rig),
:func:`map_from_recording` (``omnical map``), :func:`demo_chapter`; results only, no files.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from omnical.control.limits import DEFAULT_COMMAND_LIMITS, CommandLimits
from omnical.control.loop import ControlLog, ControlOutput, run_controller
from omnical.control.pid import PidParams
from omnical.control.rig_loop import ControlRig, ControlSession, fused_start
from omnical.control.tracking import TrackingController
from omnical.control.waypoint import SEED001_AZIMUTH_PID, WaypointController
from omnical.drivers.safety import PathCheck
from omnical.drivers.watchdog import Watched
from omnical.errors import ConfigError, RecordingError, RunStop, SafetyStopError
from omnical.estimation.fusion import FusedPoseSource, FusionParams
from omnical.estimation.se2 import (
    Pose2,
    between,
    between_poses,
    compose,
    compose_poses,
    interpolate_poses,
)
from omnical.experiment.ports import RobotState
from omnical.experiment.rig import LEAD_IN_S, RowSink
from omnical.navigation.grid import OccupancyGrid
from omnical.navigation.inflation import Footprint, InflatedMap, inflate
from omnical.navigation.map_io import SHIPPED_WORLDS, resolve_world
from omnical.navigation.prm import PlanParams, PlanResult, Roadmap, build_roadmap, plan
from omnical.navigation.raycast import cast_rays
from omnical.navigation.scan_match import MatchParams, likelihood_field, match_scan
from omnical.navigation.slam import SlamParams, SlamResult, run_slam
from omnical.recording.recording import Recording, RecordingBuilder
from omnical.recording.topics import GROUND_TRUTH, ODOM, SCAN
from omnical.robot.description import RobotDescription
from omnical.services.hil import SerialRig
from omnical.trajectory.references import waypoints as waypoint_reference
from omnical.twin.clock import TwinClock
from omnical.twin.lidar import LidarParams, LidarScans, scan_points, simulate_scans
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.record import lidar_params
from omnical.twin.rig import TwinRig, TwinSession
from omnical.twin.simulator import DigitalTwin, TwinLog
from omnical.twin.world import World, load_world

__all__ = [
    "LAB_GOALS",
    "LAB_START",
    "LAB_TOUR",
    "SHIPPED_WORLDS",
    "WAREHOUSE_GOALS",
    "WAREHOUSE_LAP",
    "WAREHOUSE_START",
    "ControllerChoice",
    "MapScore",
    "MappingRun",
    "NavigationChapter",
    "NavigationLeg",
    "NavigationRun",
    "RecordedMap",
    "RigNavigation",
    "demo_chapter",
    "leg_controller",
    "map_from_recording",
    "map_score",
    "mapping_tour",
    "navigate",
    "navigate_on",
    "resolve_world",
    "robot_footprint",
    "robot_world",
]

ControllerChoice = Literal["waypoint", "tracking"]
"""The controller of a leg: seed 001's way-point controller or the holonomic tracker."""

#: The lab tour of the mapping run (world frame, m) and its start pose: one loop around the lab.
LAB_START = (1.0, 1.0, 0.0)
LAB_TOUR = ((6.5, 1.0), (6.8, 3.0), (6.0, 4.0), (4.5, 5.3), (1.0, 4.3), (1.0, 1.0))
#: The demo's three goals on the lab map.
LAB_GOALS = ((6.5, 1.0), (6.0, 4.0), (1.0, 4.3))
#: One lap of the warehouse mapping tour (driven twice) and its start pose: the outer aisles,
#: then the central cross aisle and the aisle at y = 12.5 m.
WAREHOUSE_START = (1.2, 1.2, 0.0)
WAREHOUSE_LAP = (
    (18.2, 1.2),
    (18.2, 18.0),
    (9.5, 17.4),
    (9.5, 12.5),
    (2.0, 12.5),
    (1.2, 1.2),
)
#: Goals of the warehouse navigation benchmark.
WAREHOUSE_GOALS = ((9.5, 9.8), (18.2, 12.3), (4.0, 12.4), (1.2, 1.2))

#: Tracker speed on a leg (chosen): seed 001's 0.1 m/s way-point limit doubled.
TRACKING_SPEED_MPS = 0.2


def robot_footprint(robot: RobotDescription) -> Footprint:
    """The navigation footprint of ``robot`` (its description's rectangle)."""
    return Footprint(robot.footprint.length_m, robot.footprint.width_m)


def robot_world(path: str | Path, robot: RobotDescription) -> World:
    """The floor plan at ``path`` (map_server YAML, or a shipped world's name:
    :func:`resolve_world`) with ``robot``'s footprint."""
    return load_world(resolve_world(path), robot_footprint(robot))


#: Tour speed (chosen): 0.3 m/s, three times seed 001's way-point limit, to keep tours short.
TOUR_DISTANCE_PID = PidParams(kp=0.8, output_min=0.0, output_max=0.3)


@dataclass(frozen=True)
class MapScore:
    """A map against the floor plan (tolerance one cell of 2 cm).

    Attributes:
        occupied_precision: estimated occupied cells within the tolerance of a true occupied cell.
        recall_seen: true surface cells seen from the path (hit by a noiseless beam) within the
            tolerance of an estimated occupied cell.
        free_but_occupied: estimated free cells that are occupied in the floor plan.
    """

    occupied_precision: float
    recall_seen: float
    free_but_occupied: float


def _mask_in(
    grid: OccupancyGrid, mask: NDArray[np.bool_], target: OccupancyGrid
) -> NDArray[np.bool_]:
    """Re-sample a mask of ``grid`` onto the cells of ``target`` (nearest cell centre)."""
    rows, cols = target.shape
    rc = np.indices((rows, cols)).reshape(2, -1).T
    src = grid.world_to_cell(target.cell_to_world(rc))
    inside = grid.in_bounds(src)
    out = np.zeros(rows * cols, dtype=bool)
    out[inside] = mask[src[inside, 0], src[inside, 1]]
    return out.reshape(rows, cols)


def map_score(
    estimated: OccupancyGrid, truth: OccupancyGrid, scans: LidarScans, tolerance_m: float = 0.02
) -> MapScore:
    """Score a map against the floor plan; "seen" surfaces come from noiseless beams of ``scans``."""
    occ = _mask_in(estimated, estimated.occupied, truth)
    free = _mask_in(estimated, estimated.free, truth)
    near_true = (
        ndimage.distance_transform_edt(~truth.occupied) * truth.resolution_m <= tolerance_m + 1e-9
    )
    near_est = ndimage.distance_transform_edt(~occ) * truth.resolution_m <= tolerance_m + 1e-9
    sensor = scans.true_pose
    seen = np.zeros(truth.shape, dtype=bool)
    for k in range(0, len(scans), 5):
        sp = compose_poses(sensor[k], np.asarray(scans.params.mount_pose))
        ang = sp[2] + scans.params.angles_rad
        r = cast_rays(
            truth, np.broadcast_to(sp[:2], (ang.size, 2)), ang, min(scans.params.range_max_m, 6.0)
        )
        ok = np.isfinite(r)
        end = sp[:2] + (r[ok] + 0.5 * truth.resolution_m)[:, None] * np.column_stack(
            [np.cos(ang[ok]), np.sin(ang[ok])]
        )
        rc = truth.world_to_cell(end)
        inside = truth.in_bounds(rc)
        seen[rc[inside, 0], rc[inside, 1]] = True
    seen &= truth.occupied
    precision = float(near_true[occ].mean()) if occ.any() else 0.0
    recall = float(near_est[seen].mean()) if seen.any() else 0.0
    fbo = float(truth.occupied[free].mean()) if free.any() else 0.0
    return MapScore(precision, recall, fbo)


@dataclass(frozen=True, eq=False)
class MappingRun:
    """A mapping tour and its SLAM result.

    Attributes:
        slam: the SLAM result (map in the world frame: the initial pose is the true start).
        scans: the simulated scans (with their true poses).
        twin_log: the twin's logs (odometry, ground truth).
        score: the map against the floor plan.
        trajectory_rmse_m: RMSE of the SLAM positions against the truth at the scans.
        yaw_rmse_rad: RMSE of the SLAM yaw.
        odometry_rmse_m: the same for the raw odometry (for comparison).
        tour_m: (K, 2) the way-points driven.
        slam_time_s: wall time of SLAM.
        slam_cpu_time_s: CPU time of SLAM (this process).
    """

    slam: SlamResult
    scans: LidarScans
    twin_log: TwinLog
    score: MapScore
    trajectory_rmse_m: float
    yaw_rmse_rad: float
    odometry_rmse_m: float
    tour_m: NDArray[np.float64]
    slam_time_s: float
    slam_cpu_time_s: float = math.nan


def _tour_path(
    world: World, start: Pose2, stops: Sequence[tuple[float, float]]
) -> NDArray[np.float64]:
    infl = inflate(world.grid, footprint=world.footprint)
    rm = build_roadmap(infl, PlanParams().prm)
    points = [np.array(start[:2])]
    for stop in stops:
        res = plan(infl, points[-1], np.array(stop), roadmap=rm)
        if res.status != "ok":
            msg = f"tour stop {stop}: {res.status} ({res.reason})"
            raise ValueError(msg)
        points += list(res.path_m[1:])
    return np.array(points)


def mapping_tour(
    world: World,
    robot: RobotDescription,
    params: TwinParams,
    stops: Sequence[tuple[float, float]],
    *,
    lidar: LidarParams | None = None,
    slam: SlamParams | None = None,
    seed: int = 0,
    max_duration_s: float = 1800.0,
) -> MappingRun:
    """Drive a tour through ``stops`` (planned on the floor plan), scan, and run SLAM.

    ``lidar`` is the sensor (default: RPLidar-like) mounted where the robot description says.
    """
    twin = DigitalTwin(robot, params, seed=seed)
    clock = TwinClock(twin)
    start: Pose2 = tuple(float(v) for v in params.start_pose_map)  # type: ignore[assignment]
    tour = _tour_path(world, start, stops)
    local = tuple(between(start, (float(x), float(y), 0.0))[:2] for x, y in tour[1:])
    ctrl = WaypointController(
        local,
        distance_pid=TOUR_DISTANCE_PID,
        max_speed_mps=0.3,
        vicinity_m=0.08,
        final_tolerance_m=0.03,
    )

    def truth(_: RobotState) -> Pose2:
        return between(start, twin.ground_truth_pose)

    twin.advance_to(1.0)
    limits = CommandLimits.from_robot(robot.limits).tightened(DEFAULT_COMMAND_LIMITS)
    run_controller(
        ctrl, twin, clock, pose_source=truth, max_duration_s=max_duration_s, limits=limits
    )
    twin.advance_to(twin.t_s + 1.0)
    log = twin.log()
    lp = lidar_params(robot, lidar)
    scans = simulate_scans(log.ground_truth_t_s, log.ground_truth_pose, world.grid, lp, seed=seed)
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    result = run_slam(
        scans.t_s,
        scans.ranges_m,
        lp.angles_rad,
        log.odom_t_s,
        log.odom_pose,
        mount_pose=lp.mount_pose,
        initial_pose=tuple(scans.true_pose[0]),
        params=slam,
    )
    slam_time = time.perf_counter() - t0
    slam_cpu = time.process_time() - cpu0
    rmse, yaw_rmse = _trajectory_errors(result.poses, scans.true_pose)
    return MappingRun(
        result,
        scans,
        log,
        map_score(result.grid, world.grid, scans),
        rmse,
        yaw_rmse,
        _trajectory_errors(result.odometry_poses, scans.true_pose)[0],
        tour,
        slam_time,
        slam_cpu,
    )


@dataclass(frozen=True, eq=False)
class NavigationLeg:
    """One leg: its plan and how it ended.

    Attributes:
        goal_m: the goal (map frame).
        plan: the leg's plan from the localised pose at its start.
        control: the loop's log (None: not driven).
        goal_error_m: distance of the true pose at rest after the leg to the goal (a twin;
            NaN elsewhere, or not driven).
        controller: "waypoint" or "tracking".
        end_pose: the localised pose (map frame) at rest after the leg (NaN: not driven).
    """

    goal_m: tuple[float, float]
    plan: PlanResult
    control: ControlLog | None
    goal_error_m: float = math.nan
    controller: ControllerChoice = "waypoint"
    end_pose: Pose2 = (math.nan, math.nan, math.nan)

    @property
    def estimated_error_m(self) -> float:
        """Distance from the localised end pose to the goal (what a robot without truth knows)."""
        return math.hypot(self.end_pose[0] - self.goal_m[0], self.end_pose[1] - self.goal_m[1])


def _all_reached(legs: Sequence[NavigationLeg]) -> bool:
    return all(
        leg.plan.status == "ok" and leg.control is not None and leg.control.reason == "done"
        for leg in legs
    )


@dataclass(frozen=True, eq=False)
class NavigationRun:
    """Navigating between points on the twin.

    Attributes:
        legs: one per goal (the run stops at the first failed leg).
        twin_log: the twin's logs (ground truth, odometry).
        estimates: (N, 4) t_s, x, y, yaw of the localised pose at each control tick.
        collision: the first collision of the footprint with the floor plan, or "".
        min_clearance_m: smallest distance from the footprint to an occupied cell (truth).
        inflated: the inflated map the legs were planned on.
        localisation_accepted: fraction of scan matches accepted.
        roadmap: the PRM the legs were planned on.
        start: the start pose (map frame).
    """

    legs: tuple[NavigationLeg, ...]
    twin_log: TwinLog
    estimates: NDArray[np.float64]
    collision: str
    min_clearance_m: float
    inflated: InflatedMap
    localisation_accepted: float = field(default=0.0)
    roadmap: Roadmap | None = None
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def reached(self) -> bool:
        """All goals reached without collision."""
        return not self.collision and _all_reached(self.legs)


@dataclass(frozen=True, eq=False)
class RigNavigation:
    """Navigating between points on any rig (:func:`navigate_on`).

    Attributes:
        legs: one per goal driven or refused (the run stops at the first failed leg).
        estimates: (N, 4) t_s, x, y, yaw of the localised pose (map frame) at every tick.
        accepted, rejected: corrections (scan matches or fixes) used and refused.
        stopped_because: why the rig stopped the run ("" if it did not, or was interrupted).
        interruption: the stop (Ctrl-C, SIGTERM, abort key, safety stop) to re-raise, or None.
        session: the rig's session, after it ended (the twin's log on a twin).
    """

    legs: tuple[NavigationLeg, ...]
    estimates: NDArray[np.float64]
    accepted: int
    rejected: int
    stopped_because: str
    interruption: RunStop | None
    session: ControlSession

    @property
    def reached(self) -> bool:
        """Every leg planned and its loop done, nothing stopped."""
        return not self.stopped_because and self.interruption is None and _all_reached(self.legs)


_ODOM_HISTORY = 200
"""Control ticks of odometry the scan localiser keeps (4 s at 50 Hz): a scan is older than that
only when its LiDAR is dead, which stops the robot."""


def _scaled(step: Pose2, f: float) -> Pose2:
    """The fraction ``f`` of a small pose increment."""
    return (step[0] * f, step[1] * f, step[2] * f)


class _ScanLocaliser:
    """Odometry prediction corrected by scan-to-map matching at the LiDAR rate."""

    def __init__(self, run: ControlSession, map_grid: OccupancyGrid, start: Pose2) -> None:
        self.run = run
        self.field = likelihood_field(map_grid.occupied, map_grid, 0.04)
        self.pose = start
        state = run.robot.read_state()
        self.last_odom = state.odom_pose
        self.period = 1.0 / run.lidar_params().rate_hz
        self.next_scan = state.t_s
        self.odom: deque[tuple[float, Pose2]] = deque(maxlen=_ODOM_HISTORY)
        self.rows: list[tuple[float, float, float, float]] = []
        self.accepted = 0
        self.rejected = 0
        self.params = MatchParams(window_xy_m=0.1, window_yaw_rad=math.radians(3.0))

    def __call__(self, state: RobotState) -> Pose2:
        self.pose = compose(self.pose, between(self.last_odom, state.odom_pose))
        self.last_odom = state.odom_pose
        self.odom.append((state.t_s, state.odom_pose))
        if state.t_s + 1e-9 >= self.next_scan:
            self.next_scan += self.period
            points = scan_points(self.run.scan_now(), self.run.lidar_params())
            # a live scan is matched at the odometry's pose of its rays' time, carried to now
            age = getattr(self.run, "scan_age_s", None)  # a twin scans at the pose now
            then = self._odom_at(state.t_s - age()) if callable(age) else state.odom_pose
            guess = compose(self.pose, between(state.odom_pose, then))
            res = match_scan(self.field, points, guess, self.params)
            if res.accepted:
                self.accepted += 1
                self.pose = compose(res.pose, between(then, state.odom_pose))
            else:
                self.rejected += 1
        self.rows.append((state.t_s, *self.pose))
        return self.pose

    def estimates(self) -> NDArray[np.float64]:
        return np.array(self.rows).reshape(-1, 4)

    def _odom_at(self, t_s: float) -> Pose2:
        """The odometry pose at ``t_s``, interpolated between the ticks around it (the oldest
        or newest kept beyond them)."""
        hist = self.odom
        if t_s <= hist[0][0]:
            return hist[0][1]
        if t_s >= hist[-1][0]:
            return hist[-1][1]
        for (ta, pa), (tb, pb) in itertools.pairwise(reversed(hist)):
            if tb <= t_s:  # reversed: (ta, pa) is the later tick
                f = (t_s - tb) / (ta - tb) if ta > tb else 1.0
                return compose(pb, _scaled(between(pb, pa), f))
        return hist[-1][1]


def leg_controller(
    choice: str,
    path_m: NDArray[np.float64],
    pose: Pose2,
    tracking_speed_mps: float = TRACKING_SPEED_MPS,
) -> WaypointController | TrackingController:
    """The controller of a leg: seed 001's way-point controller along the path's points, or the
    holonomic tracker along them at constant heading (``"tracking"``)."""
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


@contextlib.contextmanager
def _lidar_required(rig: ControlRig, *, on: bool) -> Iterator[None]:
    """While ``on`` (navigating on scan): a live rig's LiDAR that reports its silence (a ROS 2
    robot's ``/scan``) is required by its driver, so a dead LiDAR stops the robot (exit 4)."""
    lidar = rig.lidar if isinstance(rig, SerialRig) else None
    if not on or lidar is None or not callable(getattr(lidar, "silence", None)):
        yield
        return
    assert isinstance(rig, SerialRig)
    watched = cast("Watched", lidar)
    rig.robot.require(watched)
    try:
        yield
    finally:
        rig.robot.release(watched)


LegCheck = Callable[[NDArray[np.float64], tuple[float, float]], PathCheck]
"""A leg's path (map frame) and goal → whether it may be driven (e.g. the beacon coverage)."""


def navigate_on(
    rig: ControlRig,
    sink: RowSink,
    goals: Sequence[tuple[float, float]],
    choices: Sequence[ControllerChoice],
    *,
    inflated: InflatedMap,
    roadmap: Roadmap,
    plan_params: PlanParams,
    limits: CommandLimits,
    start_pose_map: Pose2,
    map_grid: OccupancyGrid | None = None,
    fusion: FusionParams | None = None,
    check_leg: LegCheck | None = None,
    max_leg_s: float = 600.0,
    lead_in_s: float = LEAD_IN_S,
    tail_s: float = 1.0,
    settle_s: float = 0.5,
    on_leg: Callable[[NavigationLeg], None] | None = None,
    on_time: Callable[[float], None] | None = None,
) -> RigNavigation:
    """Plan and drive each leg on ``rig``, recorded into ``sink``; ``on_time(t_s)``: the
    rig's clock at each control tick (a progress display's).

    With ``map_grid`` the pose is the odometry corrected by scan-to-map matching from
    ``start_pose_map`` (a live LiDAR required: silent, it stops the robot); without, the
    odometry fused with the positioning system's fixes from the lead-in at rest. Every leg is
    planned from the localised pose, checked by ``check_leg`` (refused: the run stops before it
    moves) and followed by :func:`leg_controller`; the rig's alarm stops it at once.
    """
    why: list[str] = []
    legs: list[NavigationLeg] = []
    logs: list[ControlLog] = []
    interruption: RunStop | None = None
    loc: _ScanLocaliser | FusedPoseSource | None = None
    with (
        rig.session(sink, require_positions=map_grid is None) as run,
        _lidar_required(rig, on=map_grid is not None),
    ):

        def stop_now(_t: float) -> bool:
            if not why:
                alarm = run.alarm()
                if alarm:
                    why.append(alarm)
            return bool(why)

        def tick(_t: float, _output: ControlOutput) -> None:
            run.poll()
            if on_time is not None:
                on_time(run.clock.now_s())

        try:
            if map_grid is not None:
                run.hold(lead_in_s)
                loc = _ScanLocaliser(run, map_grid, start_pose_map)
            else:
                if fusion is None:
                    msg = "navigating on fixes needs the fusion parameters (the hedgehog offset)"
                    raise ConfigError(msg)
                steps = max(1, round(lead_in_s * 20.0))
                start = fused_start(run, fusion, start_pose_map[2], lead_in_s, steps=steps)
                if isinstance(start, str):
                    why.append(start)
                else:
                    loc = start
            for goal, choice in zip(goals if loc is not None else (), choices, strict=False):
                assert loc is not None
                here = loc.pose if isinstance(loc, _ScanLocaliser) else loc.state.pose
                res = plan(
                    inflated, np.array(here[:2]), np.array(goal), plan_params, roadmap=roadmap
                )
                if res.status != "ok":
                    legs.append(NavigationLeg(goal, res, None, controller=choice))
                    break
                verdict = check_leg(res.path_m, goal) if check_leg is not None else None
                if verdict is not None and not verdict.ok:
                    legs.append(NavigationLeg(goal, res, None, controller=choice))
                    why.append(f"refused: {verdict.reason}")
                    break
                ctrl: Any = leg_controller(choice, res.path_m, here)
                log = run_controller(
                    ctrl,
                    run.robot,
                    run.clock,
                    pose_source=loc,
                    max_duration_s=max_leg_s,
                    limits=limits,
                    emergency_stop=stop_now,
                    on_tick=tick,
                )
                logs.append(log)
                if log.reason == "interrupted":
                    interruption = log.interruption or KeyboardInterrupt()
                    legs.append(NavigationLeg(goal, res, log, controller=choice))
                    break
                run.hold(settle_s)
                end = loc(run.robot.read_state())
                truth = run.ground_truth()
                error = math.nan
                if truth is not None and len(truth):
                    error = math.hypot(truth[-1, 1] - goal[0], truth[-1, 2] - goal[1])
                leg = NavigationLeg(goal, res, log, error, choice, end)
                legs.append(leg)
                if on_leg is not None:
                    on_leg(leg)
                if why or log.reason != "done":
                    break
            if interruption is None:
                run.hold(tail_s)
        except (KeyboardInterrupt, SafetyStopError) as err:  # at rest: lead-in, settling, tail
            interruption = err
        finally:  # whatever ended the run, what it commanded is recorded with what it sensed
            cmd = np.vstack([log.cmd_vel for log in logs]) if logs else np.zeros((0, 4))
            run.finish(cmd, [e for log in logs for e in log.events])
    return RigNavigation(
        tuple(legs),
        loc.estimates() if loc is not None else np.zeros((0, 4)),
        loc.accepted if loc is not None else 0,
        loc.rejected if loc is not None else 0,
        "; ".join(why[:1]),
        interruption,
        run,
    )


def navigate(
    world: World,
    map_grid: OccupancyGrid,
    robot: RobotDescription,
    params: TwinParams,
    goals: Sequence[tuple[float, float]],
    *,
    lidar: LidarParams | None = None,
    plan_params: PlanParams | None = None,
    seed: int = 0,
    max_leg_s: float = 600.0,
    controller: ControllerChoice | Sequence[ControllerChoice] = "waypoint",
    sink: RowSink | None = None,
    on_time: Callable[[float], None] | None = None,
) -> NavigationRun:
    """Navigate on the twin from ``params.start_pose_map`` through ``goals`` on ``map_grid`` in
    ``world`` (:func:`navigate_on` by scan matching; a collision stops the run).

    ``controller``: one :data:`ControllerChoice` for every leg or one per goal. With ``sink``
    the run is recorded there (the twin's topics and ``/scan``); ``on_time(t_s)``: the twin's
    time at each control tick.

    Raises:
        ConfigError: a controller name is unknown, or there are not as many choices as goals.
    """
    choices = _controller_choices(controller, len(goals))
    start: Pose2 = (
        float(params.start_pose_map[0]),
        float(params.start_pose_map[1]),
        float(params.start_pose_map[2]),
    )
    infl = inflate(map_grid, footprint=world.footprint)
    pp = plan_params or PlanParams()
    roadmap = build_roadmap(infl, pp.prm)
    rig = TwinRig(
        robot, params, seed=seed, world=world, lidar=lidar, stop_on_collision=True,
        record_sensors=sink is not None,
    )  # fmt: skip
    nav = navigate_on(
        rig,
        sink if sink is not None else RecordingBuilder(),
        goals,
        choices,
        inflated=infl,
        roadmap=roadmap,
        plan_params=pp,
        limits=CommandLimits.from_robot(robot.limits).tightened(DEFAULT_COMMAND_LIMITS),
        start_pose_map=start,
        map_grid=map_grid,
        max_leg_s=max_leg_s,
        lead_in_s=0.0,
        tail_s=0.0,
        on_time=on_time,
    )
    if nav.interruption is not None:
        raise nav.interruption
    session = nav.session
    assert isinstance(session, TwinSession)
    tlog = session.twin.log()
    return NavigationRun(
        nav.legs,
        tlog,
        nav.estimates,
        nav.stopped_because,
        world.min_clearance_m(tlog.ground_truth_pose[::5]),
        infl,
        nav.accepted / max(nav.accepted + nav.rejected, 1),
        roadmap,
        start,
    )


def _controller_choices(
    controller: ControllerChoice | Sequence[ControllerChoice], goals: int
) -> list[ControllerChoice]:
    choices: list[ControllerChoice] = (
        [controller] * goals if isinstance(controller, str) else list(controller)
    )
    if len(choices) != goals:
        msg = f"navigate: {len(choices)} controller choices for {goals} goals (give one or one per goal)"
        raise ConfigError(msg)
    for c in choices:
        if c not in ("waypoint", "tracking"):
            msg = f"navigate: unknown controller {c!r}; use waypoint or tracking"
            raise ConfigError(msg)
    return choices


@dataclass(frozen=True, eq=False)
class RecordedMap:
    """SLAM on a recording (what ``omnical map`` computes).

    Attributes:
        slam: the SLAM result (map in the frame of ``initial_pose``, or of the first pose).
        scan_t_ns: (M,) bag times of the scans.
        ranges_m: (M, B) the ranges used.
        angles_rad: (B,) the beam angles (sensor frame).
        mount_pose: the LiDAR in base_link.
        truth: (M, 3) ``/ground_truth`` at the scans in the map frame (its first pose taken as the
            map's start), or None without ground truth.
        trajectory_rmse_m, yaw_rmse_rad: the SLAM poses against ``truth`` (NaN without it).
        odometry_rmse_m: the raw odometry against ``truth`` (NaN without it).
        slam_time_s: wall time of SLAM.
    """

    slam: SlamResult
    scan_t_ns: NDArray[np.int64]
    ranges_m: NDArray[np.float64]
    angles_rad: NDArray[np.float64]
    mount_pose: tuple[float, float, float]
    truth: NDArray[np.float64] | None
    trajectory_rmse_m: float
    yaw_rmse_rad: float
    odometry_rmse_m: float
    slam_time_s: float


def _trajectory_errors(est: NDArray[np.float64], truth: NDArray[np.float64]) -> tuple[float, float]:
    err = est[:, :2] - truth[:, :2]
    yaw = np.remainder(est[:, 2] - truth[:, 2] + np.pi, 2 * np.pi) - np.pi
    return float(np.sqrt((err**2).sum(axis=1).mean())), float(np.sqrt((yaw**2).mean()))


def map_from_recording(
    recording: Recording,
    *,
    initial_pose: tuple[float, float, float] | None = None,
    mount_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    params: SlamParams | None = None,
) -> RecordedMap:
    """SLAM on the ``/scan`` and ``/odom`` of ``recording``.

    Args:
        recording: holds ``/scan`` (LaserScan, one beam count) and ``/odom``.
        initial_pose: the robot's pose at the first scan in the map frame wanted (on the twin:
            the world's); None = the map is in the frame of the first pose.
        mount_pose: the LiDAR in base_link (the robot description's ``lidar``).
        params: SLAM settings.

    Raises:
        RecordingError: the recording lacks ``/scan`` or ``/odom``.
        ConfigError: too few scans or odometry samples.
    """
    for topic in (SCAN, ODOM):
        if not recording.has(topic):
            msg = f"recording has no {topic} (topics: {', '.join(recording.topics) or 'none'})"
            raise RecordingError(msg)
    scan = recording.topic(SCAN)
    odom = recording.topic(ODOM)
    t0 = int(scan.t_ns[0])
    ranges = np.asarray(scan["ranges_m"], dtype=np.float64)
    angle_min = float(scan["angle_min_rad"][0])
    increment = float(scan["angle_increment_rad"][0])
    angles = np.asarray(angle_min + increment * np.arange(ranges.shape[1]), dtype=np.float64)
    odom_pose = np.column_stack([odom["x_m"], odom["y_m"], odom["yaw_rad"]])
    start = time.perf_counter()
    result = run_slam(
        scan.t_s(t0),
        ranges,
        angles,
        odom.t_s(t0),
        odom_pose,
        mount_pose=mount_pose,
        initial_pose=initial_pose,
        params=params,
    )
    elapsed = time.perf_counter() - start
    truth: NDArray[np.float64] | None = None
    rmse = yaw_rmse = odo_rmse = math.nan
    if recording.has(GROUND_TRUTH):
        gt = recording.topic(GROUND_TRUTH)
        gt_pose = np.column_stack([gt["x_m"], gt["y_m"], gt["yaw_rad"]])
        at = interpolate_poses(gt.t_s(t0), gt_pose, scan.t_s(t0))
        origin = np.asarray(initial_pose if initial_pose is not None else (0.0, 0.0, 0.0))
        truth = compose_poses(origin, between_poses(at[0], at))
        rmse, yaw_rmse = _trajectory_errors(result.poses, truth)
        odo_rmse, _ = _trajectory_errors(result.odometry_poses, truth)
    return RecordedMap(
        result,
        np.asarray(scan.t_ns, dtype=np.int64),
        ranges,
        angles,
        mount_pose,
        truth,
        rmse,
        yaw_rmse,
        odo_rmse,
        elapsed,
    )


@dataclass(frozen=True, eq=False)
class NavigationChapter:
    """The demo's navigation chapter: a mapping tour, the map, navigating to goals on it.

    Attributes:
        world_name: the floor plan's name.
        world: the floor plan (with the robot's footprint).
        mapping: the mapping tour and its SLAM result (map in the world frame).
        navigation: navigating between the goals on the SLAM map.
        goals: the goals (world frame).
        controllers: the controller of each leg.
        elapsed_s: wall time of the chapter.
    """

    world_name: str
    world: World
    mapping: MappingRun
    navigation: NavigationRun
    goals: tuple[tuple[float, float], ...]
    controllers: tuple[ControllerChoice, ...]
    elapsed_s: float


def _default_lab() -> Path:
    """``lab-8x6.yaml``, shipped in ``omnical/data/worlds``."""
    return resolve_world("lab-8x6")


def demo_chapter(
    seed: int = 0,
    *,
    world_yaml: str | Path | None = None,
    robot: RobotDescription | None = None,
    controllers: Sequence[ControllerChoice] = ("waypoint", "tracking", "waypoint"),
) -> NavigationChapter:
    """The demo's navigation chapter on ``lab-8x6``: the mapping tour of :data:`LAB_TOUR` on the
    uncalibrated twin, SLAM, then :data:`LAB_GOALS` on the SLAM map (the middle leg tracked)."""
    from omnical.robot.loader import load_robot

    began = time.perf_counter()
    description = robot or load_robot("rosy-mecanum")
    path = Path(world_yaml) if world_yaml is not None else _default_lab()
    world = robot_world(path, description)
    params = replace(default_twin(description), start_pose_map=LAB_START)
    mapping = mapping_tour(world, description, params, LAB_TOUR, seed=seed)
    nav = navigate(
        world, mapping.slam.grid, description, params, LAB_GOALS, seed=seed, controller=controllers
    )
    return NavigationChapter(
        path.stem,
        world,
        mapping,
        nav,
        LAB_GOALS,
        tuple(controllers),
        time.perf_counter() - began,
    )
