from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.navigation.grid import OccupancyGrid
from omnical.navigation.raycast import cast_rays, cast_rays_grid, segments_free

from .conftest import room


def _brute_force_rays(
    blocked: NDArray[np.bool_],
    grid_xy: ArrayLike,
    theta_rad: ArrayLike,
    max_cells: float,
    step_cells: float = 1e-3,
) -> NDArray[np.float64]:
    """Reference: sample each ray every ``step_cells`` and report the first blocked sample (cells).

    Slow and approximate (a sample can step over a cell corner).
    """
    xy = np.asarray(grid_xy, dtype=np.float64).reshape(-1, 2)
    theta = np.broadcast_to(np.asarray(theta_rad, dtype=np.float64), (xy.shape[0],))
    t = np.arange(0.0, max_cells + step_cells, step_cells)
    rows, cols = blocked.shape
    out = np.full(xy.shape[0], np.inf)
    for i in range(xy.shape[0]):
        px = np.floor(xy[i, 0] + t * math.cos(theta[i])).astype(np.int64)
        py = np.floor(xy[i, 1] + t * math.sin(theta[i])).astype(np.int64)
        outside = (px < 0) | (py < 0) | (px >= cols) | (py >= rows)
        first_out = int(np.argmax(outside)) if outside.any() else t.shape[0]
        px, py = px[:first_out], py[:first_out]
        hits = blocked[py, px]
        if hits.any():
            out[i] = t[int(np.argmax(hits))]
    return out


def test_agrees_with_brute_force_on_random_maps() -> None:
    rng = np.random.default_rng(7)
    blocked = rng.random((80, 90)) < 0.05
    n = 3000
    starts = np.column_stack([rng.uniform(0, 90, n), rng.uniform(0, 80, n)])
    theta = rng.uniform(-math.pi, math.pi, n)
    exact = cast_rays_grid(blocked, starts, theta, 60.0)
    step = 1e-3
    ref = _brute_force_rays(blocked, starts, theta, 60.0, step)
    both_inf = np.isinf(exact) & np.isinf(ref)
    finite = np.isfinite(exact) & np.isfinite(ref)
    with np.errstate(invalid="ignore"):
        close = finite & (np.abs(exact - ref) <= 2 * step)
    assert (both_inf | close).mean() >= 0.999


def test_axis_aligned_and_world_units() -> None:
    grid = room()
    # from (0, 0.5) looking +x: the block spans x in [0.0, 0.5), rows 20..29 = y in [0.5, 1.0)
    r = cast_rays(grid, np.array([-0.5, 0.75]), np.array([0.0, math.pi]), 10.0)
    assert r[0] == np.float64(0.5)
    assert abs(r[1] - 0.45) < 1e-12  # wall column 0 spans x in [-1.0, -0.95)
    assert np.isinf(cast_rays(grid, np.array([-0.5, 0.75]), np.array([0.0]), 0.3))[0]


def test_segments_free() -> None:
    grid = room()
    blocked = grid.occupied
    a = np.array([[-0.5, 0.2], [-0.5, 0.2], [1.0, 0.2], [1.0, 1.65]])
    b = np.array([[-0.5, 2.0], [1.0, 1.0], [2.0, 0.5], [2.5, 1.65]])
    np.testing.assert_array_equal(segments_free(blocked, grid, a, b), [True, False, False, True])


def test_empty_grid_no_hit() -> None:
    grid = OccupancyGrid(np.zeros((10, 10), dtype=np.int8), 0.1)
    assert np.isinf(cast_rays(grid, np.array([0.5, 0.5]), np.array([0.3]), 5.0)).all()
