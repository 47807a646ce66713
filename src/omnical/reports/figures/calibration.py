"""Calibration figures (PNG, Agg): the procedure captures of seed 000 Figures 8–13, before/after.

:func:`plot_procedure` draws a run as the paper does (odometry started from the IPS, so its errors
show as the tracks part) with the fitted arcs; :func:`plot_measures` the §3.2 measures.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.text import Text
from matplotlib.ticker import FuncFormatter, MultipleLocator
from numpy.typing import ArrayLike, NDArray

from omnical.calibration.measures import Measures, MeasureSpec
from omnical.calibration.procedures.geometry import CircleFit, arc_length
from omnical.calibration.procedures.tracks import MoveArc, ProcedureTracks
from omnical.ips.beacons import BeaconMap
from omnical.reports.figures._common import save_figure

__all__ = ["arc_points", "odometry_in_map", "plot_measures", "plot_procedure"]

_Array = NDArray[np.float64]
_DPI = 130
_GRID_M = 0.5
_MIN_ALIGN_M = 0.3
_SIDE_GAP = 0.04
"""Space between the blocks of a procedure figure's side panel, in the panel's fraction."""


def arc_points(fit: CircleFit, start_xy_m: ArrayLike, end_xy_m: ArrayLike, n: int = 80) -> _Array:
    """Points along a fitted arc between the projections of two points.

    Args:
        fit: an arc (or line) from :func:`omnical.calibration.procedures.geometry.fit_circle`.
        start_xy_m: (2,) where the arc starts (projected onto it).
        end_xy_m: (2,) where it ends.
        n: number of points.

    Returns:
        (n, 2) positions, from the start to the end.
    """
    s0 = arc_length(fit, fit.point_xy_m, start_xy_m)
    s1 = arc_length(fit, fit.point_xy_m, end_xy_m)
    s = np.linspace(s0, s1, max(2, n))
    p = np.asarray(fit.point_xy_m, dtype=np.float64)
    if fit.centre_xy_m is None or fit.curvature_per_m == 0.0:
        h = fit.heading_rad
        return np.column_stack([p[0] + s * math.cos(h), p[1] + s * math.sin(h)])
    c = np.asarray(fit.centre_xy_m, dtype=np.float64)
    a = fit.curvature_per_m * s
    r = p - c
    x = c[0] + np.cos(a) * r[0] - np.sin(a) * r[1]
    y = c[1] + np.sin(a) * r[0] + np.cos(a) * r[1]
    return np.column_stack([x, y])


def _hedge_odometry(tracks: ProcedureTracks, offset_xy_m: _Array) -> tuple[_Array, _Array]:
    """Odometry track of the hedgehog (odom frame), and of the stand-stills."""
    pose = tracks.odom_pose
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    ox, oy = offset_xy_m
    track = np.column_stack([pose[:, 0] + c * ox - s * oy, pose[:, 1] + s * ox + c * oy])
    stills = []
    for k in sorted(tracks.stills):
        p = tracks.stills[k].odom_pose
        cy, sy = math.cos(p[2]), math.sin(p[2])
        stills.append([p[0] + cy * ox - sy * oy, p[1] + sy * ox + cy * oy])
    return track, np.asarray(stills, dtype=np.float64).reshape(-1, 2)


def odometry_in_map(tracks: ProcedureTracks, hedge_offset_xy_m: ArrayLike = (0.0, 0.0)) -> _Array:
    """The odometry's hedgehog track in the map, initialised from the IPS as seed 000 does.

    The first stand-still's odometry position is put on its IPS average, and the odometry is
    turned so that the chord to the first stand-still at least 0.3 m away points along the
    IPS chord between the same two stand-stills.

    Args:
        tracks: from :func:`omnical.calibration.procedures.tracks.procedure_tracks`.
        hedge_offset_xy_m: (2,) hedgehog position in base_link.

    Returns:
        (M, 2) hedgehog positions by odometry, in the map frame.
    """
    o = np.asarray(hedge_offset_xy_m, dtype=np.float64).ravel()[:2]
    track, odom_stills = _hedge_odometry(tracks, o)
    ips = np.array([tracks.stills[k].ips.mean_xy_m for k in sorted(tracks.stills)])
    if not len(ips):
        return track
    rotation = 0.0
    for j in range(1, len(ips)):
        d_odom = odom_stills[j] - odom_stills[0]
        d_ips = ips[j] - ips[0]
        if np.hypot(*d_odom) >= _MIN_ALIGN_M and np.hypot(*d_ips) >= _MIN_ALIGN_M:
            rotation = math.atan2(d_ips[1], d_ips[0]) - math.atan2(d_odom[1], d_odom[0])
            break
    c, s = math.cos(rotation), math.sin(rotation)
    rel = track - odom_stills[0]
    return np.column_stack(
        [ips[0][0] + c * rel[:, 0] - s * rel[:, 1], ips[0][1] + s * rel[:, 0] + c * rel[:, 1]]
    )


def _save(fig: Figure, path: str | Path) -> Path:
    return save_figure(fig, path, dpi=_DPI, tight=False)


def _below(ax: Axes, artist: Artist) -> float:
    """The height, in ``ax``'s axes fraction, of the bottom of what ``artist`` draws."""
    renderer = ax.figure.canvas.get_renderer()  # type: ignore[attr-defined]
    patch = artist.get_bbox_patch() if isinstance(artist, Text) else None
    if patch is not None:
        artist.draw(renderer)  # lays out the frame around the text
        extent = patch.get_window_extent(renderer)
    else:
        extent = artist.get_window_extent(renderer)
    return float(ax.transAxes.inverted().transform((0.0, extent.y0))[1])


