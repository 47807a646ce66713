from __future__ import annotations

import itertools

import numpy as np
import pytest

from omnical.navigation.astar import astar_grid, path_length
from omnical.navigation.grid import OccupancyGrid
from omnical.navigation.inflation import Footprint, inflate
from omnical.navigation.map_io import load_map
from omnical.navigation.prm import (
    PlanParams,
    PrmParams,
    build_roadmap,
    grid_optimal_path,
    plan,
)
from omnical.navigation.raycast import segments_free

from .conftest import room, world_yaml


def test_inflation_radius_choices() -> None:
    occ = np.zeros((50, 50), dtype=bool)
    occ[25, 25] = True
    grid = OccupancyGrid.from_occupied(occ, 0.02)
    fp = Footprint(0.6, 0.4)
    circ = inflate(grid, footprint=fp)
    ins = inflate(grid, footprint=fp, radius="inscribed")
    assert circ.radius_m == pytest.approx(fp.circumscribed_radius_m)
    assert ins.radius_m == pytest.approx(0.2)
    assert ins.blocked.sum() < circ.blocked.sum()
    # a cell 0.2 m + 1 cell away is free, one closer is blocked
    assert not ins.blocked[25, 25 + 11] and ins.blocked[25, 25 + 10]
    assert inflate(grid, 0.0).blocked.sum() == 1


def test_astar_optimal_on_empty_grid() -> None:
    blocked = np.zeros((20, 30), dtype=bool)
    cells = astar_grid(blocked, (0, 0), (10, 25))
    length = path_length(cells.astype(float))
    assert length == pytest.approx(15 + 10 * np.sqrt(2))
    blocked[5, :] = True
    assert astar_grid(blocked, (0, 0), (10, 25)).shape == (0, 2)


def test_plan_statuses_and_determinism() -> None:
    grid = room()
    inf = inflate(grid, 0.15)
    params = PlanParams(PrmParams(300, 1.5, seed=4))
    start, goal = np.array([-0.6, 0.0]), np.array([2.3, 1.2])
    a = plan(inf, start, goal, params)
    b = plan(inf, start, goal, params)
    assert a.status == "ok"
    np.testing.assert_array_equal(a.path_m, b.path_m)
    assert a.path_m[0] == pytest.approx(start) and a.path_m[-1] == pytest.approx(goal)
    assert segments_free(inf.blocked, grid, a.path_m[:-1], a.path_m[1:]).all()
    assert plan(inf, np.array([0.2, 0.7]), goal, params).status == "start_in_collision"
    assert plan(inf, start, np.array([1.75, 0.0]), params).status == "goal_in_collision"
    wall = grid.occupied | (np.arange(80)[None, :] == 55)
    closed = OccupancyGrid.from_occupied(wall, 0.05, grid.origin)
    res = plan(inflate(closed, 0.15), start, goal, params)
    assert res.status == "no_path" and "A*" in res.reason


def test_prm_empty_path_with_reason() -> None:
    inf = inflate(room(), 0.15)
    rm = build_roadmap(inf, PrmParams(0))
    found = rm.find_path(np.array([-0.6, 0.0]), np.array([2.3, 1.2]))
    assert not found.found and "no roadmap node" in found.reason


def test_narrow_passage_falls_back_to_astar() -> None:
    occ = np.zeros((60, 100), dtype=bool)
    occ[:, 40:60] = True
    occ[30:33, 40:60] = False  # a 1 m long, 3-cell wide corridor
    grid = OccupancyGrid.from_occupied(occ, 0.05)
    inf = inflate(grid, 0.02)
    res = plan(
        inf, np.array([0.5, 0.5]), np.array([4.5, 2.5]), PlanParams(PrmParams(50, 1.0, seed=0))
    )
    assert res.status == "ok" and res.method == "astar"


def test_warehouse_prm_close_to_grid_optimum() -> None:
    grid = load_map(world_yaml("warehouse-20x20"))
    inf = inflate(grid)
    rm = build_roadmap(inf, PrmParams(2000, 2.5, seed=1))
    rng = np.random.default_rng(3)
    free = np.argwhere(~inf.blocked)
    for _ in range(5):
        a, b = grid.cell_to_world(free[rng.integers(0, len(free), 2)])
        res = plan(inf, a, b, roadmap=rm)
        assert res.status == "ok"
        assert res.length_m <= 1.05 * path_length(grid_optimal_path(inf, a, b))


def test_warehouse_tour_sees_every_navigation_goal() -> None:
    """The warehouse mapping lap is plannable on the floor plan and passes each benchmark goal
    in line of sight within the map's 6 m (a lap of the outer aisles alone did not)."""
    from omnical.services.navigation import (
        WAREHOUSE_GOALS,
        WAREHOUSE_LAP,
        WAREHOUSE_START,
        _tour_path,
    )
    from omnical.twin.world import load_world

    world = load_world(world_yaml("warehouse-20x20"), Footprint(0.6, 0.6))
    tour = _tour_path(world, WAREHOUSE_START, WAREHOUSE_LAP)
    steps = [
        np.linspace(a, b, max(2, int(np.ceil(np.hypot(*(b - a)) / 0.25))))
        for a, b in itertools.pairwise(tour)
    ]
    samples = np.vstack(steps)
    infl = inflate(world.grid, footprint=world.footprint)
    for goal in WAREHOUSE_GOALS:
        g = np.array(goal)
        assert not infl.blocked_at(g), goal
        near = samples[np.hypot(*(samples - g).T) <= 5.5]
        seen = segments_free(world.grid.occupied, world.grid, near, np.broadcast_to(g, near.shape))
        assert seen.any(), f"goal {goal} is never in view of the tour"
