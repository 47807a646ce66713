"""Correlative scan matching on a likelihood field (Olson 2009), and point-to-line refinement.

:func:`match_scan` searches a window around the prior pose and flags a degenerate match (a
corridor); :func:`refine_point_to_line` refines an accepted one by ICP on nearby scans' points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.spatial import cKDTree

from omnical.navigation.grid import OccupancyGrid

__all__ = [
    "LikelihoodField",
    "MatchParams",
    "MatchResult",
    "PointMap",
    "likelihood_field",
    "likelihood_field_window",
    "match_scan",
    "point_map",
    "point_normals",
    "refine_point_to_line",
]


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


@numba.njit(cache=True)
def _stamp(
    occupied: NDArray[np.bool_], kernel: NDArray[np.float64], out: NDArray[np.float64]
) -> None:
    """``out`` (the interior of ``occupied`` without a kernel-radius border) = the max of
    ``kernel`` centred on every occupied cell."""
    rows, cols = occupied.shape
    rad = kernel.shape[0] // 2
    for r in range(rows):
        for c in range(cols):
            if not occupied[r, c]:
                continue
            for i in range(kernel.shape[0]):
                orow = r + i - 2 * rad
                if orow < 0 or orow >= out.shape[0]:
                    continue
                for j in range(kernel.shape[1]):
                    ocol = c + j - 2 * rad
                    if 0 <= ocol < out.shape[1] and kernel[i, j] > out[orow, ocol]:
                        out[orow, ocol] = kernel[i, j]


def likelihood_field_window(
    occupied: NDArray[np.bool_],
    grid: OccupancyGrid,
    sigma_m: float,
    center_xy_m: tuple[float, float],
    half_width_m: float,
) -> LikelihoodField:
    """The likelihood field of the ``occupied`` cells in a square window around a point.

    Equals :func:`likelihood_field` inside the window up to a truncation at 4 σ, at a cost that
    does not grow with the map; the field's origin is the window's lower-left corner.
    """
    res = grid.resolution_m
    rad = max(1, math.ceil(4.0 * sigma_m / res))
    half = max(1, math.ceil(half_width_m / res))
    col, row = np.floor(
        (np.asarray(center_xy_m, dtype=np.float64) - np.asarray(grid.origin[:2])) / res
    ).astype(np.int64)
    rows, cols = occupied.shape
    r0, r1 = max(0, int(row) - half), min(rows, int(row) + half + 1)
    c0, c1 = max(0, int(col) - half), min(cols, int(col) + half + 1)
    if r1 <= r0 or c1 <= c0:
        r0, r1, c0, c1 = 0, 1, 0, 1
    ext = np.zeros((r1 - r0 + 2 * rad, c1 - c0 + 2 * rad), dtype=np.bool_)
    er0, ec0 = r0 - rad, c0 - rad
    sr0, sr1 = max(0, er0), min(rows, r1 + rad)
    sc0, sc1 = max(0, ec0), min(cols, c1 + rad)
    ext[sr0 - er0 : sr1 - er0, sc0 - ec0 : sc1 - ec0] = occupied[sr0:sr1, sc0:sc1]
    d = np.arange(-rad, rad + 1) * res
    kernel = np.exp(-0.5 * (d[:, None] ** 2 + d[None, :] ** 2) / sigma_m**2)
    values = np.zeros((r1 - r0, c1 - c0), dtype=np.float64)
    # out[orow] = ext row (orow + rad) = kernel centre at ext row r shifted by i - rad
    _stamp(ext, kernel, values)
    return LikelihoodField(values, res, (grid.origin[0] + c0 * res, grid.origin[1] + r0 * res))


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
        coarse_step_cells: translation step of the coarse search (cells; the finer searches
            divide it by 4 and 16).
        prior_sigma_xy_m, prior_sigma_yaw_rad: σ of the prior (the odometry prediction): a
            candidate's mean field value is lowered by ``½ (|Δt|² / σ_xy² + Δθ² / σ_yaw²)``;
            None = a flat prior (the window alone).
    """

    window_xy_m: float = 0.15
    window_yaw_rad: float = math.radians(4.0)
    yaw_step_rad: float = math.radians(0.5)
    min_score: float = 0.35
    degeneracy_ratio: float = 0.04
    max_points: int = 180
    coarse_step_cells: int = 2
    prior_sigma_xy_m: float | None = None
    prior_sigma_yaw_rad: float | None = None


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
    prior: tuple[float, float, float],
    w_xy: float,
    w_th: float,
) -> tuple[float, float, float, float]:
    """Exhaustive search (grid units) of the mean field minus the prior's penalty
    ``½ (w_xy |t − t_prior|² + w_th (θ − θ_prior)²)``; returns the best (x, y, theta) and its
    mean field value."""
    best = -math.inf
    best_score = 0.0
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
                penalised = score - 0.5 * (
                    w_xy * ((tx - prior[0]) ** 2 + (ty - prior[1]) ** 2)
                    + w_th * (th - prior[2]) ** 2
                )
                if penalised > best:
                    best = penalised
                    best_score = score
                    bx, by, bt = tx, ty, th
    return bx, by, bt, best_score


