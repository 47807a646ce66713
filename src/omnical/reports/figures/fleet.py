"""Fleet and sweep figures (PNG, Agg): factors per recording with the fleet's band and alerts,
a figure per recording column, and a sweep's accuracy against each varied parameter.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from numpy.typing import NDArray

from omnical.calibration.drift import Alert
from omnical.reports.figures._common import save_figure

__all__ = ["plot_column_per_recording", "plot_factors_per_recording", "plot_sweep_accuracy"]


def _floats(rows: Sequence[Mapping[str, str]], column: str) -> NDArray[np.float64]:
    out = np.full(len(rows), np.nan)
    for i, row in enumerate(rows):
        try:
            out[i] = float(row.get(column, "") or "nan")
        except ValueError:
            continue
    return out


_MAX_WIDTH_IN = 16.0
"""Widest figure: a fleet of hundreds is drawn at this width (its memory flat in the fleet)."""
_MAX_LABELS = 60
"""Most recording names under a figure; more are thinned to every k-th."""


def _name_ticks(ax: Axes, names: Sequence[str]) -> None:
    step = max(1, -(-len(names) // _MAX_LABELS))
    ticks = np.arange(0, len(names), step)
    ax.set_xticks(ticks, [names[int(i)] for i in ticks], rotation=90, fontsize=6)


def _width_in(per_item_in: float, items: int) -> float:
    return min(_MAX_WIDTH_IN, max(6.0, per_item_in * items + 3.0))


def plot_factors_per_recording(
    rows: Sequence[Mapping[str, str]],
    factors: Sequence[str],
    alerts: Sequence[Alert],
    path: Path,
) -> Path:
    """One panel per factor: each recording's estimate ± 1σ, the fleet's median and the band of
    3 robust σ around it; recordings with an alert on the factor in red."""
    names = [row["name"] for row in rows]
    x = np.arange(len(rows))
    fig, axes = plt.subplots(
        len(factors), 1, figsize=(_width_in(0.25, len(rows)), 1.9 * len(factors)), sharex=True
    )
    axes = np.atleast_1d(axes)
    for ax, factor in zip(axes, factors, strict=True):
        value, sigma = _floats(rows, factor), _floats(rows, f"{factor}_sigma")
        ok = np.isfinite(value) & np.isfinite(sigma)
        flagged = np.array([any(a.name == n and a.factor == factor for a in alerts) for n in names])
        ax.errorbar(x[ok & ~flagged], value[ok & ~flagged], sigma[ok & ~flagged], fmt="o", ms=3)
        if (ok & flagged).any():
            ax.errorbar(
                x[ok & flagged], value[ok & flagged], sigma[ok & flagged], fmt="o", ms=4, color="r"
            )
        if ok.sum() >= 2:
            median = float(np.median(value[ok]))
            spread = 1.4826 * float(np.median(np.abs(value[ok] - median)))
            ax.axhline(median, color="k", lw=0.8)
            if spread > 0.0:
                ax.axhspan(median - 3 * spread, median + 3 * spread, color="0.85", zorder=0)
        ax.set_ylabel(factor.replace("_rad_per_m", "\n(rad/m)"), fontsize=7)
        ax.grid(True, alpha=0.3)
    _name_ticks(axes[-1], names)
    axes[0].set_title(  # two lines: it fits the narrowest (6-inch) figure
        "factors per recording (±1σ)\nline: fleet median, band: ±3 robust σ, red: alert",
        fontsize=9,
    )
    return save_figure(fig, path)


def plot_column_per_recording(
    rows: Sequence[Mapping[str, str]], columns: Sequence[str], ylabel: str, path: Path
) -> Path:
    """The ``columns`` of each recording as grouped bars (a locate's or an evaluation's figures);
    a column no recording has a value in is left out (UWB-only bags: no odometry bar)."""
    import textwrap

    filled = [c for c in columns if np.isfinite(_floats(rows, c)).any()]
    columns = filled or list(columns)
    names = [row["name"] for row in rows]
    x = np.arange(len(rows))
    fig, ax = plt.subplots(figsize=(_width_in(0.3 * max(1, len(columns)), len(rows)), 4.0))
    width = 0.8 / max(1, len(columns))
    for k, column in enumerate(columns):
        ax.bar(x + (k - (len(columns) - 1) / 2) * width, _floats(rows, column), width, label=column)
    _name_ticks(ax, names)
    ax.set_ylabel(textwrap.fill(ylabel, 40))  # a reference file's path is long
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=7)
    return save_figure(fig, path)


def plot_sweep_accuracy(
    parameter: Sequence[float],
    error: Sequence[float],
    *,
    parameter_label: str,
    error_label: str,
    target: float | None,
    path: Path,
) -> Path:
    """Each run's error against one varied parameter (log scale), with the median per bin."""
    p = np.asarray(parameter, dtype=float)
    e = np.abs(np.asarray(error, dtype=float))
    ok = np.isfinite(p) & np.isfinite(e) & (e > 0.0)
    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    ax.scatter(p[ok], e[ok], s=6, alpha=0.5, label="runs")
    distinct = np.unique(p[ok])
    if len(distinct) <= 8:
        centres = distinct
        medians = [float(np.median(e[ok][p[ok] == c])) for c in centres]
    else:
        edges = np.quantile(p[ok], np.linspace(0.0, 1.0, 9))
        index = np.clip(np.searchsorted(edges, p[ok], side="right") - 1, 0, 7)
        centres = np.array(
            [float(np.median(p[ok][index == b])) for b in range(8) if (index == b).any()]
        )
        medians = [float(np.median(e[ok][index == b])) for b in range(8) if (index == b).any()]
    if len(centres):
        ax.plot(centres, medians, "k-o", ms=4, label="median")
    if target is not None and math.isfinite(target):
        ax.axhline(target, color="r", lw=0.8, ls="--", label=f"target {target:g}")
    if ok.any():
        ax.set_yscale("log")
    ax.set_xlabel(parameter_label)
    ax.set_ylabel(error_label)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    return save_figure(fig, path)
