"""``evaluate``'s path.png says how each estimate was aligned onto the reference (issue 29)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from omnical.reports.figures._common import save_figure
from omnical.reports.figures.trajectory import alignment_note, plot_tracking_paths


def test_the_note_groups_the_estimates_by_alignment() -> None:
    note = alignment_note({"odometry": "origin", "ips": "se2", "multilateration": "se2"})
    lines = note.splitlines()
    assert lines[0] == "aligned onto the reference:"
    assert "• odometry:" in lines and "• IPS (Marvelmind), multilateration:" in lines
    assert "first poses made to coincide" in note and "least squares, no scale" in note
    assert alignment_note({}) == ""


def test_the_path_figure_says_the_alignment_under_its_legend(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    drawn: list[Figure] = []

    def keep(fig: Figure, path: Path, **kwargs: object) -> Path:
        drawn.append(fig)
        return save_figure(fig, path, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr("omnical.reports.figures.trajectory.save_figure", keep)
    t = np.linspace(0.0, 1.0, 30)
    ref = np.column_stack([t, t**2])
    plot_tracking_paths(
        tmp_path / "path.png",
        reference_xy_m=ref,
        odometry_xy_m=ref + 0.01,
        ips_xy_m=ref - 0.01,
        alignments={"odometry": "origin", "ips": "se2"},
    )
    (ax,) = drawn[0].axes
    (note,) = [t for t in ax.texts if t.get_text().startswith("aligned onto the reference")]
    legend = ax.get_legend()
    assert legend is not None
    renderer = FigureCanvasAgg(drawn[0]).get_renderer()  # type: ignore[no-untyped-call]
    box, frame = note.get_window_extent(renderer), legend.get_window_extent(renderer)
    assert box.y1 <= frame.y0 and box.x0 >= ax.get_window_extent(renderer).x1  # beside the plan
