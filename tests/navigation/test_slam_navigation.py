"""Scan matching and the pose graph on small scenes.

SLAM and navigation on the lab world (the issue's targets) are checked on the demo's navigation
chapter in tests/test_demo.py, which runs that very tour once for the suite.
"""

from __future__ import annotations

import math

import numpy as np

from omnical.navigation.grid import OccupancyGrid
from omnical.navigation.pose_graph import PoseEdge, optimize_pose_graph
from omnical.navigation.scan_match import likelihood_field, match_scan
from omnical.twin.lidar import Lidar, LidarParams, scan_points


def test_scan_match_recovers_pose_and_flags_corridor() -> None:
    occ = np.zeros((150, 200), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    occ[60:80, 120:130] = True
    grid = OccupancyGrid.from_occupied(occ, 0.02)
    lid = Lidar(grid, LidarParams(), seed=1)
    true = np.array([1.5, 1.0, 0.3])
    pts = scan_points(lid.scan(true), lid.params)
    res = match_scan(likelihood_field(occ, grid), pts, (1.58, 0.95, 0.34))
    assert res.accepted
    assert math.hypot(res.pose[0] - 1.5, res.pose[1] - 1.0) < 0.01
    assert abs(res.pose[2] - 0.3) < math.radians(0.5)
    corridor = np.zeros((100, 400), dtype=bool)
    corridor[30, :] = corridor[70, :] = True
    cgrid = OccupancyGrid.from_occupied(corridor, 0.02)
    clid = Lidar(cgrid, LidarParams(range_max_m=3.0), seed=1)
    cpts = scan_points(clid.scan(np.array([4.0, 1.0, 0.0])), clid.params)
    cres = match_scan(likelihood_field(corridor, cgrid), cpts, (4.05, 1.0, 0.0))
    assert cres.degenerate and not cres.accepted and cres.pose == (4.05, 1.0, 0.0)


def test_pose_graph_closes_a_loop() -> None:
    true = np.array([[0, 0, 0], [1, 0, np.pi / 2], [1, 1, np.pi], [0, 1, -np.pi / 2]], dtype=float)
    drift = true + np.array([[0, 0, 0], [0.05, 0, 0], [0.1, 0.05, 0.02], [0.1, 0.1, 0.03]])
    edges = [PoseEdge(i, i + 1, (1.0, 0.0, np.pi / 2), (0.01, 0.01, 0.01)) for i in range(3)]
    edges.append(PoseEdge(3, 0, (1.0, 0.0, np.pi / 2), (0.01, 0.01, 0.01), robust=True))
    out = optimize_pose_graph(drift, edges)
    np.testing.assert_allclose(out[:, :2], true[:, :2], atol=1e-6)
