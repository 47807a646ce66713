"""2D LiDAR SLAM (seed 001 §4.2.3): scan-to-map matching, keyframes, loop closures, a pose graph.

:func:`run_slam` matches each scan from its odometry prediction, keeps keyframes, closes loops in a
gtsam graph and builds a log-odds map from every scan at the optimised poses.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError
from omnical.estimation.se2 import (
    between,
    between_poses,
    compose,
    compose_poses,
    interpolate_poses,
)
from omnical.navigation.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from omnical.navigation.pose_graph import PoseEdge, optimize_pose_graph
from omnical.navigation.scan_match import (
    MatchParams,
    PointMap,
    likelihood_field_window,
    match_scan,
    point_map,
    point_normals,
    refine_point_to_line,
)

__all__ = ["LogOddsMap", "SlamParams", "SlamResult", "run_slam", "scan_points_sensor"]

_L_OCC = math.log(0.65 / 0.35)
_L_FREE = math.log(0.196 / 0.804)


@numba.njit(cache=True)
def _integrate(
    logodds: NDArray[np.float32],
    sx: float,
    sy: float,
    ex: NDArray[np.float64],
    ey: NDArray[np.float64],
    hit: NDArray[np.bool_],
    l_hit: float,
    l_miss: float,
    l_min: float,
    l_max: float,
) -> None:
    rows, cols = logodds.shape
    for k in range(ex.shape[0]):
        gx, gy = sx, sy
        dx, dy = ex[k] - sx, ey[k] - sy
        length = math.hypot(dx, dy)
        if length < 1e-9:
            continue
        dx /= length
        dy /= length
        ix = math.floor(gx)
        iy = math.floor(gy)
        tx_ = math.floor(ex[k])
        ty_ = math.floor(ey[k])
        if dx > 0:
            stx, tmx, tdx = 1, (ix + 1.0 - gx) / dx, 1.0 / dx
        elif dx < 0:
            stx, tmx, tdx = -1, (gx - ix) / -dx, -1.0 / dx
        else:
            stx, tmx, tdx = 0, math.inf, math.inf
        if dy > 0:
            sty, tmy, tdy = 1, (iy + 1.0 - gy) / dy, 1.0 / dy
        elif dy < 0:
            sty, tmy, tdy = -1, (gy - iy) / -dy, -1.0 / dy
        else:
            sty, tmy, tdy = 0, math.inf, math.inf
        while True:
            if ix == tx_ and iy == ty_:
                break
            if 0 <= ix < cols and 0 <= iy < rows:
                v = logodds[iy, ix] + l_miss
                logodds[iy, ix] = max(v, l_min)
            if tmx < tmy:
                if tmx > length:
                    break
                ix += stx
                tmx += tdx
            else:
                if tmy > length:
                    break
                iy += sty
                tmy += tdy
        if hit[k] and 0 <= tx_ < cols and 0 <= ty_ < rows:
            v = logodds[ty_, tx_] + l_hit
            logodds[ty_, tx_] = min(v, l_max)


def scan_points_sensor(
    ranges_m: NDArray[np.float64], angles_rad: NDArray[np.float64], max_range_m: float
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """(P, 2) beam end points in the sensor frame and whether each is a hit.

    Returns within ``max_range_m`` are hits; longer returns and ``+inf`` (no return) clear space
    up to ``max_range_m``; NaN (dropouts) and ``-inf`` (too close, REP 117) are skipped.
    """
    r = np.asarray(ranges_m, dtype=np.float64)
    keep = ~np.isnan(r) & (r > 0.0)
    hit = keep & (r <= max_range_m)
    rr = np.where(hit, r, max_range_m)[keep]
    a = angles_rad[keep]
    return np.column_stack([rr * np.cos(a), rr * np.sin(a)]), hit[keep]


@dataclass
class LogOddsMap:
    """A log-odds occupancy grid being built (mutable; :meth:`to_grid` gives the trinary map)."""

    logodds: NDArray[np.float32]
    resolution_m: float
    origin_xy_m: tuple[float, float]
    l_hit: float = 0.9
    l_miss: float = -0.4
    l_min: float = -4.0
    l_max: float = 4.0

    @classmethod
    def covering(
        cls, xy_min: NDArray[np.float64], xy_max: NDArray[np.float64], resolution_m: float
    ) -> LogOddsMap:
        """An empty map covering the box (snapped to whole cells)."""
        lo = np.floor(xy_min / resolution_m) * resolution_m
        cols = math.ceil((xy_max[0] - lo[0]) / resolution_m) + 1
        rows = math.ceil((xy_max[1] - lo[1]) / resolution_m) + 1
        return cls(
            np.zeros((rows, cols), dtype=np.float32), resolution_m, (float(lo[0]), float(lo[1]))
        )

    def geometry(self) -> OccupancyGrid:
        """An all-unknown grid with this map's geometry."""
        return OccupancyGrid(
            np.full(self.logodds.shape, UNKNOWN, dtype=np.int8),
            self.resolution_m,
            (self.origin_xy_m[0], self.origin_xy_m[1], 0.0),
        )

    def integrate(
        self,
        sensor_pose: tuple[float, float, float],
        end_sensor: NDArray[np.float64],
        hit: NDArray[np.bool_],
    ) -> None:
        """Integrate one scan taken from ``sensor_pose`` (world) with end points in the sensor frame."""
        world = compose_poses(
            np.asarray(sensor_pose), np.column_stack([end_sensor, np.zeros(len(end_sensor))])
        )
        res, (ox, oy) = self.resolution_m, self.origin_xy_m
        _integrate(
            self.logodds,
            (sensor_pose[0] - ox) / res,
            (sensor_pose[1] - oy) / res,
            np.ascontiguousarray((world[:, 0] - ox) / res),
            np.ascontiguousarray((world[:, 1] - oy) / res),
            np.ascontiguousarray(hit),
            self.l_hit,
            self.l_miss,
            self.l_min,
            self.l_max,
        )

    def occupied(self) -> NDArray[np.bool_]:
        """Cells with p > 0.65."""
        return np.asarray(self.logodds > _L_OCC)

    def to_grid(self) -> OccupancyGrid:
        """The trinary map (p > 0.65 occupied, p < 0.196 free, otherwise unknown)."""
        cells = np.full(self.logodds.shape, UNKNOWN, dtype=np.int8)
        cells[self.logodds < _L_FREE] = FREE
        cells[self.logodds > _L_OCC] = OCCUPIED
        return OccupancyGrid(
            cells, self.resolution_m, (self.origin_xy_m[0], self.origin_xy_m[1], 0.0)
        )


