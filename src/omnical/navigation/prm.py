"""Probabilistic roadmap (MATLAB ``mobileRobotPRM`` semantics) and seed 001 §4.2.3's planner.

PRM first, grid A* as the fallback, then shortcutting; seeded (the same seed gives the same path),
segments checked exactly on the grid, an empty path with its reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Final, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from omnical.errors import ConfigError
from omnical.navigation.astar import astar_grid, path_length
from omnical.navigation.inflation import InflatedMap
from omnical.navigation.raycast import segments_free

__all__ = [
    "MAX_NUM_NODES",
    "PlanParams",
    "PlanResult",
    "PlanStatus",
    "PrmParams",
    "PrmPath",
    "Roadmap",
    "build_roadmap",
    "grid_optimal_path",
    "plan",
    "shortcut",
]

PlanStatus = Literal["ok", "start_in_collision", "goal_in_collision", "no_path"]

MAX_NUM_NODES: Final = 5000
"""Most PRM nodes (the roadmap's candidate pairs grow as the square)."""


@dataclass(frozen=True)
class PrmParams:
    """``mobileRobotPRM`` properties.

    Attributes:
        num_nodes: NumNodes (MATLAB default 50).
        connection_distance_m: ConnectionDistance (MATLAB default inf).
        seed: seed of the node sampling.
    """

    num_nodes: int = 50
    connection_distance_m: float = math.inf
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.num_nodes <= MAX_NUM_NODES:
            msg = f"PRM num_nodes must be 0 to {MAX_NUM_NODES}, got {self.num_nodes}"
            raise ConfigError(msg)
        if self.seed < 0:
            msg = f"PRM seed must be >= 0, got {self.seed}"
            raise ConfigError(msg)
        if not self.connection_distance_m > 0.0:
            msg = f"PRM connection distance must be > 0, got {self.connection_distance_m}"
            raise ConfigError(msg)


@dataclass(frozen=True, eq=False)
class PrmPath:
    """A ``findpath`` answer: (K, 2) way-points start → goal, empty with a reason when none."""

    path_m: NDArray[np.float64]
    reason: str = ""

    @property
    def found(self) -> bool:
        """A path was found."""
        return bool(self.path_m.shape[0] > 0)


@dataclass(frozen=True, eq=False)
class Roadmap:
    """A built roadmap.

    Attributes:
        inflated: the inflated map it was built on.
        params: the PRM parameters.
        nodes_m: (N, 2) node positions, world frame.
        edges: (E, 2) node index pairs (i < j), sorted.
        lengths_m: (E,) edge lengths.
    """

    inflated: InflatedMap
    params: PrmParams
    nodes_m: NDArray[np.float64]
    edges: NDArray[np.int64]
    lengths_m: NDArray[np.float64]

    def _connect(self, point: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        d = np.hypot(*(self.nodes_m - point).T) if self.nodes_m.shape[0] else np.empty(0)
        near = np.flatnonzero(d <= self.params.connection_distance_m)
        if near.size == 0:
            return near.astype(np.int64), d[near]
        ok = segments_free(
            self.inflated.blocked,
            self.inflated.grid,
            np.broadcast_to(point, (near.size, 2)),
            self.nodes_m[near],
        )
        return near[ok].astype(np.int64), d[near[ok]]

    def find_path(self, start_xy_m: ArrayLike, goal_xy_m: ArrayLike) -> PrmPath:
        """``findpath``: the shortest roadmap path from start to goal (world frame)."""
        start = np.asarray(start_xy_m, dtype=np.float64).reshape(2)
        goal = np.asarray(goal_xy_m, dtype=np.float64).reshape(2)
        empty = np.empty((0, 2))
        blocked = self.inflated.blocked_at(np.stack([start, goal]))
        if blocked[0]:
            return PrmPath(empty, "the start is in collision on the inflated map")
        if blocked[1]:
            return PrmPath(empty, "the goal is in collision on the inflated map")
        n = self.nodes_m.shape[0]
        s_idx, g_idx = n, n + 1
        direct = float(np.hypot(*(goal - start)))
        if direct <= self.params.connection_distance_m and bool(
            segments_free(self.inflated.blocked, self.inflated.grid, start, goal)[0]
        ):
            return PrmPath(np.stack([start, goal]))
        s_near, s_d = self._connect(start)
        g_near, g_d = self._connect(goal)
        if s_near.size == 0:
            return PrmPath(
                empty, "no roadmap node is visible from the start within the connection distance"
            )
        if g_near.size == 0:
            return PrmPath(
                empty, "no roadmap node is visible from the goal within the connection distance"
            )
        rows = np.concatenate(
            [self.edges[:, 0], np.full(s_near.size, s_idx), np.full(g_near.size, g_idx)]
        )
        cols = np.concatenate([self.edges[:, 1], s_near, g_near])
        w = np.concatenate([self.lengths_m, s_d, g_d])
        graph = coo_matrix((w, (rows, cols)), shape=(n + 2, n + 2)).tocsr()
        dist, pred = dijkstra(graph, directed=False, indices=s_idx, return_predecessors=True)
        if not math.isfinite(float(dist[g_idx])):
            return PrmPath(empty, "the start and the goal are not connected on the roadmap")
        order = [g_idx]
        while order[-1] != s_idx:
            order.append(int(pred[order[-1]]))
        points = np.vstack([self.nodes_m, start, goal])
        return PrmPath(points[order[::-1]].copy())


def build_roadmap(inflated: InflatedMap, params: PrmParams | None = None) -> Roadmap:
    """``mobileRobotPRM``: sample ``num_nodes`` free nodes and connect the visible close pairs."""
    p = params or PrmParams()
    grid = inflated.grid
    rng = np.random.default_rng(p.seed)
    free = np.flatnonzero(~inflated.blocked.ravel())
    if free.size == 0 or p.num_nodes == 0:
        nodes = np.empty((0, 2))
    else:
        picks = free[rng.integers(0, free.size, p.num_nodes)]
        cols = grid.shape[1]
        colrow = np.column_stack([picks % cols, picks // cols]).astype(np.float64)
        nodes = grid.grid_to_world(colrow + rng.random((p.num_nodes, 2)))
    if nodes.shape[0] >= 2:
        radius = p.connection_distance_m if math.isfinite(p.connection_distance_m) else 1e300
        pairs = cKDTree(nodes).query_pairs(radius, output_type="ndarray").astype(np.int64)
        pairs = np.sort(pairs, axis=1)
        pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
        ok = segments_free(inflated.blocked, grid, nodes[pairs[:, 0]], nodes[pairs[:, 1]])
        edges = pairs[ok]
    else:
        edges = np.empty((0, 2), dtype=np.int64)
    lengths = np.hypot(*(nodes[edges[:, 1]] - nodes[edges[:, 0]]).T) if edges.size else np.empty(0)
    return Roadmap(inflated, p, nodes, edges, lengths)


def shortcut(inflated: InflatedMap, path_m: ArrayLike) -> NDArray[np.float64]:
    """Greedy shortcutting: from each kept way-point jump to the farthest one visible from it."""
    path = np.asarray(path_m, dtype=np.float64).reshape(-1, 2)
    if path.shape[0] <= 2:
        return path.copy()
    keep = [0]
    i, last = 0, path.shape[0] - 1
    while i < last:
        cand = np.arange(i + 1, last + 1)
        ok = segments_free(
            inflated.blocked, inflated.grid, np.broadcast_to(path[i], (cand.size, 2)), path[cand]
        )
        ok[0] = True
        i = int(cand[np.flatnonzero(ok)[-1]])
        keep.append(i)
    return path[keep].copy()


def grid_optimal_path(
    inflated: InflatedMap, start_xy_m: ArrayLike, goal_xy_m: ArrayLike
) -> NDArray[np.float64]:
    """The A* path (8-connected, optimal on the grid) from start to goal; (0, 2) if none.

    The way-points are the cell centres, with the exact start and goal at the ends.
    """
    grid = inflated.grid
    start = np.asarray(start_xy_m, dtype=np.float64).reshape(2)
    goal = np.asarray(goal_xy_m, dtype=np.float64).reshape(2)
    s_rc, g_rc = grid.world_to_cell(np.stack([start, goal]))
    cells = astar_grid(inflated.blocked, (int(s_rc[0]), int(s_rc[1])), (int(g_rc[0]), int(g_rc[1])))
    if cells.shape[0] == 0:
        return np.empty((0, 2))
    pts = grid.cell_to_world(cells)
    pts[0], pts[-1] = start, goal
    return pts


@dataclass(frozen=True)
class PlanParams:
    """How :func:`plan` plans.

    Attributes:
        prm: roadmap parameters (1000 nodes within 3 m by default).
        fallback: run grid A* when the roadmap finds no path (narrow passages).
        shortcut: shortcut the path.
    """

    prm: PrmParams = field(
        default_factory=lambda: PrmParams(num_nodes=1000, connection_distance_m=3.0)
    )
    fallback: bool = True
    shortcut: bool = True


@dataclass(frozen=True, eq=False)
class PlanResult:
    """A planned path.

    Attributes:
        status: ok, start_in_collision, goal_in_collision or no_path.
        path_m: (K, 2) way-points start → goal (after shortcutting); empty unless ok.
        raw_path_m: the path before shortcutting.
        method: "prm", "astar" (the fallback) or "" when no path.
        reason: why there is no path ("" when ok).
    """

    status: PlanStatus
    path_m: NDArray[np.float64]
    raw_path_m: NDArray[np.float64]
    method: str
    reason: str = ""

    @property
    def length_m(self) -> float:
        """Length of the path."""
        return path_length(self.path_m)


def plan(
    inflated: InflatedMap,
    start_xy_m: ArrayLike,
    goal_xy_m: ArrayLike,
    params: PlanParams | None = None,
    *,
    roadmap: Roadmap | None = None,
) -> PlanResult:
    """Plan from start to goal: PRM, then A* if the roadmap has no path, then shortcutting.

    Args:
        inflated: the inflated map.
        start_xy_m, goal_xy_m: world points.
        params: planner parameters.
        roadmap: a roadmap built on ``inflated`` (None = build one from ``params.prm``).
    """
    pp = params or PlanParams()
    start = np.asarray(start_xy_m, dtype=np.float64).reshape(2)
    goal = np.asarray(goal_xy_m, dtype=np.float64).reshape(2)
    empty = np.empty((0, 2))
    blocked = inflated.blocked_at(np.stack([start, goal]))
    if blocked[0]:
        return PlanResult(
            "start_in_collision",
            empty,
            empty,
            "",
            "the start is an obstacle or closer than the inflation radius",
        )
    if blocked[1]:
        return PlanResult(
            "goal_in_collision",
            empty,
            empty,
            "",
            "the goal is an obstacle or closer than the inflation radius",
        )
    rm = roadmap if roadmap is not None else build_roadmap(inflated, pp.prm)
    found = rm.find_path(start, goal)
    method, raw, reason = "prm", found.path_m, found.reason
    if not found.found and pp.fallback:
        raw = grid_optimal_path(inflated, start, goal)
        method = "astar"
        if raw.shape[0] == 0:
            reason = f"{found.reason}; A* on the inflated grid found no path either"
    if raw.shape[0] == 0:
        return PlanResult("no_path", empty, empty, "", reason)
    path = shortcut(inflated, raw) if pp.shortcut else raw.copy()
    return PlanResult("ok", path, raw, method)
