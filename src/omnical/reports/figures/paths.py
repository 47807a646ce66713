"""Closed-loop path figure (seed 001 Figures 8 and 10, seed 003's test paths)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import ArrayLike

from omnical.reports.figures._common import finish_plan_view, save_figure

__all__ = ["plot_closed_loop"]


def plot_closed_loop(
    path: Path,
    *,
    waypoints_xy_m: ArrayLike,
    odometry_xy_m: ArrayLike,
    truth_xy_m: ArrayLike,
    title: str,
) -> Path:
    """Waypoints (red), the odometry the controller closed on (black), the true path (blue)."""
    wp = np.asarray(waypoints_xy_m, dtype=np.float64)
    od = np.asarray(odometry_xy_m, dtype=np.float64)
    gt = np.asarray(truth_xy_m, dtype=np.float64)
    fig, ax = plt.subplots(figsize=(7, 6.5))
    ax.plot(wp[:, 0], wp[:, 1], "-o", color="tab:red", lw=1.4, ms=4, label="reference way-points")
    ax.plot(od[:, 0], od[:, 1], "-", color="black", lw=1.0, label="odometry (closes the loop)")
    ax.plot(gt[:, 0], gt[:, 1], "-", color="tab:blue", lw=1.0, label="ground truth")
    ax.plot(
        gt[-1, 0], gt[-1, 1], "o", color="tab:blue", ms=7, mfc="white", label="final, ground truth"
    )
    finish_plan_view(ax, title=title, xlabel="x (m, path frame)", ylabel="y (m, path frame)")
    return save_figure(fig, path)