@dataclass(frozen=True)
class SlamParams:
    """SLAM settings.

    Attributes:
        resolution_m: map cell (seed 001: 2 cm).
        max_range_m: returns beyond are not used as hits (seed 001: 4 m of a 12 m sensor).
        keyframe_distance_m, keyframe_yaw_rad: motion that makes a new keyframe.
        match: the scan matcher of every scan (the odometry prediction as its prior).
        loop_match: the wider matcher of loop closures.
        loop_radius_m: older keyframes within this distance are loop candidates.
        loop_min_separation: a candidate must be at least this many keyframes back.
        loop_min_score: minimum score of an accepted loop closure.
        field_sigma_m: σ of the likelihood field.
        odometry_sigmas: σ (x, y, yaw) of a sequential edge.
        loop_sigmas: σ (x, y, yaw) of a loop-closure edge.
        refine_keyframes: an accepted match is refined by point-to-line ICP on the points of
            the nearest keyframes (at most this many within ``max_range_m``; 0 = no refinement).
        refine_max_distance_m: farthest pairing of that refinement.
    """

    resolution_m: float = 0.02
    max_range_m: float = 6.0
    keyframe_distance_m: float = 0.25
    keyframe_yaw_rad: float = math.radians(10.0)
    match: MatchParams = field(
        default_factory=lambda: MatchParams(
            prior_sigma_xy_m=0.1, prior_sigma_yaw_rad=math.radians(5.0)
        )
    )
    loop_match: MatchParams = field(
        default_factory=lambda: MatchParams(
            window_xy_m=0.3, window_yaw_rad=math.radians(6.0), min_score=0.5
        )
    )
    loop_radius_m: float = 1.5
    loop_min_separation: int = 30
    loop_min_score: float = 0.6
    field_sigma_m: float = 0.04
    odometry_sigmas: tuple[float, float, float] = (0.01, 0.01, 0.003)
    loop_sigmas: tuple[float, float, float] = (0.03, 0.03, 0.01)
    refine_keyframes: int = 40
    refine_max_distance_m: float = 0.08


