"""The navigation figures (issue 29): the map fills the navigation and plan figures (it filled
less than half, beside a wide legend), and the mapping figure's time colours have a colour bar."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from omnical.navigation.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from omnical.reports.figures._common import save_figure
from omnical.reports.figures.navigation import plot_mapping, plot_navigation, plot_plan


def _grid() -> OccupancyGrid:
    """An 8 m × 6 m room (walls round free floor) in a larger unknown map, 5 cm cells."""
    cells = np.full((160, 200), UNKNOWN, dtype=np.int8)
    cells[20:140, 20:180] = OCCUPIED
    cells[22:138, 22:178] = FREE
    return OccupancyGrid(cells, 0.05, (-1.0, -1.0, 0.0))


@pytest.fixture
def drawn(monkeypatch: pytest.MonkeyPatch) -> list[Figure]:
    figures: list[Figure] = []

    def keep(fig: Figure, path: Path, **kwargs: object) -> Path:
        figures.append(fig)
        return save_figure(fig, path, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr("omnical.reports.figures.navigation.save_figure", keep)
    return figures


def _share_of_the_png(fig: Figure, ax: Axes) -> float:
    """The map axes' area over the area of the PNG (cropped to what is drawn)."""
    renderer = FigureCanvasAgg(fig).get_renderer()  # type: ignore[no-untyped-call]
    frame = ax.get_window_extent(renderer)
    png = fig.get_tightbbox(renderer)
    assert png is not None
    return float(frame.width * frame.height / (png.width * png.height * fig.dpi**2))


def _covered(ax: Axes, grid: OccupancyGrid) -> float:
    """The share of the axes' view the map image covers."""
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    ox, oy, _ = grid.origin
    rows, cols = grid.shape
    w = max(0.0, min(x1, ox + cols * grid.resolution_m) - max(x0, ox))
    h = max(0.0, min(y1, oy + rows * grid.resolution_m) - max(y0, oy))
    return w * h / ((x1 - x0) * (y1 - y0))


def _roadmap() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    nodes = rng.uniform((0.5, 0.5), (6.5, 4.5), (300, 2))
    edges = np.array([(i, j) for i in range(300) for j in range(i + 1, min(i + 40, 300))])
    return nodes, edges


@pytest.mark.parametrize("kind", ["navigation", "plan"])
def test_the_map_fills_the_figure(tmp_path: Path, drawn: list[Figure], kind: str) -> None:
    grid = _grid()
    nodes, edges = _roadmap()
    common: dict[str, Any] = {
        "grid": grid,
        "blocked": grid.cells != FREE,
        "roadmap_nodes": nodes,
        "roadmap_edges": edges,
        "title": "t",
    }
    plot: Callable[..., Path]
    if kind == "navigation":
        plot, path = plot_navigation, np.array([[1.0, 1.0], [3.0, 2.0], [6.0, 4.0]])
        common.update(goals=path[1:], planned=[path[:2], path[1:]], driven=path)
    else:
        plot, path = plot_plan, np.array([[1.0, 1.0], [3.0, 2.0]])
        common.update(goal=path[1], planned=path, raw=np.array([[1, 1], [2, 1.4], [3, 2.0]]))
    plot(tmp_path / f"{kind}.png", start=path[0], **common)
    (ax,) = drawn[0].axes
    assert _share_of_the_png(drawn[0], ax) >= 0.6
    assert _covered(ax, grid) >= 0.99  # the view is the map's known part, not empty margins
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    assert x0 < 0.0 and x1 > 8.0 and y0 < 0.0 and y1 > 6.0  # and holds the whole room


def test_the_mapping_figure_has_a_colour_bar_for_time(tmp_path: Path, drawn: list[Figure]) -> None:
    grid = _grid()
    t = np.linspace(0.0, 1.0, 20)
    poses = np.column_stack([1.0 + 5.0 * t, 1.0 + 3.0 * t, np.zeros_like(t)])
    scans = [np.array([[0.0, 3.0 * k / 4], [8.0, 3.0 * k / 4]]) for k in range(5)]
    plot_mapping(
        tmp_path / "m.png",
        grid=grid,
        poses=poses,
        scan_points_world=scans,
        scan_t_s=[0.0, 10.0, 20.0, 30.0, 52.0],
    )
    bars = [ax for ax in drawn[0].axes if ax.get_ylabel() == "time since the first scan (s)"]
    assert len(bars) == 1
    low, high = bars[0].get_ylim()
    assert (low, high) == (0.0, 52.0)
    with pytest.raises(ValueError, match="4 scan times for 5 scans"):
        plot_mapping(
            tmp_path / "n.png",
            grid=grid,
            poses=poses,
            scan_points_world=scans,
            scan_t_s=[0.0, 1.0, 2.0, 3.0],
        )
