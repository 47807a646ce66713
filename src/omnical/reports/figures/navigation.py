"""Navigation figures like seed 001 Figures 12–13: the mapping run (scans and tracked poses,
the map it built), navigating on the map (inflated obstacles, roadmap, planned and driven
paths with the start and the goals), and a planned path on its map (``omnical plan``)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection
from matplotlib.colors import ListedColormap, Normalize
from matplotlib.figure import Figure
from mpl_toolkits.axes_grid1 import make_axes_locatable  # type: ignore[import-untyped]
from numpy.typing import ArrayLike, NDArray

from omnical.navigation.grid import FREE, OCCUPIED, OccupancyGrid
from omnical.reports.figures._common import save_figure

__all__ = ["plot_mapping", "plot_navigation", "plot_plan"]

# unknown light grey, free white, occupied black (a map_server map as RViz shows it)
_MAP_COLOURS = ListedColormap(["#d9d9d9", "#ffffff", "#000000"])


_MAX_EDGES_DRAWN = 20_000
"""Most roadmap edges drawn in a navigation figure."""


def _map_image(grid: OccupancyGrid) -> NDArray[np.int8]:
    img = np.zeros(grid.shape, dtype=np.int8)
    img[grid.cells == FREE] = 1
    img[grid.cells == OCCUPIED] = 2
    return img


def _extent(grid: OccupancyGrid) -> tuple[float, float, float, float]:
    ox, oy, _ = grid.origin
    rows, cols = grid.shape
    r = grid.resolution_m
    return (ox, ox + cols * r, oy, oy + rows * r)


def _draw_map(ax: Axes, grid: OccupancyGrid) -> None:
    ax.imshow(
        _map_image(grid),
        cmap=_MAP_COLOURS,
        vmin=0,
        vmax=2,
        origin="lower",
        extent=_extent(grid),
        interpolation="nearest",
    )


def _finish(fig: Figure, path: Path) -> Path:
    # the one figure writer: its PNGs carry omnical's Software record, by which
    # --overwrite recognises omnical's own figures (reports.outputs.is_figure)
    return save_figure(fig, path, dpi=130, crop=True)


def _crop_to(ax: Axes, xy: NDArray[np.float64], margin_m: float) -> None:
    lo, hi = xy.min(axis=0) - margin_m, xy.max(axis=0) + margin_m
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])


def plot_mapping(
    path: Path,
    *,
    grid: OccupancyGrid,
    poses: ArrayLike,
    scan_points_world: Sequence[ArrayLike],
    odometry: ArrayLike | None = None,
    truth: ArrayLike | None = None,
    keyframes: ArrayLike | None = None,
    loop_pairs: ArrayLike | None = None,
    scan_t_s: ArrayLike | None = None,
    title: str = "",
) -> Path:
    """Seed 001 Fig. 12: left, a sample of the scans at their SLAM poses and the tracked path,
    coloured by time (a colour bar says which); right, the map built (trinary), with the SLAM
    path, the raw odometry and the truth.

    Args:
        path: PNG to write.
        grid: the map built.
        poses: (M, 3) SLAM poses at the scans.
        scan_points_world: scans' hit points in the map frame, each (P, 2).
        odometry: (M, 3) raw odometry in the map frame (optional).
        truth: (M, 3) true poses (optional; only on the twin).
        keyframes: (K,) scan index of each keyframe (optional).
        loop_pairs: (L, 2) keyframe-index pairs with an accepted loop closure (optional).
        scan_t_s: (S,) time of each scan drawn, s since the first scan of the run (None: the
            scans are coloured in their order, said so on the colour bar).
        title: figure title.
    """
    est = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 6.2))
    count = len(scan_points_world)
    if scan_t_s is not None:
        when = np.asarray(scan_t_s, dtype=np.float64).reshape(-1)
        what = "time since the first scan (s)"
    else:
        when, what = np.arange(count, dtype=np.float64), "scan, in the order of time"
    if when.size != count:
        msg = f"plot_mapping: {when.size} scan times for {count} scans"
        raise ValueError(msg)
    span = (float(when.min()), float(when.max())) if count else (0.0, 1.0)
    norm = Normalize(span[0], span[1] if span[1] > span[0] else span[0] + 1.0)
    cmap = plt.get_cmap("viridis")
    colours = cmap(norm(when))
    for pts, colour in zip(scan_points_world, colours, strict=False):
        p = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        left.plot(p[:, 0], p[:, 1], ".", ms=1.0, color=colour, alpha=0.6)
    left.plot(est[:, 0], est[:, 1], "-", color="tab:red", lw=1.2, label="tracked poses (SLAM)")
    if keyframes is not None:
        kf = est[np.asarray(keyframes, dtype=np.int64)]
        left.quiver(
            kf[:, 0],
            kf[:, 1],
            np.cos(kf[:, 2]),
            np.sin(kf[:, 2]),
            color="tab:red",
            alpha=0.6,
            scale=45,
            width=0.0018,
            label="keyframes (heading)",
        )
        if loop_pairs is not None:
            pairs = np.asarray(loop_pairs, dtype=np.int64).reshape(-1, 2)
            for n, (i, j) in enumerate(pairs):
                a, b = kf[i], kf[j]
                left.plot(
                    [a[0], b[0]],
                    [a[1], b[1]],
                    "-",
                    color="tab:orange",
                    lw=1.0,
                    label="loop closures" if n == 0 else None,
                )
    left.plot(est[0, 0], est[0, 1], "s", color="tab:green", ms=8, label="start")
    left.set_title(f"{count} scans (colour: time) and the tracked poses", fontsize=10)
    _draw_map(right, grid)
    if odometry is not None:
        od = np.asarray(odometry, dtype=np.float64).reshape(-1, 3)
        right.plot(od[:, 0], od[:, 1], "-", color="tab:gray", lw=1.0, label="wheel odometry")
    if truth is not None:
        gt = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
        right.plot(gt[:, 0], gt[:, 1], "-", color="tab:blue", lw=2.2, alpha=0.6, label="truth")
    right.plot(est[:, 0], est[:, 1], "-", color="tab:red", lw=1.0, label="SLAM")
    right.plot(est[0, 0], est[0, 1], "s", color="tab:green", ms=8, label="start")
    right.set_title("occupancy map (black occupied, white free, grey unknown)", fontsize=10)
    hits = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in scan_points_world]
    everything = np.vstack([est[:, :2], *hits]) if hits else est[:, :2]
    for ax in (left, right):
        ax.set_aspect("equal")
        _crop_to(ax, everything, 0.5)
        ax.grid(True, alpha=0.25)
        ax.set_xlabel("x (m, map frame)")
        ax.set_ylabel("y (m)")
        ax.legend(loc="upper right", fontsize=7, framealpha=0.9)
    # in an axes of the left one's height (it keeps its equal scales), not beside its box
    bar_ax = make_axes_locatable(left).append_axes("right", size="2.5%", pad=0.08)
    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=bar_ax)
    bar.set_label(what, fontsize=8)
    bar.ax.tick_params(labelsize=7)
    if title:
        fig.suptitle(title, fontsize=11)
    return _finish(fig, path)


_MAP_VIEW_WIDTH_IN = 8.0
"""Width of the map in a navigation or plan figure; the height follows the map's shape."""
_MAP_VIEW_MARGIN_M = 0.3
"""Free border around the known part of the map."""


