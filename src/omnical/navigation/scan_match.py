"""Correlative scan matching on a likelihood field (Olson 2009, without the GPU), with a
degeneracy check.

The map's occupied cells become a likelihood field ``exp(−d² / 2σ²)`` (``d`` the distance to
the nearest occupied cell, from a Euclidean distance transform). A scan is matched by an
exhaustive search of a window around the prior pose (the odometry prediction): every rotation
step, every translation step (one cell), scoring the mean field value at the scan's points; the
best candidate is then refined on a 4× finer lattice with bilinear interpolation. The
information matrix of the fit (the outer products of the field's gradient at the points) shows
whether the scan constrains both directions: in a featureless corridor it does not, and the
match is flagged *degenerate* (its ratio of smallest to largest translational eigenvalue is
below a threshold) so the caller keeps the prior instead of accepting a slide along the walls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from omnical.navigation.grid import OccupancyGrid

__all__ = ["LikelihoodField", "MatchParams", "MatchResult", "likelihood_field", "match_scan"]


@dataclass(frozen=True, eq=False)
class LikelihoodField:
    """The likelihood field of a map (same cells as the map; yaw of the origin must be 0).

    Attributes:
        values: (rows, cols) field in [0, 1].
        resolution_m: cell side.
        origin_xy_m: lower-left corner of cell (0, 0).
    """

    values: NDArray[np.float64]
    resolution_m: float
    origin_xy_m: tuple[float, float]


def likelihood_field(
    occupied: NDArray[np.bool_], grid: OccupancyGrid, sigma_m: float = 0.05
) -> LikelihoodField:
    """The likelihood field of the ``occupied`` cells of a grid with ``grid``'s geometry."""
    if occupied.any():
        d = ndimage.distance_transform_edt(~occupied) * grid.resolution_m
        values = np.exp(-0.5 * (np.asarray(d) / sigma_m) ** 2)
    else:
        values = np.zeros(occupied.shape)
    return LikelihoodField(
        np.ascontiguousarray(values, dtype=np.float64),
        grid.resolution_m,
        (grid.origin[0], grid.origin[1]),
    )


@dataclass(frozen=True)
class MatchParams:
    """Search window and acceptance.

    Attributes:
        window_xy_m: half-width of the translation window around the prior.
        window_yaw_rad: half-width of the rotation window.
        yaw_step_rad: rotation step of the coarse search.
        min_score: a match scoring less (mean field value) is rejected.
        degeneracy_ratio: smallest / largest translational information below this = degenerate.
        max_points: the scan is thinned to at most this many points.
    """

    window_xy_m: float = 0.15
    window_yaw_rad: float = math.radians(4.0)
    yaw_step_rad: float = math.radians(0.5)
    min_score: float = 0.35
    degeneracy_ratio: float = 0.04
    max_points: int = 180


@dataclass(frozen=True)
class MatchResult:
    """A scan match.

    Attributes:
        pose: (x, y, yaw) best pose (the prior when not accepted).
        score: mean field value at the scan points for the best pose.
        accepted: the match is good and not degenerate.
        degenerate: the scan does not constrain both translational directions.
        information: (3, 3) information matrix of the fit (x, y, yaw), unscaled.
        reason: why it was not accepted ("" if accepted).
    """

    pose: tuple[float, float, float]
    score: float
    accepted: bool
    degenerate: bool
    information: NDArray[np.float64]
    reason: str = ""


@numba.njit(cache=True)
def _bilinear(f: NDArray[np.float64], gx: float, gy: float) -> float:
    rows, cols = f.shape
    x = gx - 0.5
    y = gy - 0.5
    ix = math.floor(x)
    iy = math.floor(y)
    if ix < 0 or iy < 0 or ix + 1 >= cols or iy + 1 >= rows:
        return 0.0
    ax = x - ix
    ay = y - iy
    value: float = (
        (1 - ax) * (1 - ay) * f[iy, ix]
        + ax * (1 - ay) * f[iy, ix + 1]
        + (1 - ax) * ay * f[iy + 1, ix]
        + ax * ay * f[iy + 1, ix + 1]
    )
    return value