@dataclass(frozen=True, eq=False)
class SlamResult:
    """What SLAM produced.

    Attributes:
        grid: the trinary occupancy map (world = the frame of the initial pose).
        t_s: (M,) scan times.
        poses: (M, 3) estimated base_link pose at each scan (after the pose graph).
        front_end_poses: (M, 3) the front end's poses (before the pose graph).
        odometry_poses: (M, 3) the odometry at each scan, in the map frame.
        keyframes: (K,) scan index of each keyframe.
        loop_closures: (L, 2) keyframe pairs (older, newer) with an accepted loop closure.
        accepted: (M,) the scan's match was accepted.
        degenerate: (M,) the scan's match was degenerate (kept the odometry prediction).
        graph_time_s: time spent in the pose-graph optimisation.
    """

    grid: OccupancyGrid
    t_s: NDArray[np.float64]
    poses: NDArray[np.float64]
    front_end_poses: NDArray[np.float64]
    odometry_poses: NDArray[np.float64]
    keyframes: NDArray[np.int64]
    loop_closures: NDArray[np.int64]
    accepted: NDArray[np.bool_]
    degenerate: NDArray[np.bool_]
    graph_time_s: float


def run_slam(
    scan_t_s: ArrayLike,
    ranges_m: ArrayLike,
    angles_rad: ArrayLike,
    odom_t_s: ArrayLike,
    odom_poses: ArrayLike,
    *,
    mount_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    initial_pose: tuple[float, float, float] | None = None,
    params: SlamParams | None = None,
) -> SlamResult:
    """Build a map and the trajectory from scans and wheel odometry.

    Args:
        scan_t_s: (M,) scan times.
        ranges_m: (M, B) ranges (NaN dropouts, inf no return).
        angles_rad: (B,) beam angles in the sensor frame.
        odom_t_s, odom_poses: wheel odometry (N,), (N, 3) in the odometry frame.
        mount_pose: the sensor in base_link.
        initial_pose: pose of the robot at the first scan in the map frame (None = the origin:
            the map is in the frame of the first pose).
        params: settings.

    Raises:
        ConfigError: no scans, mismatched shapes, or odometry not covering the scans.
    """
    p = params or SlamParams()
    t = np.asarray(scan_t_s, dtype=np.float64)
    ranges = np.asarray(ranges_m, dtype=np.float64)
    angles = np.asarray(angles_rad, dtype=np.float64)
    ot = np.asarray(odom_t_s, dtype=np.float64)
    op = np.asarray(odom_poses, dtype=np.float64)
    if t.shape[0] < 1 or ranges.shape != (t.shape[0], angles.shape[0]):
        msg = f"SLAM: need (M, B) ranges for M scan times and B angles, got {ranges.shape}, {t.shape}, {angles.shape}"
        raise ConfigError(msg)
    if ot.shape[0] < 2:
        msg = "SLAM: need at least two odometry samples"
        raise ConfigError(msg)
    odom = interpolate_poses(ot, op, t)
    start = initial_pose if initial_pose is not None else (0.0, 0.0, 0.0)
    # odometry in the map frame (for the map's extent and the predictions)
    odom_map = compose_poses(np.asarray(start), between_poses(odom[0], odom))
    margin = p.max_range_m + 1.0
    lmap = LogOddsMap.covering(
        odom_map[:, :2].min(axis=0) - margin, odom_map[:, :2].max(axis=0) + margin, p.resolution_m
    )
    geometry = lmap.geometry()
    mount = tuple(float(v) for v in mount_pose)
    m = t.shape[0]
    est = np.empty((m, 3))
    accepted = np.zeros(m, dtype=bool)
    degenerate = np.zeros(m, dtype=bool)
    sensor_pts = [scan_points_sensor(ranges[k], angles, p.max_range_m) for k in range(m)]
    base_hits = []
    for k in range(m):
        pts, hit = sensor_pts[k]
        base = compose_poses(
            np.asarray(mount), np.column_stack([pts[hit], np.zeros(int(hit.sum()))])
        )[:, :2]
        base_hits.append(base)
    keyframes: list[int] = [0]
    est[0] = start
    lmap.integrate(compose(tuple(est[0]), mount), *sensor_pts[0])  # type: ignore[arg-type]
    # the front end's field: a window around the newest keyframe, recomputed per keyframe
    half_m = p.max_range_m + p.match.window_xy_m + 2.0 * p.keyframe_distance_m
    lf = likelihood_field_window(
        lmap.occupied(), geometry, p.field_sigma_m, (est[0, 0], est[0, 1]), half_m
    )
    loops: list[tuple[int, int]] = []
    loop_edges: list[PoseEdge] = []
    clouds: dict[int, _Cloud] = {}
    pm = _keyframe_points(p, est, keyframes, base_hits, clouds)
    for k in range(1, m):
        pred = compose(tuple(est[k - 1]), between(tuple(odom[k - 1]), tuple(odom[k])))
        res = match_scan(lf, base_hits[k], pred, p.match)
        accepted[k], degenerate[k] = res.accepted, res.degenerate
        est[k] = res.pose
        if res.accepted and pm is not None:
            est[k] = refine_point_to_line(pm, base_hits[k], res.pose, p.refine_max_distance_m)[0]
        last = est[keyframes[-1]]
        moved = math.hypot(est[k, 0] - last[0], est[k, 1] - last[1])
        turned = abs(math.remainder(est[k, 2] - last[2], 2 * math.pi))
        if moved >= p.keyframe_distance_m or turned >= p.keyframe_yaw_rad:
            keyframes.append(k)
            lmap.integrate(compose(tuple(est[k]), mount), *sensor_pts[k])  # type: ignore[arg-type]
            lf = likelihood_field_window(
                lmap.occupied(), geometry, p.field_sigma_m, (est[k, 0], est[k, 1]), half_m
            )
            _loop_search(p, est, keyframes, base_hits, geometry, loops, loop_edges, clouds)
            pm = _keyframe_points(p, est, keyframes, base_hits, clouds)
    kf = np.array(keyframes, dtype=np.int64)
    front = est.copy()
    t0 = time.perf_counter()
    if loop_edges:
        kf_poses = est[kf]
        seq = between_poses(kf_poses[:-1], kf_poses[1:])
        edges = [PoseEdge(i, i + 1, tuple(seq[i]), p.odometry_sigmas) for i in range(len(kf) - 1)]
        optimised = optimize_pose_graph(kf_poses, edges + loop_edges)
        owner = np.searchsorted(kf, np.arange(m), side="right") - 1
        offsets = between_poses(kf_poses[owner], est)
        est = compose_poses(optimised[owner], offsets)
    graph_time = time.perf_counter() - t0
    final = LogOddsMap.covering(
        np.array(lmap.origin_xy_m),
        np.array(lmap.origin_xy_m)
        + np.array(lmap.logodds.shape[::-1]) * p.resolution_m
        - p.resolution_m,
        p.resolution_m,
    )
    sensor_poses = compose_poses(est, np.asarray(mount))
    for k in range(m):
        final.integrate(tuple(sensor_poses[k]), *sensor_pts[k])
    return SlamResult(
        final.to_grid(),
        t,
        est,
        front,
        odom_map,
        kf,
        np.array(loops, dtype=np.int64).reshape(-1, 2),
        accepted,
        degenerate,
        graph_time,
    )