def _map_view(grid: OccupancyGrid) -> tuple[float, float, float, float]:
    """The limits (x0, x1, y0, y1) around the known part of the map (the whole map if none)."""
    known = np.argwhere(~grid.unknown)
    if not known.size:
        return _extent(grid)
    xy = grid.cell_to_world(known)
    lo, hi = xy.min(axis=0) - _MAP_VIEW_MARGIN_M, xy.max(axis=0) + _MAP_VIEW_MARGIN_M
    return (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))


def _map_figure(
    grid: OccupancyGrid, blocked: ArrayLike
) -> tuple[Figure, Axes, tuple[float, float, float, float]]:
    """A figure shaped like the map's known part (the legend goes under it, not beside: beside,
    it took half the width), the map and its inflated obstacles drawn; and the view's limits."""
    view = _map_view(grid)
    aspect = (view[3] - view[2]) / max(view[1] - view[0], 1e-9)
    height = min(max(_MAP_VIEW_WIDTH_IN * aspect, 3.0), 11.0)
    fig, ax = plt.subplots(figsize=(_MAP_VIEW_WIDTH_IN + 0.8, height + 2.2))
    _draw_map(ax, grid)
    inflated = np.asarray(blocked, dtype=bool) & grid.free  # unknown cells stay grey
    overlay = np.ma.masked_where(~inflated, inflated.astype(np.float64))
    ax.imshow(
        overlay,
        cmap=ListedColormap(["#f4a6a6"]),
        vmin=0,
        vmax=1,
        origin="lower",
        extent=_extent(grid),
        interpolation="nearest",
        alpha=0.7,
    )
    ax.plot([], [], "s", color="#f4a6a6", ms=8, label="inflated obstacles")
    return fig, ax, view


