"""Exact ray casting on an occupancy grid (Amanatides & Woo, 1987), compiled with numba.

:func:`cast_rays`: the range to the first blocked cell (``inf`` past the grid or the range), rays in
parallel; :func:`segments_free` checks the planners' straight segments with the same kernel.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.navigation.grid import OccupancyGrid

__all__ = ["cast_rays", "cast_rays_grid", "segments_free"]


@numba.njit(cache=True, nogil=True)
def _cast_one(
    blocked: NDArray[np.bool_], gx: float, gy: float, dx: float, dy: float, tmax: float
) -> float:
    rows, cols = blocked.shape
    ix = math.floor(gx)
    iy = math.floor(gy)
    if ix < 0 or iy < 0 or ix >= cols or iy >= rows:
        return math.inf
    if blocked[iy, ix]:
        return 0.0
    inf = math.inf
    if dx > 0.0:
        step_x, t_max_x, t_dx = 1, (ix + 1.0 - gx) / dx, 1.0 / dx
    elif dx < 0.0:
        step_x, t_max_x, t_dx = -1, (gx - ix) / -dx, -1.0 / dx
    else:
        step_x, t_max_x, t_dx = 0, inf, inf
    if dy > 0.0:
        step_y, t_max_y, t_dy = 1, (iy + 1.0 - gy) / dy, 1.0 / dy
    elif dy < 0.0:
        step_y, t_max_y, t_dy = -1, (gy - iy) / -dy, -1.0 / dy
    else:
        step_y, t_max_y, t_dy = 0, inf, inf
    while True:
        if t_max_x < t_max_y:
            t = t_max_x
            ix += step_x
            t_max_x += t_dx
        else:
            t = t_max_y
            iy += step_y
            t_max_y += t_dy
        if t > tmax:
            return inf
        if ix < 0 or iy < 0 or ix >= cols or iy >= rows:
            return inf
        if blocked[iy, ix]:
            return t


@numba.njit(cache=True, parallel=True)
def _cast_many(
    blocked: NDArray[np.bool_],
    gx: NDArray[np.float64],
    gy: NDArray[np.float64],
    theta: NDArray[np.float64],
    tmax: NDArray[np.float64],
) -> NDArray[np.float64]:
    n = gx.shape[0]
    out = np.empty(n)
    for i in numba.prange(n):
        out[i] = _cast_one(blocked, gx[i], gy[i], math.cos(theta[i]), math.sin(theta[i]), tmax[i])
    return out


@numba.njit(cache=True)
def _cast_serial(
    blocked: NDArray[np.bool_],
    gx: NDArray[np.float64],
    gy: NDArray[np.float64],
    theta: NDArray[np.float64],
    tmax: NDArray[np.float64],
) -> NDArray[np.float64]:
    n = gx.shape[0]
    out = np.empty(n)
    for i in range(n):
        out[i] = _cast_one(blocked, gx[i], gy[i], math.cos(theta[i]), math.sin(theta[i]), tmax[i])
    return out


_PARALLEL_FROM = 8192
"""Ray counts from which the threaded kernel pays for its start-up."""


def cast_rays_grid(
    blocked: NDArray[np.bool_],
    grid_xy: ArrayLike,
    theta_rad: ArrayLike,
    max_cells: ArrayLike,
) -> NDArray[np.float64]:
    """Rays in grid coordinates: (N, 2) start (col, row), (N,) direction, (N,) max length (cells).

    Returns:
        (N,) distance in cells to the first blocked cell, ``inf`` beyond the maximum or the grid.
    """
    xy = np.asarray(grid_xy, dtype=np.float64).reshape(-1, 2)
    n = xy.shape[0]
    theta = np.broadcast_to(np.asarray(theta_rad, dtype=np.float64), (n,))
    tmax = np.broadcast_to(np.asarray(max_cells, dtype=np.float64), (n,))
    kernel = _cast_many if n >= _PARALLEL_FROM else _cast_serial
    return np.asarray(
        kernel(
            np.ascontiguousarray(blocked, dtype=np.bool_),
            np.ascontiguousarray(xy[:, 0]),
            np.ascontiguousarray(xy[:, 1]),
            np.ascontiguousarray(theta),
            np.ascontiguousarray(tmax),
        )
    )


def cast_rays(
    grid: OccupancyGrid,
    origins_xy_m: ArrayLike,
    angles_rad: ArrayLike,
    max_range_m: float,
    *,
    blocked: NDArray[np.bool_] | None = None,
) -> NDArray[np.float64]:
    """Range of each ray (world frame) to the first blocked cell, ``inf`` when nothing is hit.

    Args:
        grid: the map (its resolution and origin).
        origins_xy_m: (N, 2) or (2,) ray origins, world frame.
        angles_rad: (N,) ray directions, world frame.
        max_range_m: rays are cut at this range.
        blocked: (rows, cols) mask of cells that stop a ray; None = the occupied cells.

    Returns:
        (N,) ranges in metres.
    """
    angles = np.atleast_1d(np.asarray(angles_rad, dtype=np.float64))
    origins = np.broadcast_to(np.asarray(origins_xy_m, dtype=np.float64), (angles.shape[0], 2))
    g = grid.world_to_grid(origins)
    mask = grid.occupied if blocked is None else blocked
    cells = cast_rays_grid(mask, g, angles - grid.origin[2], max_range_m / grid.resolution_m)
    return cells * grid.resolution_m


def segments_free(
    blocked: NDArray[np.bool_], grid: OccupancyGrid, p0_m: ArrayLike, p1_m: ArrayLike
) -> NDArray[np.bool_]:
    """(N,) True where the straight segment p0 → p1 (world, (N, 2) each) crosses no blocked cell.

    Segments that leave the grid count as blocked.
    """
    a = np.asarray(p0_m, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(p1_m, dtype=np.float64).reshape(-1, 2)
    ga, gb = grid.world_to_grid(a), grid.world_to_grid(b)
    d = gb - ga
    length = np.hypot(d[:, 0], d[:, 1])
    theta = np.arctan2(d[:, 1], d[:, 0])
    hit = cast_rays_grid(blocked, ga, theta, length)
    rows, cols = blocked.shape
    inside = (gb[:, 0] >= 0) & (gb[:, 0] < cols) & (gb[:, 1] >= 0) & (gb[:, 1] < rows)
    inside &= (ga[:, 0] >= 0) & (ga[:, 0] < cols) & (ga[:, 1] >= 0) & (ga[:, 1] < rows)
    return np.asarray(np.isinf(hit) & inside)