@numba.njit(cache=True)
def _search(
    f: NDArray[np.float64],
    px: NDArray[np.float64],
    py: NDArray[np.float64],
    x0: float,
    y0: float,
    th0: float,
    n_xy: int,
    step_xy: float,
    n_th: int,
    step_th: float,
) -> tuple[float, float, float, float]:
    """Exhaustive search (grid units); returns the best (x, y, theta, score)."""
    best = -1.0
    bx, by, bt = x0, y0, th0
    n = px.shape[0]
    for it in range(-n_th, n_th + 1):
        th = th0 + it * step_th
        c = math.cos(th)
        s = math.sin(th)
        rx = c * px - s * py
        ry = s * px + c * py
        for ix in range(-n_xy, n_xy + 1):
            tx = x0 + ix * step_xy
            for iy in range(-n_xy, n_xy + 1):
                ty = y0 + iy * step_xy
                total = 0.0
                for k in range(n):
                    total += _bilinear(f, rx[k] + tx, ry[k] + ty)
                score = total / n
                if score > best:
                    best = score
                    bx, by, bt = tx, ty, th
    return bx, by, bt, best


def _information(
    lf: LikelihoodField, pts: NDArray[np.float64], pose: tuple[float, float, float]
) -> NDArray[np.float64]:
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    wx = c * pts[:, 0] - s * pts[:, 1] + x
    wy = s * pts[:, 0] + c * pts[:, 1] + y
    gx = (wx - lf.origin_xy_m[0]) / lf.resolution_m
    gy = (wy - lf.origin_xy_m[1]) / lf.resolution_m
    fy, fx = np.gradient(lf.values)
    coords = np.vstack([gy - 0.5, gx - 0.5])
    dx = ndimage.map_coordinates(fx, coords, order=1, mode="constant") / lf.resolution_m
    dy = ndimage.map_coordinates(fy, coords, order=1, mode="constant") / lf.resolution_m
    # ∂(wx, wy)/∂th = (−(wy − y), wx − x)
    dth = dx * -(wy - y) + dy * (wx - x)
    jac = np.column_stack([dx, dy, dth])
    return np.asarray(jac.T @ jac)


def match_scan(
    lf: LikelihoodField,
    points_base: ArrayLike,
    prior: tuple[float, float, float],
    params: MatchParams | None = None,
) -> MatchResult:
    """Match scan points (base_link, (P, 2)) against a likelihood field around ``prior``."""
    p = params or MatchParams()
    pts = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] > p.max_points:
        pts = pts[np.linspace(0, pts.shape[0] - 1, p.max_points).round().astype(np.int64)]
    empty = np.zeros((3, 3))
    if pts.shape[0] < 10:
        return MatchResult(prior, 0.0, False, False, empty, "too few points")
    res = lf.resolution_m
    px = np.ascontiguousarray(pts[:, 0] / res)
    py = np.ascontiguousarray(pts[:, 1] / res)
    x0 = (prior[0] - lf.origin_xy_m[0]) / res
    y0 = (prior[1] - lf.origin_xy_m[1]) / res
    n_xy = max(1, math.ceil(p.window_xy_m / res))
    n_th = max(1, math.ceil(p.window_yaw_rad / p.yaw_step_rad))
    bx, by, bt, _ = _search(lf.values, px, py, x0, y0, prior[2], n_xy, 1.0, n_th, p.yaw_step_rad)
    bx, by, bt, _ = _search(lf.values, px, py, bx, by, bt, 2, 0.25, 2, p.yaw_step_rad / 4)
    bx, by, bt, score = _search(lf.values, px, py, bx, by, bt, 2, 0.0625, 2, p.yaw_step_rad / 16)
    pose = (bx * res + lf.origin_xy_m[0], by * res + lf.origin_xy_m[1], bt)
    info = _information(lf, pts, pose)
    eig = np.linalg.eigvalsh(info[:2, :2])
    degenerate = bool(eig[1] <= 0.0 or eig[0] / eig[1] < p.degeneracy_ratio)
    if score < p.min_score:
        return MatchResult(
            prior, float(score), False, degenerate, info, f"score {score:.2f} below {p.min_score}"
        )
    if degenerate:
        return MatchResult(
            prior,
            float(score),
            False,
            True,
            info,
            "degenerate: the scan constrains one direction only",
        )
    return MatchResult(pose, float(score), True, False, info)
