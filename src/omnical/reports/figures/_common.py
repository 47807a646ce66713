"""What every figure does last: a plan view's axes, and saving the PNG (Agg) and closing it."""

from __future__ import annotations

import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from omnical.reports.outputs import FIGURE_SOFTWARE

__all__ = ["finish_plan_view", "save_figure", "wrap_title"]


def save_figure(
    fig: Figure, path: str | Path, *, dpi: int = 120, tight: bool = True, crop: bool = False
) -> Path:
    """Write ``fig`` as a PNG at ``path`` (parent directories created), close it, return the path.

    ``crop``: size the PNG to what is drawn (``bbox_inches="tight"``), for a legend placed
    outside the axes, which ``tight_layout`` does not make room for. The PNG's ``Software``
    record says omnical: ``--overwrite`` replaces such a figure only
    (:func:`omnical.reports.outputs.is_figure`).
    """
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    if tight:
        fig.tight_layout()
    try:
        fig.savefig(
            out,
            dpi=dpi,
            bbox_inches="tight" if crop else None,
            pad_inches=0.15,
            metadata={"Software": FIGURE_SOFTWARE},
        )
    except OSError as err:
        if err.filename is None:  # a write refused (the disk full) names no file: this one
            err.filename = str(out)
        raise
    finally:
        plt.close(fig)
    return out


def wrap_title(title: str, width_in: float, fontsize: float = 12.0) -> str:
    """``title`` broken into lines that fit ``width_in`` inches at ``fontsize`` points.

    Matplotlib does not wrap a title (one wider than the figure is cut off at both ends). A
    character is taken as 0.52 em wide and 95 % of the width is used: the estimate errs short.
    """
    chars = max(20, int(0.95 * width_in * 72.0 / (0.52 * fontsize)))
    return "\n".join(textwrap.wrap(title, width=chars)) or title


def finish_plan_view(ax: Axes, *, title: str, xlabel: str, ylabel: str) -> None:
    """Equal axis scales, a light grid, labels, title and legend of a path seen from above."""
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    fig = ax.figure
    width_in = fig.get_figwidth() if isinstance(fig, Figure) else 7.0
    ax.set_title(wrap_title(title, width_in, 10), fontsize=10)
    ax.legend(loc="best", fontsize=8, framealpha=0.9)
