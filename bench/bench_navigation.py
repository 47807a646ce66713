"""Navigation benchmarks (issue 13): ray casting, inflation, PRM, query, pose graph, and the
mapping / navigation targets on both shipped worlds.

Prints figures; no assertions. ``python bench/bench_navigation.py`` (needs ../shared/worlds);
``--worlds`` adds the mapping tours and navigation on lab-8x6 and warehouse-20x20 (two laps,
default uncalibrated rosy-mecanum twin; minutes of CPU) and writes their figures to
``bench-navigation-out/``; ``--worlds-only`` skips the timings, ``--world=NAME`` (repeatable)
keeps only those worlds.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from omnical.estimation.se2 import between_poses, compose_poses
from omnical.navigation.astar import path_length
from omnical.navigation.inflation import inflate
from omnical.navigation.map_io import load_map
from omnical.navigation.pose_graph import PoseEdge, optimize_pose_graph
from omnical.navigation.prm import PrmParams, build_roadmap, grid_optimal_path, plan
from omnical.navigation.raycast import cast_rays

WORLDS = Path(__file__).resolve().parents[1].parent / "shared" / "worlds"


def _best(fn, repeat: int = 3) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    grid = load_map(WORLDS / "warehouse-20x20.yaml")
    rng = np.random.default_rng(0)
    free = np.argwhere(grid.free)
    origins = np.repeat(grid.cell_to_world(free[rng.integers(0, len(free), 2000)]), 500, axis=0)
    angles = rng.uniform(-np.pi, np.pi, origins.shape[0])
    cast_rays(grid, origins[:10], angles[:10], 12.0)
    t = _best(lambda: cast_rays(grid, origins, angles, 12.0))
    print(f"ray casting: {origins.shape[0] / t / 1e6:.2f} M rays/s (12 m, warehouse)")
    t = _best(lambda: inflate(grid))
    print(f"inflation (warehouse): {t * 1e3:.0f} ms")
    infl = inflate(grid)
    build_roadmap(infl, PrmParams(100, 2.5, seed=0))
    t = _best(lambda: build_roadmap(infl, PrmParams(2000, 2.5, seed=1)))
    print(f"PRM 2000 nodes, 2.5 m: {t * 1e3:.0f} ms")
    rm = build_roadmap(infl, PrmParams(2000, 2.5, seed=1))
    blocked_free = np.argwhere(~infl.blocked)
    qt, ratios = [], []
    for _ in range(20):
        a, b = grid.cell_to_world(blocked_free[rng.integers(0, len(blocked_free), 2)])
        t0 = time.perf_counter()
        res = plan(infl, a, b, roadmap=rm)
        qt.append(time.perf_counter() - t0)
        ratios.append(res.length_m / path_length(grid_optimal_path(infl, a, b)))
    print(
        f"query (plan + shortcut): median {np.median(qt) * 1e3:.1f} ms, max {max(qt) * 1e3:.1f} ms; "
        f"length / grid optimum: max {max(ratios):.3f}"
    )
    n = 2000
    th = np.linspace(0, 4 * np.pi, n)
    true = np.column_stack([5 * np.cos(th), 5 * np.sin(th), th + np.pi / 2])
    rel = between_poses(true[:-1], true[1:]) + rng.normal(0, [0.005, 0.005, 0.001], (n - 1, 3))
    init = [true[0]]
    for r in rel:
        init.append(compose_poses(init[-1], r))
    edges = [PoseEdge(i, i + 1, tuple(rel[i]), (0.01, 0.01, 0.002)) for i in range(n - 1)]  # type: ignore[arg-type]
    edges += [
        PoseEdge(
            i, i + 1000, tuple(between_poses(true[i], true[i + 1000])), (0.02, 0.02, 0.005), True
        )  # type: ignore[arg-type]
        for i in range(0, 1000, 50)
    ]
    t = _best(lambda: optimize_pose_graph(np.array(init), edges))
    print(f"pose graph 2000 nodes, 20 loop closures: {t * 1e3:.0f} ms")


def worlds(out_dir: Path, only: tuple[str, ...] = ()) -> None:
    """Mapping tour, map score, SLAM RMSE, navigation on the lab and the warehouse (``only``:
    these worlds)."""
    import math
    from dataclasses import replace

    from omnical.reports.navigation import write_mapping_figure, write_navigation_figure
    from omnical.robot.loader import load_robot
    from omnical.services.navigation import (
        LAB_GOALS,
        LAB_START,
        LAB_TOUR,
        WAREHOUSE_GOALS,
        WAREHOUSE_LAP,
        WAREHOUSE_START,
        mapping_tour,
        navigate,
        robot_world,
    )
    from omnical.twin.params import default_twin

    robot = load_robot("rosy-mecanum")
    cases = (
        ("lab-8x6", LAB_START, LAB_TOUR, LAB_GOALS),
        ("warehouse-20x20", WAREHOUSE_START, WAREHOUSE_LAP * 2, WAREHOUSE_GOALS),
    )
    for name, start, tour, goals in cases:
        if only and name not in only:
            continue
        world = robot_world(WORLDS / f"{name}.yaml", robot)
        params = replace(default_twin(robot), start_pose_map=start)
        t0 = time.perf_counter()
        run = mapping_tour(world, robot, params, tour, max_duration_s=3000.0)
        drive_s = float(run.scans.t_s[-1] - run.scans.t_s[0])
        sc = run.score
        print(
            f"{name}: mapping {drive_s:.0f} s of robot time, SLAM {run.slam_time_s:.1f} s wall "
            f"({drive_s / run.slam_time_s:.1f}x real time), {run.slam_cpu_time_s:.1f} s CPU "
            f"({drive_s / run.slam_cpu_time_s:.1f}x), graph {run.slam.graph_time_s * 1e3:.0f} ms; "
            f"tour + SLAM {time.perf_counter() - t0:.0f} s"
        )
        front = run.slam.front_end_poses[:, :2] - run.scans.true_pose[:, :2]
        print(
            f"  map: precision {sc.occupied_precision:.4f}, recall {sc.recall_seen:.4f}, "
            f"free-but-occupied {sc.free_but_occupied * 100:.3f} %; "
            f"SLAM RMSE {run.trajectory_rmse_m * 100:.2f} cm, yaw {math.degrees(run.yaw_rmse_rad):.3f} deg "
            f"(front end {np.sqrt((front**2).sum(axis=1).mean()) * 100:.2f} cm, "
            f"odometry {run.odometry_rmse_m * 100:.1f} cm); keyframes {len(run.slam.keyframes)}, "
            f"loop closures {len(run.slam.loop_closures)}, degenerate {int(run.slam.degenerate.sum())}"
        )
        write_mapping_figure(run, out_dir / f"{name}-mapping.png", f"{name}: mapping tour")
        for controller in ("waypoint", "tracking"):
            t0 = time.perf_counter()
            nav = navigate(world, run.slam.grid, robot, params, goals, controller=controller)
            errors = ", ".join(f"{leg.goal_error_m * 100:.1f}" for leg in nav.legs)
            gt = nav.twin_log.ground_truth_pose
            at = np.searchsorted(nav.twin_log.ground_truth_t_s, nav.estimates[:, 0]).clip(
                0, len(gt) - 1
            )
            loc = np.hypot(*(nav.estimates[:, 1:3] - gt[at, :2]).T)
            print(
                f"  navigate ({controller}): reached {nav.reached}, goal errors [{errors}] cm, "
                f"collision {nav.collision or 'none'}, min clearance {nav.min_clearance_m * 100:.1f} cm, "
                f"localisation RMSE {np.sqrt((loc**2).mean()) * 100:.1f} cm (max {loc.max() * 100:.1f}), "
                f"{time.perf_counter() - t0:.0f} s"
            )
            write_navigation_figure(
                nav,
                run.slam.grid,
                out_dir / f"{name}-navigate-{controller}.png",
                f"{name}: {controller}",
            )


if __name__ == "__main__":
    import sys

    args = sys.argv[1:]
    if "--worlds-only" not in args:
        main()
    if "--worlds" in args or "--worlds-only" in args:
        names = tuple(a.split("=", 1)[1] for a in args if a.startswith("--world="))
        worlds(Path("bench-navigation-out"), names)