def _draw_roadmap(ax: Axes, roadmap_nodes: ArrayLike, roadmap_edges: ArrayLike) -> None:
    nodes = np.asarray(roadmap_nodes, dtype=np.float64).reshape(-1, 2)
    edges = np.asarray(roadmap_edges, dtype=np.int64).reshape(-1, 2)
    # A dense roadmap (10⁵ edges) is a haze at this size and costs seconds to draw: at
    # most _MAX_EDGES_DRAWN, evenly taken, as one collection; the legend says how many.
    every = max(1, -(-len(edges) // _MAX_EDGES_DRAWN))
    shown = edges[::every]
    segs = np.stack([nodes[shown[:, 0]], nodes[shown[:, 1]]], axis=1)
    ax.add_collection(LineCollection(list(segs), colors="#c6dbef", linewidths=0.3, alpha=0.5))
    label = f"roadmap (PRM: {len(nodes)} nodes, {len(edges)} edges"
    label += f", 1 in {every} drawn)" if every > 1 else ")"
    ax.plot([], [], "-", color="#c6dbef", lw=1.0, label=label)
    ax.plot(nodes[:, 0], nodes[:, 1], ".", color="#6baed6", ms=1.0, alpha=0.6)


def _finish_map_view(
    fig: Figure, ax: Axes, view: tuple[float, float, float, float], title: str, path: Path
) -> Path:
    ax.set_aspect("equal")
    ax.set_xlim(view[0], view[1])
    ax.set_ylim(view[2], view[3])
    ax.set_xlabel("x (m, map frame)")
    ax.set_ylabel("y (m)")
    ax.grid(True, alpha=0.25)
    ax.legend(
        loc="upper center",
        bbox_to_anchor=(0.5, -0.09),
        ncol=2,
        fontsize=8,
        framealpha=0.9,
        borderaxespad=0.0,
    )
    if title:
        ax.set_title(title, fontsize=10)
    return _finish(fig, path)


def plot_navigation(
    path: Path,
    *,
    grid: OccupancyGrid,
    blocked: ArrayLike,
    start: ArrayLike,
    goals: ArrayLike,
    planned: Sequence[ArrayLike],
    driven: ArrayLike,
    roadmap_nodes: ArrayLike | None = None,
    roadmap_edges: ArrayLike | None = None,
    estimated: ArrayLike | None = None,
    title: str = "",
) -> Path:
    """Seed 001 Fig. 13: the map with its inflated obstacles, the roadmap, the planned legs,
    the driven path (truth) and the localised estimate, the start and the goals.

    Args:
        path: PNG to write.
        grid: the map planned on.
        blocked: (rows, cols) True where the robot's centre may not go (inflation).
        start: (x, y[, yaw]) start.
        goals: (G, 2) goals.
        planned: each leg's planned path (K, 2).
        driven: (N, 2+) the true path driven.
        roadmap_nodes, roadmap_edges: the PRM (N, 2) and (E, 2) (optional).
        estimated: (N, 2+) the localised estimate (optional).
        title: figure title.
    """
    fig, ax, view = _map_figure(grid, blocked)
    if roadmap_nodes is not None and roadmap_edges is not None:
        _draw_roadmap(ax, roadmap_nodes, roadmap_edges)
    if estimated is not None:
        e = np.asarray(estimated, dtype=np.float64)
        ax.plot(e[:, 0], e[:, 1], "-", color="tab:orange", lw=1.0, label="localised estimate")
    d = np.asarray(driven, dtype=np.float64)
    ax.plot(d[:, 0], d[:, 1], "-", color="tab:blue", lw=2.0, label="driven (truth)")
    for n, leg in enumerate(planned):
        p = np.asarray(leg, dtype=np.float64).reshape(-1, 2)
        if len(p):
            ax.plot(
                p[:, 0],
                p[:, 1],
                "--o",
                color="tab:purple",
                lw=1.3,
                ms=4,
                label="planned legs" if n == 0 else None,
            )
    s = np.asarray(start, dtype=np.float64)
    ax.plot(s[0], s[1], "s", color="tab:green", ms=10, label="start")
    g = np.asarray(goals, dtype=np.float64).reshape(-1, 2)
    ax.plot(g[:, 0], g[:, 1], "*", color="tab:red", ms=15, mec="black", label="goals")
    for k, (x, y) in enumerate(g, 1):
        ax.annotate(f"G{k}", (x, y), textcoords="offset points", xytext=(6, 6), fontsize=9)
    return _finish_map_view(fig, ax, view, title, path)


def plot_plan(
    path: Path,
    *,
    grid: OccupancyGrid,
    blocked: ArrayLike,
    start: ArrayLike,
    goal: ArrayLike,
    planned: ArrayLike,
    raw: ArrayLike | None = None,
    roadmap_nodes: ArrayLike | None = None,
    roadmap_edges: ArrayLike | None = None,
    title: str = "",
) -> Path:
    """A planned path on its map (``omnical plan``): the inflated obstacles, the roadmap, the
    path before and after shortcutting, the start and the goal.

    Args:
        path: PNG to write.
        grid: the map planned on.
        blocked: (rows, cols) True where the robot's centre may not go (inflation).
        start: (x, y) start.
        goal: (x, y) goal.
        planned: (K, 2) the path's way-points (after shortcutting).
        raw: (R, 2) the path the roadmap or A* found, before shortcutting (optional).
        roadmap_nodes, roadmap_edges: the PRM (N, 2) and (E, 2) (optional).
        title: figure title.
    """
    fig, ax, view = _map_figure(grid, blocked)
    if roadmap_nodes is not None and roadmap_edges is not None:
        _draw_roadmap(ax, roadmap_nodes, roadmap_edges)
    p = np.asarray(planned, dtype=np.float64).reshape(-1, 2)
    ax.plot(p[:, 0], p[:, 1], "-o", color="tab:purple", lw=1.8, ms=5, label="planned path")
    if raw is not None:  # over the path: where they agree, its way-points still show
        r = np.asarray(raw, dtype=np.float64).reshape(-1, 2)
        ax.plot(
            r[:, 0],
            r[:, 1],
            "--x",
            color="tab:orange",
            lw=1.0,
            ms=6,
            label="found, before shortcutting",
        )
    s = np.asarray(start, dtype=np.float64).reshape(-1)
    ax.plot(s[0], s[1], "s", color="tab:green", ms=10, label="start")
    g = np.asarray(goal, dtype=np.float64).reshape(-1)
    ax.plot(g[0], g[1], "*", color="tab:red", ms=15, mec="black", label="goal")
    return _finish_map_view(fig, ax, view, title, path)