def _arc_line(k: int, arc: MoveArc) -> str:
    return (
        f"{k} {arc.kind:<7} {arc.length_m:6.3f} m (odom {arc.odom_length_m:6.3f}), "
        f"κ {1e3 * arc.curvature_per_m:+6.1f} mrad/m"
    )


def plot_procedure(
    tracks: ProcedureTracks,
    arcs: Sequence[MoveArc],
    path: str | Path,
    *,
    beacons: BeaconMap | None = None,
    hedge_offset_xy_m: ArrayLike = (0.0, 0.0),
    title: str = "calibration procedure",
    measured: Sequence[str] = (),
) -> Path:
    """Draw one procedure run in the map as seed 000 Figures 8–13 do (docs/DESIGN-NOTES.md).

    Args:
        tracks: the run reduced by :func:`~omnical.calibration.procedures.tracks.procedure_tracks`.
        arcs: its translations from :func:`~omnical.calibration.procedures.tracks.move_arcs`.
        path: PNG to write.
        beacons: stationary beacons to draw (triangles), if given.
        hedge_offset_xy_m: (2,) hedgehog position in base_link (the odometry track is the
            hedgehog's, to compare with the IPS).
        title: figure title.
        measured: what the run measured (the factors, their σ, the change), one line each:
            framed at the top of the side panel, above the legend.

    Returns:
        The path written.
    """
    fig, (ax, side) = plt.subplots(
        1, 2, figsize=(12.0, 6.6), gridspec_kw={"width_ratios": [2.0, 1.0]}
    )
    if beacons is not None:
        b = beacons.positions_m
        ax.scatter(b[:, 0], b[:, 1], marker="^", s=90, c="0.3", zorder=5, label="beacons")
        for addr, (x, y, _) in zip(beacons.addresses, b, strict=True):
            ax.annotate(str(addr), (x, y), textcoords="offset points", xytext=(5, 5), fontsize=9)
    fix = tracks.fix_xy_m
    ax.plot(fix[:, 0], fix[:, 1], ".", color="tab:blue", ms=2.2, alpha=0.55, label="IPS positions")
    odom = odometry_in_map(tracks, hedge_offset_xy_m)
    ax.plot(odom[:, 0], odom[:, 1], "-", color="black", lw=1.1, label="odometry (hedgehog)")
    stills = np.array([s.ips.mean_xy_m for s in tracks.stills.values()]).reshape(-1, 2)
    ax.plot(
        stills[:, 0],
        stills[:, 1],
        "o",
        mfc="none",
        mec="tab:orange",
        ms=7,
        mew=1.3,
        label="stand-still averages",
        zorder=6,
    )
    lines = []
    for k, arc in enumerate(arcs, start=1):
        pts = arc_points(arc.fit, arc.before.ips.mean_xy_m, arc.after.ips.mean_xy_m)
        ax.plot(pts[:, 0], pts[:, 1], "-", color="tab:red", lw=1.8, alpha=0.85, zorder=4)
        mid = pts[int(len(pts) * (0.2 + 0.6 * ((0.618 * k) % 1.0)))]  # spread the labels
        ax.annotate(
            str(k),
            mid,
            fontsize=8,
            color="tab:red",
            ha="center",
            va="center",
            bbox={"boxstyle": "circle,pad=0.2", "fc": "white", "ec": "tab:red", "lw": 0.8},
            zorder=7,
        )
        lines.append(_arc_line(k, arc))
    if arcs:
        ax.plot([], [], "-", color="tab:red", lw=1.8, label="fitted arcs")
    if len(odom):
        ax.plot(
            odom[-1, 0],
            odom[-1, 1],
            "s",
            color="lightcoral",
            mec="darkred",
            ms=11,
            zorder=8,
            label="final, odometry",
        )
    if len(fix):
        tail = fix[tracks.fix_t_s >= tracks.fix_t_s[-1] - 1.0]
        end = np.median(tail, axis=0)
        ax.plot(
            end[0],
            end[1],
            "o",
            color="tab:blue",
            mec="navy",
            ms=11,
            alpha=0.8,
            zorder=8,
            label="final, IPS",
        )
    ax.xaxis.set_major_locator(MultipleLocator(_GRID_M))
    ax.yaxis.set_major_locator(MultipleLocator(_GRID_M))
    whole = FuncFormatter(lambda v, _pos: f"{v:.0f}" if abs(v - round(v)) < 1e-6 else "")
    ax.xaxis.set_major_formatter(whole)
    ax.yaxis.set_major_formatter(whole)
    ax.tick_params(labelsize=8)
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.35)
    ax.set_xlabel("x (m, map), grid 0.5 m")
    ax.set_ylabel("y (m, map)")
    ax.set_title(title, fontsize=11)
    handles, labels = ax.get_legend_handles_labels()
    side.axis("off")
    fig.tight_layout()
    # the side panel top down: the measured factors, the legend, the translations; each
    # placed under what is drawn above it (measured once laid out)
    top = 1.0
    if measured:
        box = side.text(
            0.0,
            top,
            "\n".join(measured),
            va="top",
            ha="left",
            family="monospace",
            fontsize=8,
            bbox={"boxstyle": "round,pad=0.5", "fc": "#fff5f0", "ec": "tab:red", "lw": 0.8},
        )
        top = _below(side, box) - _SIDE_GAP
    legend = side.legend(
        handles,
        labels,
        loc="upper left",
        bbox_to_anchor=(0.0, top),
        borderaxespad=0.0,
        fontsize=8,
        frameon=False,
    )
    text = "translations (robot centre, from the IPS arcs)\n\n" + (
        "\n".join(lines) if lines else "none usable"
    )
    top = _below(side, legend) - _SIDE_GAP
    side.text(0.0, top, text, va="top", ha="left", family="monospace", fontsize=7.5)
    return _save(fig, path)


