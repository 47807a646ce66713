"""SLAM, localisation and navigation on the lab world (the issue's targets, on the twin)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from omnical.navigation.grid import OccupancyGrid
from omnical.navigation.pose_graph import PoseEdge, optimize_pose_graph
from omnical.navigation.scan_match import likelihood_field, match_scan
from omnical.robot.loader import load_robot
from omnical.services.navigation import mapping_tour, navigate
from omnical.twin.lidar import Lidar, LidarParams, scan_points
from omnical.twin.params import default_twin
from omnical.twin.world import load_world

from .conftest import world_yaml

LAB_START = (1.0, 1.0, 0.0)
LAB_TOUR = [(6.5, 1.0), (6.8, 3.0), (6.0, 4.0), (4.5, 5.3), (1.0, 4.3), (1.0, 1.0)]


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


@pytest.fixture(scope="module")
def lab_mapping():  # type: ignore[no-untyped-def]
    robot = load_robot("rosy-mecanum")
    world = load_world(world_yaml("lab-8x6"))
    params = replace(default_twin(robot), start_pose_map=LAB_START)
    return world, robot, params, mapping_tour(world, robot, params, LAB_TOUR)


def test_lab_map_and_trajectory_targets(lab_mapping) -> None:  # type: ignore[no-untyped-def]
    _, _, _, run = lab_mapping
    assert run.score.occupied_precision >= 0.95
    assert run.score.recall_seen >= 0.90
    assert run.score.free_but_occupied <= 0.01
    assert run.trajectory_rmse_m <= 0.02
    assert math.degrees(run.yaw_rmse_rad) <= 0.5
    assert len(run.slam.keyframes) > 20 and len(run.slam.loop_closures) > 0


@pytest.fixture(scope="module")
def lab_navigation(lab_mapping):  # type: ignore[no-untyped-def]
    world, robot, params, run = lab_mapping
    return navigate(
        world,
        run.slam.grid,
        robot,
        params,
        [(6.5, 1.0), (6.0, 4.0), (1.0, 4.3)],
        controller=("waypoint", "tracking", "waypoint"),
    )


def test_lab_navigation_on_the_slam_map(lab_navigation) -> None:  # type: ignore[no-untyped-def]
    nav = lab_navigation
    assert [leg.controller for leg in nav.legs] == ["waypoint", "tracking", "waypoint"]
    assert nav.collision == ""
    assert nav.reached
    assert nav.min_clearance_m > 0.0
    assert all(leg.goal_error_m <= 0.05 for leg in nav.legs)


def test_navigation_chapter_section_and_figures(lab_mapping, lab_navigation, tmp_path) -> None:  # type: ignore[no-untyped-def]
    from omnical.reports.markdown import write_markdown_report
    from omnical.reports.navigation import navigation_chapter_section
    from omnical.services.navigation import LAB_GOALS, NavigationChapter

    world, _, _, run = lab_mapping
    chapter = NavigationChapter(
        "lab-8x6", world, run, lab_navigation, LAB_GOALS, ("waypoint", "tracking", "waypoint"), 0.0
    )
    section = navigation_chapter_section(chapter, tmp_path / "figures")
    report = write_markdown_report(tmp_path, "t", [section])
    text = report.read_text(encoding="utf-8")
    assert "figures/navigation-mapping.png" in text and "figures/navigation-goals.png" in text
    assert "occupied precision" in text and "tracking" in text
    for name in ("navigation-mapping.png", "navigation-goals.png"):
        assert (tmp_path / "figures" / name).read_bytes().startswith(b"\x89PNG")


def test_controller_choices_are_checked(lab_mapping) -> None:  # type: ignore[no-untyped-def]
    from omnical.errors import ConfigError

    world, robot, params, run = lab_mapping
    with pytest.raises(ConfigError, match="2 controller choices for 1 goals"):
        navigate(
            world, run.slam.grid, robot, params, [(6.5, 1.0)], controller=("waypoint", "waypoint")
        )
    with pytest.raises(ConfigError, match="unknown controller 'pid'"):
        navigate(world, run.slam.grid, robot, params, [(6.5, 1.0)], controller="pid")  # type: ignore[arg-type]