def _world_points(pose: NDArray[np.float64], base: NDArray[np.float64]) -> NDArray[np.float64]:
    return compose_poses(pose, np.column_stack([base, np.zeros(len(base))]))[:, :2]


_Cloud = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]


def _cloud(
    clouds: dict[int, _Cloud],
    k: int,
    est: NDArray[np.float64],
    base_hits: list[NDArray[np.float64]],
) -> _Cloud:
    """Scan ``k``'s points and normals at its estimated pose (computed once, then cached)."""
    if k not in clouds:
        pts = _world_points(est[k], base_hits[k])
        normals, planar = point_normals(pts)
        clouds[k] = (pts, normals, planar)
    return clouds[k]


def _keyframe_points(
    p: SlamParams,
    est: NDArray[np.float64],
    keyframes: list[int],
    base_hits: list[NDArray[np.float64]],
    clouds: dict[int, _Cloud],
) -> PointMap | None:
    """The points of the nearest keyframes (within ``max_range_m`` of the newest) at their
    estimated poses, for refining the matches until the next keyframe; ``clouds`` caches each
    keyframe's points and normals (world frame)."""
    if p.refine_keyframes <= 0:
        return None
    k = keyframes[-1]
    kf = np.array(keyframes)
    d = np.hypot(est[kf, 0] - est[k, 0], est[kf, 1] - est[k, 1])
    order = np.argsort(d, kind="stable")[: p.refine_keyframes]
    parts = [_cloud(clouds, int(kf[i]), est, base_hits) for i in order if d[i] <= p.max_range_m]
    pts = np.vstack([c[0] for c in parts])
    if pts.shape[0] < 10:
        return None
    return point_map(pts, np.vstack([c[1] for c in parts]), np.concatenate([c[2] for c in parts]))