@numba.njit(cache=True)
def _gradient_at(
    f: NDArray[np.float64], gx: NDArray[np.float64], gy: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Central differences (one cell) of the bilinear field at the points (per cell)."""
    n = gx.shape[0]
    dx = np.empty(n)
    dy = np.empty(n)
    for k in range(n):
        dx[k] = 0.5 * (_bilinear(f, gx[k] + 1.0, gy[k]) - _bilinear(f, gx[k] - 1.0, gy[k]))
        dy[k] = 0.5 * (_bilinear(f, gx[k], gy[k] + 1.0) - _bilinear(f, gx[k], gy[k] - 1.0))
    return dx, dy


def _information(
    lf: LikelihoodField, pts: NDArray[np.float64], pose: tuple[float, float, float]
) -> NDArray[np.float64]:
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    wx = c * pts[:, 0] - s * pts[:, 1] + x
    wy = s * pts[:, 0] + c * pts[:, 1] + y
    gx = (wx - lf.origin_xy_m[0]) / lf.resolution_m
    gy = (wy - lf.origin_xy_m[1]) / lf.resolution_m
    dx, dy = _gradient_at(lf.values, np.ascontiguousarray(gx), np.ascontiguousarray(gy))
    dx /= lf.resolution_m
    dy /= lf.resolution_m
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
    step = float(p.coarse_step_cells)
    n_xy = max(1, math.ceil(p.window_xy_m / (res * step)))
    n_th = max(1, math.ceil(p.window_yaw_rad / p.yaw_step_rad))
    g0 = (x0, y0, float(prior[2]))
    w_xy = 0.0 if p.prior_sigma_xy_m is None else (res / p.prior_sigma_xy_m) ** 2
    w_th = 0.0 if p.prior_sigma_yaw_rad is None else p.prior_sigma_yaw_rad**-2
    f = lf.values
    bx, by, bt, _ = _search(
        f, px, py, x0, y0, g0[2], n_xy, step, n_th, p.yaw_step_rad, g0, w_xy, w_th
    )
    bx, by, bt, _ = _search(
        f, px, py, bx, by, bt, 2, step / 4, 2, p.yaw_step_rad / 4, g0, w_xy, w_th
    )
    bx, by, bt, score = _search(
        f, px, py, bx, by, bt, 2, step / 16, 2, p.yaw_step_rad / 16, g0, w_xy, w_th
    )
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


@dataclass(frozen=True, eq=False)
class PointMap:
    """Scan points in the world frame with their surface normals, for point-to-line refinement.

    Attributes:
        points_m: (N, 2) points.
        normals: (N, 2) unit normals (from the principal axes of each point's neighbours).
        planar: (N,) the neighbourhood is a line (the normal is meaningful).
        tree: k-d tree over ``points_m``.
    """

    points_m: NDArray[np.float64]
    normals: NDArray[np.float64]
    planar: NDArray[np.bool_]
    tree: cKDTree


def point_normals(
    points_m: ArrayLike, neighbours: int = 7, planarity: float = 0.1
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """(P, 2) unit normals of points (P, 2) from the principal axes of their ``neighbours``
    nearest points, and (P,) whether each neighbourhood is a line (its smaller spread below
    ``planarity`` × the larger) so that the normal is meaningful."""
    pts = np.asarray(points_m, dtype=np.float64).reshape(-1, 2)
    k = min(neighbours, pts.shape[0])
    if k < 3:
        return np.zeros_like(pts), np.zeros(pts.shape[0], dtype=bool)
    _, idx = cKDTree(pts).query(pts, k)
    nb = pts[idx]
    centred = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", centred, centred)
    w, v = np.linalg.eigh(cov)
    return np.ascontiguousarray(v[:, :, 0]), np.asarray(w[:, 0] < planarity * w[:, 1])


def point_map(
    points_m: ArrayLike,
    normals: ArrayLike | None = None,
    planar: ArrayLike | None = None,
) -> PointMap:
    """A :class:`PointMap` of ``points_m`` (P, 2); without ``normals`` and ``planar`` they come
    from :func:`point_normals`."""
    pts = np.asarray(points_m, dtype=np.float64).reshape(-1, 2)
    if normals is None or planar is None:
        nrm, flat = point_normals(pts)
    else:
        nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 2)
        flat = np.asarray(planar, dtype=np.bool_).reshape(-1)
    return PointMap(pts, nrm, flat, cKDTree(pts))


def refine_point_to_line(
    pm: PointMap,
    points_base: ArrayLike,
    prior: tuple[float, float, float],
    max_distance_m: float = 0.08,
    iterations: int = 15,
    *,
    damping: float = 1e-3,
    point_sigma_m: float = 0.01,
    prior_sigmas: tuple[float, float, float] | None = None,
    max_points: int = 180,
) -> tuple[tuple[float, float, float], float]:
    """Point-to-line ICP of scan points (base_link) on ``pm`` from ``prior`` (a correlative match).

    Pairs farther than ``max_distance_m`` or non-planar are left out (scan thinned to
    ``max_points``); Levenberg–Marquardt steps on the point-to-line residuals (σ
    ``point_sigma_m``, ``damping`` × the diagonal), optionally with a Gaussian prior at
    ``prior`` (σ ``prior_sigmas``; none by default).

    Returns:
        The refined pose and the fraction of points paired at the end (the prior and 0.0 when
        fewer than ten pairs are found).
    """
    src = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
    if src.shape[0] > max_points:
        src = src[np.linspace(0, src.shape[0] - 1, max_points).round().astype(np.int64)]
    p0 = np.array(prior, dtype=np.float64)
    w_prior = (
        np.zeros((3, 3))
        if prior_sigmas is None
        else np.diag(np.asarray(prior_sigmas, dtype=np.float64) ** -2)
    )
    w_point = point_sigma_m**-2
    pose = p0.copy()
    fraction = 0.0
    for _ in range(iterations):
        x, y, th = pose
        c, s = math.cos(th), math.sin(th)
        w = np.column_stack([c * src[:, 0] - s * src[:, 1] + x, s * src[:, 0] + c * src[:, 1] + y])
        d, i = pm.tree.query(w, distance_upper_bound=max_distance_m)
        ok = np.isfinite(d)
        ok[ok] = pm.planar[i[ok]]
        if ok.sum() < 10:
            return (float(prior[0]), float(prior[1]), float(prior[2])), 0.0
        fraction = float(ok.mean())
        n = pm.normals[i[ok]]
        q = pm.points_m[i[ok]]
        pw = w[ok]
        r = ((pw - q) * n).sum(axis=1)
        jac = np.column_stack([n, n[:, 0] * -(pw[:, 1] - y) + n[:, 1] * (pw[:, 0] - x)])
        jtj = w_point * (jac.T @ jac)
        h = jtj + np.diag(damping * np.diag(jtj) + 1e-9) + w_prior
        g = w_point * (jac.T @ r) + w_prior @ (pose - p0)
        step = -np.linalg.solve(h, g)
        pose = pose + step
        if abs(step[0]) < 1e-4 and abs(step[1]) < 1e-4 and abs(step[2]) < 1e-5:
            break
    return (float(pose[0]), float(pose[1]), float(pose[2])), fraction
