"""The twin in a floor plan: the robot's footprint against the occupied cells.

:class:`World` says whether the footprint at a pose touches an occupied cell (sampled finer than
half a cell, so that any real overlap is found) and how far it stays from the walls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError
from omnical.navigation.grid import OccupancyGrid
from omnical.navigation.inflation import Footprint
from omnical.navigation.map_io import load_map

__all__ = ["World", "load_world"]


@dataclass(frozen=True, eq=False)
class World:
    """A floor plan and the robot's footprint in it.

    Attributes:
        grid: the floor plan (occupied cells are walls; unknown cells count as walls too).
        footprint: the robot's footprint.
        name: label (the map file's stem).
    """

    grid: OccupancyGrid
    footprint: Footprint = field(default_factory=Footprint)
    name: str = "world"

    def __post_init__(self) -> None:
        solid = self.grid.occupied | self.grid.unknown
        object.__setattr__(self, "_solid", solid)
        object.__setattr__(self, "_distance_cache", None)
        step = 0.45 * self.grid.resolution_m
        fp = self.footprint
        xs = np.linspace(
            -fp.length_m / 2, fp.length_m / 2, max(2, math.ceil(fp.length_m / step) + 1)
        )
        ys = np.linspace(-fp.width_m / 2, fp.width_m / 2, max(2, math.ceil(fp.width_m / step) + 1))
        gx, gy = np.meshgrid(xs, ys)
        samples = np.column_stack([gx.ravel(), gy.ravel()])
        object.__setattr__(self, "_samples", samples)
        edge = (np.abs(samples[:, 0]) == xs[-1]) | (np.abs(samples[:, 1]) == ys[-1])
        object.__setattr__(self, "_outline", samples[edge])

    def _distance(self) -> NDArray[np.float64]:
        """Distance from each cell to the nearest wall, m (computed on first use: SciPy's
        import and the transform are 0.3 s a ROS 2 twin's start need not wait for)."""
        cached: NDArray[np.float64] | None = self._distance_cache  # type: ignore[attr-defined]
        if cached is None:
            from scipy import ndimage

            solid: NDArray[np.bool_] = self._solid  # type: ignore[attr-defined]
            cached = np.asarray(ndimage.distance_transform_edt(~solid) * self.grid.resolution_m)
            object.__setattr__(self, "_distance_cache", cached)
        return cached

    def _points(self, pose: ArrayLike) -> NDArray[np.float64]:
        x, y, yaw = (float(v) for v in np.asarray(pose, dtype=np.float64)[:3])
        s: NDArray[np.float64] = self._samples  # type: ignore[attr-defined]
        c, sn = math.cos(yaw), math.sin(yaw)
        return np.column_stack([x + c * s[:, 0] - sn * s[:, 1], y + sn * s[:, 0] + c * s[:, 1]])

    def collides(self, pose: ArrayLike) -> bool:
        """The footprint at base_link pose (x, y, yaw) touches a wall (or leaves the map)."""
        rc = self.grid.world_to_cell(self._points(pose))
        inside = self.grid.in_bounds(rc)
        if not inside.all():
            return True
        solid: NDArray[np.bool_] = self._solid  # type: ignore[attr-defined]
        return bool(solid[rc[:, 0], rc[:, 1]].any())

    def collision_message(self, pose: ArrayLike) -> str:
        """ "" when free, else a message naming the pose."""
        if not self.collides(pose):
            return ""
        x, y, yaw = (float(v) for v in np.asarray(pose)[:3])
        return (
            f"collision: the footprint touches an occupied cell of {self.name} "
            f"at x={x:.3f} m, y={y:.3f} m, yaw={math.degrees(yaw):.1f}°"
        )

    def first_collision(self, poses: ArrayLike, chunk: int = 256) -> int | None:
        """Index of the first of (N, 3) base_link poses whose footprint touches a wall (or
        leaves the map), None if none does (:meth:`collides` for each, vectorised)."""
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        s: NDArray[np.float64] = self._samples  # type: ignore[attr-defined]
        dist = self._distance()
        # Poses whose centre is farther from every wall than the footprint reaches (plus a cell
        # of rounding) cannot touch one: only the others are sampled.
        reach_m = float(np.max(np.hypot(s[:, 0], s[:, 1]))) + 1.5 * self.grid.resolution_m
        rc0 = self.grid.world_to_cell(p[:, :2])
        near = ~self.grid.in_bounds(rc0)
        ok = ~near
        near[ok] = dist[rc0[ok, 0], rc0[ok, 1]] <= reach_m
        candidates = np.flatnonzero(near)
        for start in range(0, len(candidates), chunk):
            index = candidates[start : start + chunk]
            per_pose = self._touching(p[index], s)
            if per_pose.any():
                return int(index[int(np.argmax(per_pose))])
        return None

    def first_contact(self, poses: ArrayLike) -> int | None:
        """:meth:`first_collision` for a stream of poses a few millimetres apart from a free
        start (a ROS 2 twin's truth): a wall can reach the footprint only across its outline,
        so only the outline is sampled (1/17 of the samples), every pose, with no distance map."""
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        per_pose = self._touching(p, self._outline)  # type: ignore[attr-defined]
        return int(np.argmax(per_pose)) if per_pose.any() else None

    def _touching(
        self, poses: NDArray[np.float64], samples: NDArray[np.float64]
    ) -> NDArray[np.bool_]:
        """(N,) whether ``samples`` (body frame) at each of (N, 3) poses touch a wall or leave
        the map."""
        solid: NDArray[np.bool_] = self._solid  # type: ignore[attr-defined]
        c, sn = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
        xs = poses[:, 0:1] + c * samples[None, :, 0] - sn * samples[None, :, 1]
        ys = poses[:, 1:2] + sn * samples[None, :, 0] + c * samples[None, :, 1]
        rc = self.grid.world_to_cell(np.column_stack([xs.ravel(), ys.ravel()]))
        inside = self.grid.in_bounds(rc)
        hit = ~inside
        hit[inside] = solid[rc[inside, 0], rc[inside, 1]]
        return np.asarray(hit.reshape(len(poses), -1).any(axis=1), dtype=np.bool_)

    def min_clearance_m(self, poses: ArrayLike) -> float:
        """Smallest distance from the footprint's samples to a wall centre over (N, 3) poses."""
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        dist = self._distance()
        best = math.inf
        for pose in p:
            rc = self.grid.world_to_cell(self._points(pose))
            inside = self.grid.in_bounds(rc)
            if not inside.all():
                return 0.0
            best = min(best, float(dist[rc[:, 0], rc[:, 1]].min()))
        return best - 0.5 * self.grid.resolution_m


def check_start(world: World, pose: ArrayLike, what: str, fix: str) -> None:
    """Refuse a start (``what``: how the user gave it) whose footprint touches a wall of
    ``world`` or leaves it: a mistake, said with ``fix``, before the run.

    Raises:
        ConfigError: the start is not free.
    """
    if world.collides(pose):
        x, y = (float(v) for v in np.asarray(pose, dtype=np.float64)[:2])
        msg = (
            f"{what} ({x:g}, {y:g}) m puts the robot in a wall of {world.name} or outside it: {fix}"
        )
        raise ConfigError(msg)


def load_world(path: str | Path, footprint: Footprint | None = None) -> World:
    """A world from a map_server YAML."""
    return World(load_map(path), footprint or Footprint(), Path(path).stem)
