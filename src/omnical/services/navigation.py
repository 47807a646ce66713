"""Navigation on the twin (seed 001 §4.2.3): a mapping tour with SLAM, and navigating between
points on the map with scan-to-map localisation; results only, no files.

- :func:`mapping_tour`: drive a tour through a floor plan (the "manual navigation" of seed 001
  Fig. 12, here seed 001's way-point controller on the true pose, as a driver who sees the robot),
  record odometry and LiDAR scans, run SLAM, and score the map against the floor plan.
- :func:`navigate`: plan each leg on the map (PRM, A* fallback), follow it with seed 001's
  way-point controller closing the loop on a pose that the odometry predicts and scan-to-map
  matching corrects, and check the footprint against the floor plan on the ground truth (a
  collision stops the run with a message).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from omnical.control.limits import DEFAULT_COMMAND_LIMITS, CommandLimits
from omnical.control.loop import ControlLog, run_controller
from omnical.control.pid import PidParams
from omnical.control.waypoint import SEED001_AZIMUTH_PID, WaypointController
from omnical.estimation.se2 import Pose2, between, compose
from omnical.experiment.ports import RobotState
from omnical.navigation.grid import OccupancyGrid
from omnical.navigation.inflation import InflatedMap, inflate
from omnical.navigation.prm import PlanParams, PlanResult, build_roadmap, plan
from omnical.navigation.raycast import cast_rays
from omnical.navigation.scan_match import MatchParams, likelihood_field, match_scan
from omnical.navigation.slam import SlamParams, SlamResult, run_slam
from omnical.robot.description import RobotDescription
from omnical.twin.clock import TwinClock
from omnical.twin.lidar import Lidar, LidarParams, LidarScans, scan_points, simulate_scans
from omnical.twin.params import TwinParams
from omnical.twin.simulator import DigitalTwin, TwinLog
from omnical.twin.world import World

__all__ = [
    "MapScore",
    "MappingRun",
    "NavigationLeg",
    "NavigationRun",
    "map_score",
    "mapping_tour",
    "navigate",
]

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
    lid = Lidar(truth, scans.params)
    sensor = scans.true_pose
    seen = np.zeros(truth.shape, dtype=bool)
    for k in range(0, len(scans), 5):
        from omnical.estimation.se2 import compose_poses

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
    del lid
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
    """Drive a tour through ``stops`` (planned on the floor plan), scan, and run SLAM."""
    import time

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
    lp = lidar or LidarParams()
    scans = simulate_scans(log.ground_truth_t_s, log.ground_truth_pose, world.grid, lp, seed=seed)
    t0 = time.perf_counter()
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
    err = result.poses[:, :2] - scans.true_pose[:, :2]
    yaw_err = np.remainder(result.poses[:, 2] - scans.true_pose[:, 2] + np.pi, 2 * np.pi) - np.pi
    odo_err = result.odometry_poses[:, :2] - scans.true_pose[:, :2]
    return MappingRun(
        result,
        scans,
        log,
        map_score(result.grid, world.grid, scans),
        float(np.sqrt((err**2).sum(axis=1).mean())),
        float(np.sqrt((yaw_err**2).mean())),
        float(np.sqrt((odo_err**2).sum(axis=1).mean())),
        tour,
        slam_time,
    )


@dataclass(frozen=True, eq=False)
class NavigationLeg:
    """One leg: its plan and how it ended."""

    goal_m: tuple[float, float]
    plan: PlanResult
    control: ControlLog | None
    goal_error_m: float


@dataclass(frozen=True, eq=False)
class NavigationRun:
    """Navigating between points.

    Attributes:
        legs: one per goal (the run stops at the first failed leg).
        twin_log: the twin's logs (ground truth, odometry).
        estimates: (N, 4) t_s, x, y, yaw of the localised pose at each control tick.
        collision: the first collision of the footprint with the floor plan, or "".
        min_clearance_m: smallest distance from the footprint to an occupied cell (truth).
        inflated: the inflated map the legs were planned on.
        localisation_accepted: fraction of scan matches accepted.
    """

    legs: tuple[NavigationLeg, ...]
    twin_log: TwinLog
    estimates: NDArray[np.float64]
    collision: str
    min_clearance_m: float
    inflated: InflatedMap
    localisation_accepted: float = field(default=0.0)

    @property
    def reached(self) -> bool:
        """All goals reached without collision."""
        return not self.collision and all(
            leg.plan.status == "ok" and leg.control is not None and leg.control.reason == "done"
            for leg in self.legs
        )


class _Localiser:
    """Odometry prediction corrected by scan-to-map matching at the LiDAR rate."""

    def __init__(
        self, twin: DigitalTwin, lidar: Lidar, map_grid: OccupancyGrid, start: Pose2, rate_hz: float
    ) -> None:
        self.twin, self.lidar = twin, lidar
        self.field = likelihood_field(map_grid.occupied, map_grid, 0.04)
        self.pose = start
        self.last_odom = twin.read_state().odom_pose
        self.period = 1.0 / lidar.params.rate_hz
        self.next_scan = twin.t_s
        self.rows: list[tuple[float, float, float, float]] = []
        self.matches = 0
        self.accepted = 0
        self.params = MatchParams(window_xy_m=0.1, window_yaw_rad=math.radians(3.0))

    def __call__(self, state: RobotState) -> Pose2:
        self.pose = compose(self.pose, between(self.last_odom, state.odom_pose))
        self.last_odom = state.odom_pose
        if self.twin.t_s + 1e-9 >= self.next_scan:
            self.next_scan += self.period
            ranges = self.lidar.scan(np.asarray(self.twin.ground_truth_pose))
            res = match_scan(
                self.field, scan_points(ranges, self.lidar.params), self.pose, self.params
            )
            self.matches += 1
            if res.accepted:
                self.accepted += 1
                self.pose = res.pose
        self.rows.append((self.twin.t_s, *self.pose))
        return self.pose


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
) -> NavigationRun:
    """Navigate from ``params.start_pose_map`` through ``goals`` on ``map_grid`` in ``world``.

    The start pose is known (as seed 001's robot starts at a known map pose); from there the
    pose is the odometry corrected by scan-to-map matching. Every leg is planned from the
    localised pose and followed with seed 001's way-point controller (differential-style: turn,
    then drive), which suits a path of straight segments.
    """
    twin = DigitalTwin(robot, params, seed=seed)
    clock = TwinClock(twin)
    start: Pose2 = tuple(float(v) for v in params.start_pose_map)  # type: ignore[assignment]
    lp = lidar or LidarParams()
    lid = Lidar(world.grid, lp, seed)
    infl = inflate(map_grid, footprint=world.footprint)
    pp = plan_params or PlanParams()
    roadmap = build_roadmap(infl, pp.prm)
    loc = _Localiser(twin, lid, map_grid, start, lp.rate_hz)
    collision = ""

    def stop_on_collision(_: float) -> bool:
        nonlocal collision
        if not collision:
            collision = world.collision_message(twin.ground_truth_pose)
        return bool(collision)

    limits = CommandLimits.from_robot(robot.limits).tightened(DEFAULT_COMMAND_LIMITS)
    legs: list[NavigationLeg] = []
    for goal in goals:
        here = np.array(loc.pose[:2])
        res = plan(infl, here, np.array(goal), pp, roadmap=roadmap)
        if res.status != "ok":
            legs.append(NavigationLeg(goal, res, None, math.nan))
            break
        ctrl = WaypointController(
            tuple((float(x), float(y)) for x, y in res.path_m[1:]),
            azimuth_pid=SEED001_AZIMUTH_PID,
            final_tolerance_m=0.01,
        )
        log = run_controller(
            ctrl,
            twin,
            clock,
            pose_source=loc,
            max_duration_s=max_leg_s,
            limits=limits,
            emergency_stop=stop_on_collision,
        )
        twin.advance_to(twin.t_s + 0.5)
        gt = twin.ground_truth_pose
        legs.append(NavigationLeg(goal, res, log, math.hypot(gt[0] - goal[0], gt[1] - goal[1])))
        if collision or log.reason != "done":
            break
    tlog = twin.log()
    clearance = world.min_clearance_m(tlog.ground_truth_pose[::5])
    return NavigationRun(
        tuple(legs),
        tlog,
        np.array(loc.rows).reshape(-1, 4),
        collision,
        clearance,
        infl,
        loc.accepted / max(loc.matches, 1),
    )
