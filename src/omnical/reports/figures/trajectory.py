"""Trajectory tracking figures (PNG, Agg): paths, coordinates over time, speeds over time.

:func:`plot_tracking_paths` (seed 000 Fig. 16), :func:`plot_position_time` (Fig. 17),
:func:`plot_speeds` (seed 001 Figs. 9, 11); a long run drawn through :func:`envelope_indices`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Final

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import EllipseCollection
from matplotlib.figure import Figure
from numpy.typing import ArrayLike, NDArray

from omnical.errors import GeometryError
from omnical.ips.solve.fixes import CHI2_2DOF_95
from omnical.reports.figures._common import save_figure, wrap_title

__all__ = [
    "ESTIMATE_STYLE",
    "alignment_note",
    "confidence_radius_m",
    "envelope_indices",
    "plot_position_time",
    "plot_speeds",
    "plot_tracking_paths",
]

FloatArray = NDArray[np.float64]

ESTIMATE_STYLE: dict[str, tuple[str, str]] = {
    "reference": ("tab:red", "reference"),
    "odometry": ("black", "odometry"),
    "ips": ("tab:blue", "IPS (Marvelmind)"),
    "multilateration": ("tab:green", "multilateration"),
    "ground_truth": ("tab:gray", "ground truth"),
    "smoothed": ("tab:purple", "smoothed (IPS + odometry)"),
    "seed003": ("tab:orange", "dead wheels + IMU (seed 003)"),
}
"""Colour and legend label per estimate name (seed 000 Figure 16 colours)."""

_DPI = 130
MAX_SERIES_POINTS: Final = 4000
MAX_PATH_POINTS: Final = 50_000
"""A path in the plane longer than this is drawn through every k-th point (:func:`_thinned`):
at 50 Hz a robot moves millimetres between samples, far below a pixel of a floor plan."""
"""A series over time longer than this is drawn through :func:`envelope_indices` (≈ 1000 bins:
finer than the pixels of the axes)."""


def envelope_indices(values: ArrayLike, max_points: int = MAX_SERIES_POINTS) -> NDArray[np.intp]:
    """The samples of a series that draw the same curve at figure scale, in order.

    All of them when there are at most ``max_points`` (or a value is not finite: the gaps a
    NaN makes are kept as they are); else, for each of ``max_points // 4`` bins of consecutive
    samples, its first, last, lowest and highest — the min/max envelope a line the width of
    the axes shows.
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    n = v.size
    if n <= max(max_points, 4) or not np.all(np.isfinite(v)):
        return np.arange(n)
    bins = max(1, max_points // 4)
    size = -(-n // bins)
    padded = np.concatenate([v, np.full(bins * size - n, v[-1])]).reshape(bins, size)
    first = np.arange(bins) * size
    picks = np.concatenate(
        [
            first,
            first + size - 1,
            first + np.argmin(padded, axis=1),
            first + np.argmax(padded, axis=1),
            [n - 1],
        ]
    )
    out: NDArray[np.intp] = np.unique(np.minimum(picks, n - 1))
    return out


def _thinned(xy: FloatArray, max_points: int = MAX_PATH_POINTS) -> FloatArray:
    """``xy`` through every k-th point (the last one kept), at most about ``max_points``."""
    n = xy.shape[0]
    if n <= max_points:
        return xy
    keep = np.unique(np.concatenate([np.arange(0, n, -(-n // max_points)), [n - 1]]))
    out: FloatArray = xy[keep]
    return out


def _step_indices(values: FloatArray) -> NDArray[np.intp]:
    """The samples of a step signal (held until the next) where it changes, with its ends:
    the same steps, exactly."""
    n = values.shape[0]
    if n <= 2:
        return np.arange(n)
    changed = np.any(values[1:] != values[:-1], axis=1)
    out: NDArray[np.intp] = np.unique(np.concatenate([[0], np.flatnonzero(changed) + 1, [n - 1]]))
    return out


def confidence_radius_m(covariance_xy_m2: ArrayLike, scale: float = CHI2_2DOF_95) -> FloatArray:
    """Radius of the circle that holds the confidence ellipse: sqrt(scale · largest eigenvalue).

    Args:
        covariance_xy_m2: (N, 2, 2) horizontal covariances, m².
        scale: χ² quantile of the ellipse (default 95 % with two degrees of freedom).
    """
    cov = np.asarray(covariance_xy_m2, dtype=np.float64)
    if cov.ndim != 3 or cov.shape[1:] != (2, 2):
        raise GeometryError(f"covariances must be (N, 2, 2), got {cov.shape}")
    largest = np.linalg.eigvalsh(0.5 * (cov + np.swapaxes(cov, 1, 2)))[:, -1]
    out: FloatArray = np.sqrt(scale * np.clip(largest, 0.0, None))
    return out


def _xy(name: str, values: ArrayLike) -> FloatArray:
    xy = np.asarray(values, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] < 2:
        raise GeometryError(f"{name}: positions must be (N, 2), got {xy.shape}")
    return xy[:, :2]


def _save(fig: Figure, path: str | Path) -> Path:
    return save_figure(fig, path, dpi=_DPI, tight=True)


def _style(name: str, index: int) -> tuple[str, str]:
    return ESTIMATE_STYLE.get(name, (f"C{index % 10}", name))


def plot_tracking_paths(
    path: str | Path,
    *,
    reference_xy_m: ArrayLike,
    odometry_xy_m: ArrayLike | None = None,
    ips_xy_m: ArrayLike | None = None,
    multilateration_xy_m: ArrayLike | None = None,
    multilateration_cov_xy_m2: ArrayLike | None = None,
    lines_xy_m: Mapping[str, ArrayLike] | None = None,
    title: str = "trajectory tracking",
    frame: str = "reference frame",
    max_circles: int = 300,
    reference_label: str = "reference",
    alignments: Mapping[str, str] | None = None,
) -> Path:
    """Draw the paths of seed 000 Figure 16 in one frame, axes to equal scale.

    Args:
        path: PNG to write.
        reference_xy_m: (N, 2) reference path (red line).
        odometry_xy_m: (N, 2) aligned odometry (black line).
        ips_xy_m: (N, 2) aligned vendor IPS positions (blue).
        multilateration_xy_m: (N, 2) aligned multilateration fixes (green points).
        multilateration_cov_xy_m2: (N, 2, 2) their covariances: 95 % confidence circles
            (:func:`confidence_radius_m`), at most ``max_circles`` evenly subsampled.
        lines_xy_m: further estimates drawn as lines, name → (N, 2) aligned path (e.g. the
            smoothed trajectory, seed 003's dead-wheel estimate; styles of
            :data:`ESTIMATE_STYLE`).
        title: figure title.
        frame: name of the frame of all positions, for the axis labels.
        max_circles: largest number of circles drawn.
        reference_label: the reference's legend entry (e.g. "reference = ground truth").
        alignments: estimate name → how it was carried onto the reference (an
            :class:`omnical.choices.AlignMode`: ``none``, ``origin``, ``se2``), said under the
            legend (:func:`alignment_note`).

    Raises:
        GeometryError: an array has the wrong shape.
    """
    fig, ax = plt.subplots(figsize=(8, 7))
    ref = _xy("reference", reference_xy_m)
    if ips_xy_m is not None:
        ips = _xy("ips", ips_xy_m)
        color, label = ESTIMATE_STYLE["ips"]
        joined = _thinned(ips)  # the line between the fixes; every fix is still a dot
        ax.plot(joined[:, 0], joined[:, 1], "-", color=color, lw=0.4, alpha=0.35)
        ax.plot(ips[:, 0], ips[:, 1], ".", color=color, ms=2.5, alpha=0.8, label=label)
    if multilateration_xy_m is not None:
        mlat = _xy("multilateration", multilateration_xy_m)
        color, label = ESTIMATE_STYLE["multilateration"]
        ax.plot(mlat[:, 0], mlat[:, 1], ".", color=color, ms=2.5, label=label)
        if multilateration_cov_xy_m2 is not None and len(mlat):
            radius = confidence_radius_m(multilateration_cov_xy_m2)
            if radius.shape[0] != mlat.shape[0]:
                raise GeometryError(
                    f"{radius.shape[0]} covariances for {mlat.shape[0]} multilateration fixes"
                )
            idx = np.flatnonzero(np.isfinite(radius) & np.all(np.isfinite(mlat), axis=1))
            idx = idx[:: max(1, -(-idx.size // max(1, max_circles)))]
            if idx.size:
                circles = EllipseCollection(
                    2 * radius[idx],
                    2 * radius[idx],
                    np.zeros(idx.size),
                    units="xy",
                    offsets=mlat[idx],
                    offset_transform=ax.transData,
                    facecolors="none",
                    edgecolors=color,
                    linewidths=0.5,
                    alpha=0.6,
                )
                ax.add_collection(circles)
                ax.plot([], [], "o", mfc="none", color=color, label="95 % confidence circles")
    if odometry_xy_m is not None:
        odom = _thinned(_xy("odometry", odometry_xy_m))
        color, label = ESTIMATE_STYLE["odometry"]
        ax.plot(odom[:, 0], odom[:, 1], "-", color=color, lw=1.0, label=label)
    for index, (name, xy_m) in enumerate((lines_xy_m or {}).items()):
        line = _thinned(_xy(name, xy_m))
        color, label = _style(name, index)
        if name == "ground_truth":
            # wide and light, over the reference but under the dashed estimates: what the
            # robot did, which a good estimate covers without hiding it
            ax.plot(
                line[:, 0], line[:, 1], "-", color=color, lw=2.6, alpha=0.6, label=label, zorder=4.5
            )
            continue
        # on top of the reference, dashed: a good estimate lies on it and must still show
        ax.plot(line[:, 0], line[:, 1], "--", color=color, lw=1.1, label=label, zorder=6)
    color = ESTIMATE_STYLE["reference"][0]
    drawn = _thinned(ref)
    ax.plot(drawn[:, 0], drawn[:, 1], "-", color=color, lw=1.6, label=reference_label, zorder=4)
    if len(ref):
        ax.plot(ref[0, 0], ref[0, 1], "o", color=color, ms=7, mfc="white", zorder=5, label="start")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel(f"x (m, {frame})")
    ax.set_ylabel(f"y (m, {frame})")
    ax.set_title(wrap_title(title, fig.get_figwidth()))
    # beside the plan, not over it: a path fills its axes
    legend = ax.legend(
        loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=8, framealpha=0.9
    )
    note = alignment_note(alignments or {})
    if note:  # under the legend, which names what it speaks of
        renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
        below = legend.get_window_extent(renderer).y0
        y = float(ax.transAxes.inverted().transform((0.0, below))[1]) - 0.03
        ax.text(1.025, y, note, transform=ax.transAxes, va="top", ha="left", fontsize=7.5)
    return save_figure(fig, path, dpi=_DPI, tight=False, crop=True)


_ALIGNED: Final = {
    "none": "as recorded (same frame)",
    "origin": "at the start: first poses made to coincide",
    "se2": "best fit: rotation + translation\nover the run (least squares, no scale)",
}
"""What each alignment mode did (:mod:`omnical.evaluation.alignment`), for a figure."""


def alignment_note(alignments: Mapping[str, str]) -> str:
    """How the estimates drawn were carried onto the reference, grouped by mode; "" if none.

    Args:
        alignments: estimate name → alignment mode (``none``, ``origin``, ``se2``).
    """
    by_mode: dict[str, list[str]] = {}
    for index, (name, mode) in enumerate(alignments.items()):
        by_mode.setdefault(str(mode), []).append(_style(name, index)[1])
    if not by_mode:
        return ""
    lines = ["aligned onto the reference:"]
    for mode, names in by_mode.items():
        what = _ALIGNED.get(mode, mode).replace("\n", "\n    ")
        lines.append(f"• {', '.join(names)}:\n    {what}")
    return "\n".join(lines)


def plot_position_time(
    path: str | Path,
    *,
    reference: tuple[ArrayLike, ArrayLike],
    estimates: Mapping[str, tuple[ArrayLike, ArrayLike]],
    title: str = "position over time",
    frame: str = "reference frame",
    reference_label: str = "reference",
) -> Path:
    """Draw x(t) and y(t) of each estimate against the reference (seed 000 Figure 17).

    Args:
        path: PNG to write.
        reference: ``(t_s, xy_m)``, (N,) seconds and (N, 2) metres.
        estimates: name → ``(t_s, xy_m)``; names of :data:`ESTIMATE_STYLE` get its colours.
        title: figure title.
        frame: name of the frame of all positions, for the axis labels.
        reference_label: the reference's legend entry.

    Raises:
        GeometryError: an array has the wrong shape.
    """
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    series = [("reference", reference), *estimates.items()]
    for i, (name, (t, values)) in enumerate(series):
        t_s = np.asarray(t, dtype=np.float64)
        xy = _xy(name, values)
        if t_s.shape != (xy.shape[0],):
            raise GeometryError(f"{name}: {t_s.shape} times for {xy.shape[0]} positions")
        color, label = _style(name, i)
        is_ref = name == "reference"
        if is_ref:
            label = reference_label
        for axis, ax in enumerate(axes):
            keep = envelope_indices(xy[:, axis])
            ax.plot(
                t_s[keep],
                xy[keep, axis],
                "-",
                color=color,
                lw=1.6 if is_ref else 0.9,
                alpha=1.0 if is_ref else 0.85,
                label=label,
                zorder=4 if is_ref else 3,
            )
    for ax, coordinate in zip(axes, ("x", "y"), strict=True):
        ax.set_ylabel(f"{coordinate} (m, {frame})")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=8, framealpha=0.9)
    axes[0].set_title(wrap_title(title, fig.get_figwidth()))
    axes[1].set_xlabel("time (s)")
    return _save(fig, path)


def plot_speeds(
    path: str | Path,
    *,
    cmd_t_s: ArrayLike,
    cmd_twist: ArrayLike,
    odom_t_s: ArrayLike | None = None,
    odom_twist: ArrayLike | None = None,
    title: str = "speeds over time",
) -> Path:
    """Draw linear and angular speed over time (seed 001 Figures 9 and 11).

    The linear speed is the magnitude of the planar body velocity, sqrt(vx² + vy²) (an
    omnidirectional robot moves sideways too); the angular speed is wz. Commands are drawn as
    steps (held until the next one).

    Args:
        path: PNG to write.
        cmd_t_s: (N,) times of the commands, seconds.
        cmd_twist: (N, 3) commanded body twists (vx m/s, vy m/s, wz rad/s), ``/cmd_vel``.
        odom_t_s: (M,) times of the odometry, seconds.
        odom_twist: (M, 3) measured body twists, ``/odom``.
        title: figure title.

    Raises:
        GeometryError: an array has the wrong shape.
    """
    fig, (ax_v, ax_w) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    rows = []
    if odom_t_s is not None and odom_twist is not None:
        rows.append(("odometry (/odom)", odom_t_s, odom_twist, "black", "default"))
    rows.append(("commanded (/cmd_vel)", cmd_t_s, cmd_twist, "tab:red", "steps-post"))
    for label, t, twist, color, drawstyle in rows:
        t_s = np.asarray(t, dtype=np.float64)
        tw = np.asarray(twist, dtype=np.float64)
        if tw.ndim != 2 or tw.shape != (t_s.size, 3) or t_s.ndim != 1:
            raise GeometryError(f"{label}: twists must be ({t_s.size}, 3), got {tw.shape}")
        # the measured speed wide and light underneath, the command thin on top of it
        style = (
            {"lw": 1.1, "alpha": 1.0, "ls": "--"}
            if drawstyle == "steps-post"
            else {"lw": 2.2, "alpha": 0.45, "ls": "-"}
        )
        speed = np.hypot(tw[:, 0], tw[:, 1])
        steps = _step_indices(tw) if drawstyle == "steps-post" else None
        for ax, series in ((ax_v, speed), (ax_w, tw[:, 2])):
            keep = steps if steps is not None and steps.size <= MAX_SERIES_POINTS else None
            if keep is None:
                keep = envelope_indices(series)
            ax.plot(t_s[keep], series[keep], color=color, drawstyle=drawstyle, label=label, **style)
    ax_v.set_ylabel("linear speed (m/s)")
    ax_w.set_ylabel("angular speed (rad/s)")
    ax_w.set_xlabel("time (s)")
    for ax, floor in ((ax_v, 0.05), (ax_w, 0.1)):
        lo, hi = ax.get_ylim()
        if hi - lo < floor:  # a constant signal: don't magnify round-off into the plot
            mid = 0.5 * (lo + hi)
            ax.set_ylim(mid - floor, mid + floor)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8, framealpha=0.9)
    ax_v.set_title(wrap_title(title, fig.get_figwidth()))
    return _save(fig, path)