def plot_measures(
    before: Measures,
    after: Measures,
    specs: Sequence[MeasureSpec],
    path: str | Path,
    *,
    title: str = "before and after calibration",
) -> Path:
    """Bars of the paper's measures: seed 000 and the twin, before and after calibration.

    Args:
        before: measures of the uncalibrated robot.
        after: measures of the calibrated robot.
        specs: the measures to draw, with the paper's values.
        path: PNG to write.
        title: figure title.

    Returns:
        The path written.
    """
    fig, axes = plt.subplots(1, len(specs), figsize=(2.6 * len(specs), 4.0), squeeze=False)
    colours = ("0.65", "tab:red", "0.35", "tab:green")
    names = ("seed 000\nbefore", "twin\nbefore", "seed 000\nafter (≤)", "twin\nafter")
    for ax, spec in zip(axes[0], specs, strict=True):
        values = (spec.paper_before, spec.value(before), spec.paper_after, spec.value(after))
        x = np.arange(4)
        ax.bar(x, values, color=colours, width=0.7)
        for xi, v in zip(x, values, strict=True):
            ax.annotate(
                f"{v:.3g}",
                (xi, v),
                textcoords="offset points",
                xytext=(0, 2),
                ha="center",
                fontsize=7.5,
            )
        ax.set_yscale("log")
        positive = [v for v in values if v > 0.0] or [1e-3]
        ax.set_ylim(min(positive) / 3.0, max(positive) * 2.5)
        ax.set_xticks(x, names, fontsize=6.5)
        verdict = "pass" if spec.passes(after) else "FAIL"
        ax.set_title(f"{spec.label}\n({spec.unit}) — {verdict}", fontsize=8.5)
        ax.grid(True, axis="y", alpha=0.3, which="both")
        ax.tick_params(axis="y", labelsize=7)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return _save(fig, path)
