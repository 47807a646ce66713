"""The SLAM front end's pieces: the windowed likelihood field, the odometry prior of the
correlative matcher, and the point-to-line refinement (fast, synthetic maps)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from omnical.estimation.se2 import compose_poses
from omnical.navigation.grid import OccupancyGrid
from omnical.navigation.scan_match import (
    MatchParams,
    likelihood_field,
    likelihood_field_window,
    match_scan,
    point_map,
    point_normals,
    refine_point_to_line,
)
from omnical.twin.lidar import Lidar, LidarParams, scan_points


def _room() -> tuple[NDArray[np.bool_], OccupancyGrid]:
    occ = np.zeros((150, 200), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    occ[60:80, 120:130] = True
    occ[20:24, 30:60] = True
    return occ, OccupancyGrid.from_occupied(occ, 0.02, (-0.5, 0.25, 0.0))


def test_windowed_field_equals_the_full_field_inside_the_window() -> None:
    occ, grid = _room()
    full = likelihood_field(occ, grid, 0.04)
    win = likelihood_field_window(occ, grid, 0.04, (1.3, 1.2), 0.8)
    c0 = round((win.origin_xy_m[0] - full.origin_xy_m[0]) / grid.resolution_m)
    r0 = round((win.origin_xy_m[1] - full.origin_xy_m[1]) / grid.resolution_m)
    rows, cols = win.values.shape
    assert (rows, cols) == (81, 81)
    inside = full.values[r0 : r0 + rows, c0 : c0 + cols]
    # truncated at 4 sigma: exp(-8) below the full field's tail
    np.testing.assert_allclose(win.values, inside, atol=math.exp(-8.0) + 1e-12)
    # the window clips at the map's edge
    edge = likelihood_field_window(occ, grid, 0.04, (-0.45, 0.3), 0.5)
    assert edge.origin_xy_m == (grid.origin[0], grid.origin[1])


def _scan_world(grid: OccupancyGrid, pose: NDArray[np.float64], seed: int) -> NDArray[np.float64]:
    lid = Lidar(grid, LidarParams(), seed=seed)
    return np.asarray(scan_points(lid.scan(pose), lid.params))


def test_point_to_line_refinement_is_millimetre_accurate() -> None:
    _, grid = _room()
    true = np.array([1.23, 1.31, 0.2])
    # the map's points: noisy scans from three other poses at their true poses, each scan's
    # normals from its own points (as SLAM builds it)
    others = (np.array([1.0, 1.2, 0.0]), np.array([1.6, 1.5, 1.0]), np.array([1.4, 0.9, -0.5]))
    cloud = [
        compose_poses(q, np.column_stack([s, np.zeros(len(s))]))[:, :2]
        for seed, q in enumerate(others)
        for s in [_scan_world(grid, q, seed)]
    ]
    normals = [point_normals(c) for c in cloud]
    pm = point_map(
        np.vstack(cloud),
        np.vstack([n for n, _ in normals]),
        np.concatenate([f for _, f in normals]),
    )
    pts = _scan_world(grid, true, seed=7)
    start = (1.245, 1.295, 0.2 + math.radians(0.3))
    pose, paired = refine_point_to_line(pm, pts, start)
    assert paired > 0.5
    assert math.hypot(pose[0] - true[0], pose[1] - true[1]) < 0.005
    assert abs(pose[2] - true[2]) < math.radians(0.05)
    # no pairs within reach: the prior comes back
    far, none = refine_point_to_line(pm, pts + 5.0, start)
    assert far == start and none == 0.0


def test_point_to_line_in_a_corridor_corrects_across_and_does_not_run_along() -> None:
    corridor = np.zeros((100, 400), dtype=bool)
    corridor[30, :] = corridor[70, :] = True
    grid = OccupancyGrid.from_occupied(corridor, 0.02)
    lid = Lidar(grid, LidarParams(range_max_m=3.0), seed=1)
    # as SLAM builds it: each scan's normals from its own points, then stacked
    cloud = [
        compose_poses(p, np.column_stack([s, np.zeros(len(s))]))[:, :2]
        for p in (np.array([3.0, 1.0, 0.0]), np.array([5.0, 1.0, 0.0]))
        for s in [scan_points(lid.scan(p), lid.params)]
    ]
    normals = [point_normals(c) for c in cloud]
    pm = point_map(
        np.vstack(cloud),
        np.vstack([n for n, _ in normals]),
        np.concatenate([f for _, f in normals]),
    )
    pts = scan_points(lid.scan(np.array([4.0, 1.0, 0.0])), lid.params)
    pose, _ = refine_point_to_line(pm, pts, (4.05, 1.02, 0.0))
    assert abs(pose[1] - 1.0) < 0.003  # across the corridor: corrected
    assert abs(pose[0] - 4.0) <= 0.05 + 1e-9  # along it: no worse than the prior (damped)
    # a prior (the correlative match) holds the axis where the points say little
    held, _ = refine_point_to_line(pm, pts, (4.05, 1.02, 0.0), prior_sigmas=(0.005, 0.005, 0.01))
    assert abs(held[0] - 4.05) < 0.01 and abs(held[1] - 1.0) < 0.003


def test_odometry_prior_picks_the_nearest_of_equal_matches() -> None:
    # a corridor whose walls repeat every 10 cm: matches 10 cm apart score alike
    rows, cols = 100, 400
    occ = np.zeros((rows, cols), dtype=bool)
    occ[30, :] = occ[70, :] = True
    occ[31, ::5] = occ[69, ::5] = True
    grid = OccupancyGrid.from_occupied(occ, 0.02)
    lid = Lidar(grid, LidarParams.ideal(range_max_m=3.0), seed=1)
    true = np.array([4.01, 1.0, 0.0])
    pts = scan_points(lid.scan(true), lid.params)
    lf = likelihood_field(occ, grid, 0.02)
    prior = (4.02, 1.0, 0.0)
    wide = MatchParams(window_xy_m=0.15, degeneracy_ratio=0.0)
    with_prior = MatchParams(
        window_xy_m=0.15, degeneracy_ratio=0.0, prior_sigma_xy_m=0.1, prior_sigma_yaw_rad=0.1
    )
    res = match_scan(lf, pts, prior, with_prior)
    assert res.accepted
    assert abs(res.pose[0] - true[0]) < 0.02
    flat = match_scan(lf, pts, prior, wide)
    assert abs(flat.pose[0] - true[0]) > 0.05  # the window alone: a peak 10 cm off
    # the score the prior reports is the field's, not the penalised one
    assert abs(res.score - flat.score) < 0.05
