"""The occupancy grid: a frozen dataclass over a numpy array, with world ↔ cell transforms.

Cells as ``nav_msgs/OccupancyGrid`` (0, 100, −1); ``cells[row, col]``, row 0 at the bottom (unlike
the image); the origin is the lower-left corner of cell (0, 0), as in a map_server YAML.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError

__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "OccupancyGrid"]

FREE = 0
OCCUPIED = 100
UNKNOWN = -1


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """A trinary occupancy grid.

    Attributes:
        cells: (rows, cols) int8: FREE, OCCUPIED or UNKNOWN; row 0 at the bottom.
        resolution_m: cell side, m.
        origin: (x m, y m, yaw rad) of the lower-left corner of cell (0, 0) in the world.

    Raises:
        ConfigError: a non-2-D array, values other than 0 / 100 / −1, a non-positive resolution
            or a non-finite origin.
    """

    cells: NDArray[np.int8]
    resolution_m: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        cells = np.asarray(self.cells)
        if cells.ndim != 2 or cells.shape[0] < 1 or cells.shape[1] < 1:
            msg = f"occupancy grid: expected a non-empty 2-D array, got shape {cells.shape}"
            raise ConfigError(msg)
        cells = cells.astype(np.int8, copy=True)
        if not np.isin(cells, (FREE, OCCUPIED, UNKNOWN)).all():
            msg = "occupancy grid: cells must be 0 (free), 100 (occupied) or -1 (unknown)"
            raise ConfigError(msg)
        cells.setflags(write=False)
        object.__setattr__(self, "cells", cells)
        if not (math.isfinite(self.resolution_m) and self.resolution_m > 0.0):
            msg = f"occupancy grid: resolution must be finite and > 0, got {self.resolution_m}"
            raise ConfigError(msg)
        origin = tuple(float(v) for v in self.origin)
        if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
            msg = f"occupancy grid: origin must be 3 finite numbers, got {self.origin}"
            raise ConfigError(msg)
        object.__setattr__(self, "origin", origin)

    @classmethod
    def from_occupied(
        cls,
        occupied: ArrayLike,
        resolution_m: float,
        origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
        unknown: ArrayLike | None = None,
    ) -> OccupancyGrid:
        """A grid from a boolean occupied mask (and an optional unknown mask)."""
        occ = np.asarray(occupied, dtype=bool)
        cells = np.where(occ, OCCUPIED, FREE).astype(np.int8)
        if unknown is not None:
            cells[np.asarray(unknown, dtype=bool) & ~occ] = UNKNOWN
        return cls(cells, resolution_m, origin)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols)."""
        return (int(self.cells.shape[0]), int(self.cells.shape[1]))

    @property
    def size_m(self) -> tuple[float, float]:
        """(width along x, height along y) in metres."""
        return (self.shape[1] * self.resolution_m, self.shape[0] * self.resolution_m)

    @property
    def occupied(self) -> NDArray[np.bool_]:
        """(rows, cols) True where occupied."""
        return np.asarray(self.cells == OCCUPIED)

    @property
    def free(self) -> NDArray[np.bool_]:
        """(rows, cols) True where free."""
        return np.asarray(self.cells == FREE)

    @property
    def unknown(self) -> NDArray[np.bool_]:
        """(rows, cols) True where unknown."""
        return np.asarray(self.cells == UNKNOWN)

    def world_to_grid(self, xy_m: ArrayLike) -> NDArray[np.float64]:
        """(..., 2) world points → continuous grid coordinates (col, row), in cells.

        Cell (r, c) spans [c, c + 1) × [r, r + 1) in these coordinates.
        """
        p = np.asarray(xy_m, dtype=np.float64)
        ox, oy, yaw = self.origin
        with np.errstate(over="ignore", invalid="ignore"):  # a point far beyond: ±inf, outside
            dx, dy = p[..., 0] - ox, p[..., 1] - oy
            if yaw != 0.0:
                c, s = math.cos(yaw), math.sin(yaw)
                dx, dy = c * dx + s * dy, -s * dx + c * dy
            return np.stack([dx, dy], axis=-1) / self.resolution_m

    def grid_to_world(self, colrow: ArrayLike) -> NDArray[np.float64]:
        """(..., 2) continuous grid coordinates (col, row) → world points."""
        g = np.asarray(colrow, dtype=np.float64) * self.resolution_m
        ox, oy, yaw = self.origin
        gx, gy = g[..., 0], g[..., 1]
        if yaw != 0.0:
            c, s = math.cos(yaw), math.sin(yaw)
            gx, gy = c * gx - s * gy, s * gx + c * gy
        return np.stack([gx + ox, gy + oy], axis=-1)

    def world_to_cell(self, xy_m: ArrayLike) -> NDArray[np.int64]:
        """(..., 2) world points → integer cells (row, col); beyond the map: one past its edge."""
        g = np.nan_to_num(np.floor(self.world_to_grid(xy_m)), nan=-1.0)
        rows, cols = self.shape
        col = np.clip(g[..., 0], -1, cols).astype(np.int64)
        row = np.clip(g[..., 1], -1, rows).astype(np.int64)
        return np.stack([row, col], axis=-1)

    def cell_to_world(self, rowcol: ArrayLike) -> NDArray[np.float64]:
        """(..., 2) integer cells (row, col) → world points of the cell centres."""
        rc = np.asarray(rowcol, dtype=np.float64)
        return self.grid_to_world(np.stack([rc[..., 1] + 0.5, rc[..., 0] + 0.5], axis=-1))

    def in_bounds(self, rowcol: ArrayLike) -> NDArray[np.bool_]:
        """(...,) True for cells inside the grid."""
        rc = np.asarray(rowcol)
        rows, cols = self.shape
        return np.asarray(
            (rc[..., 0] >= 0) & (rc[..., 0] < rows) & (rc[..., 1] >= 0) & (rc[..., 1] < cols)
        )

    def value_at(self, xy_m: ArrayLike, outside: int = UNKNOWN) -> NDArray[np.int8]:
        """(...,) cell values at world points (``outside`` beyond the grid)."""
        rc = self.world_to_cell(xy_m)
        inside = self.in_bounds(rc)
        out = np.full(rc.shape[:-1], outside, dtype=np.int8)
        out[inside] = self.cells[rc[inside][:, 0], rc[inside][:, 1]]
        return out