def _loop_search(
    p: SlamParams,
    est: NDArray[np.float64],
    keyframes: list[int],
    base_hits: list[NDArray[np.float64]],
    geometry: OccupancyGrid,
    loops: list[tuple[int, int]],
    loop_edges: list[PoseEdge],
    clouds: dict[int, _Cloud],
) -> None:
    """Match the newest keyframe against a submap of the nearest old keyframes (at least
    ``loop_min_separation`` back, within ``max_range_m``; the nearest within ``loop_radius_m``
    is the edge's other end), refine by point-to-line ICP on their points, add an edge."""
    n = len(keyframes)
    if n <= p.loop_min_separation:
        return
    k = keyframes[-1]
    old = np.array(keyframes[: n - p.loop_min_separation])
    d = np.hypot(est[old, 0] - est[k, 0], est[old, 1] - est[k, 1])
    if d.min() > p.loop_radius_m:
        return
    j_pos = int(np.argmin(d))
    j = int(old[j_pos])
    order = np.argsort(d, kind="stable")[: max(p.refine_keyframes, 7)]
    near = [int(old[i]) for i in order if d[i] <= p.max_range_m]
    parts = [_cloud(clouds, i, est, base_hits) for i in near]
    pts = np.vstack([c[0] for c in parts])
    rc = geometry.world_to_cell(pts)
    inside = geometry.in_bounds(rc)
    occ = np.zeros(geometry.shape, dtype=bool)
    occ[rc[inside, 0], rc[inside, 1]] = True
    lf = likelihood_field_window(
        occ,
        geometry,
        p.field_sigma_m,
        (est[k, 0], est[k, 1]),
        p.max_range_m + p.loop_match.window_xy_m + 0.5,
    )
    res = match_scan(lf, base_hits[k], tuple(est[k]), p.loop_match)
    if not res.accepted or res.score < p.loop_min_score:
        return
    pose = res.pose
    if p.refine_keyframes > 0:
        pm = point_map(pts, np.vstack([c[1] for c in parts]), np.concatenate([c[2] for c in parts]))
        pose = refine_point_to_line(pm, base_hits[k], pose, p.refine_max_distance_m)[0]
    i_kf, j_kf = j_pos, n - 1
    rel = between(tuple(est[j]), pose)
    loops.append((i_kf, j_kf))
    loop_edges.append(PoseEdge(i_kf, j_kf, rel, p.loop_sigmas, robust=True))
