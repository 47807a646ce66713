"""What every figure does last: a plan view's axes, and saving the PNG (Agg) and closing it."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.axes import Axes
from matplotlib.figure import Figure

__all__ = ["finish_plan_view", "save_figure"]


def save_figure(fig: Figure, path: str | Path, *, dpi: int = 120, tight: bool = True) -> Path:
    """Write ``fig`` as a PNG at ``path`` (parent directories created), close it, return the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    if tight:
        fig.tight_layout()
    fig.savefig(out, dpi=dpi)
    plt.close(fig)
    return out


def finish_plan_view(ax: Axes, *, title: str, xlabel: str, ylabel: str) -> None:
    """Equal axis scales, a light grid, labels, title and legend of a path seen from above."""
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.legend(loc="best", fontsize=8, framealpha=0.9)
