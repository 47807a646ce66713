"""Navigation benchmarks (issue 13): ray casting, inflation, PRM, query, pose graph.

Prints figures; no assertions. ``python bench/bench_navigation.py`` (needs ../shared/worlds).
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


if __name__ == "__main__":
    main()
