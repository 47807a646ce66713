"""``omnical locate --plot``: the legend beside the map, every status listed, nothing clipped.

On the TU Chemnitz run (real ranges, 4 anchors, ellipses ≈ 0.3 m, two degenerate fixes) the
legend used to cover beacon 108, the ellipses ran past the axes and the degenerate fixes had
no legend entry.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from omnical.ips.beacons import BeaconMap
from omnical.ips.from_recording import locate
from omnical.ips.solve.fixes import CHI2_2DOF_95, Fixes, FixStatus
from omnical.reports.figures._common import save_figure
from omnical.reports.figures.ips import fixes_view, plot_fixes
from sibling import sibling_module


def test_the_tu_chemnitz_figure_shows_everything(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    run = sibling_module("ips/uwb_bags.py").tuc_run()
    fixes, beacons = locate(run.recording)
    assert isinstance(beacons, BeaconMap)
    assert np.any(fixes.status == FixStatus.DEGENERATE)
    drawn: list[Figure] = []
    real_save = save_figure

    def keep(fig: Figure, path: Path, **kwargs: object) -> Path:
        drawn.append(fig)
        return real_save(fig, path, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr("omnical.reports.figures.ips.save_figure", keep)
    png = plot_fixes(fixes, beacons, tmp_path / "fixes.png", title="tuc")
    assert png.read_bytes().startswith(b"\x89PNG")
    (ax,) = drawn[0].axes
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    b = beacons.positions_m
    assert np.all((b[:, 0] > x0) & (b[:, 0] < x1) & (b[:, 1] > y0) & (b[:, 1] < y1))
    usable = (fixes.status <= FixStatus.DEGRADED) & np.isfinite(fixes.positions_map_m[:, 0])
    p, cov = fixes.positions_map_m[usable], fixes.covariance_xy_m2[usable]
    half = np.sqrt(CHI2_2DOF_95 * np.column_stack([cov[:, 0, 0], cov[:, 1, 1]]))
    assert np.all(p[:, 0] - half[:, 0] >= x0) and np.all(p[:, 0] + half[:, 0] <= x1)
    assert np.all(p[:, 1] - half[:, 1] >= y0) and np.all(p[:, 1] + half[:, 1] <= y1)
    legend = ax.get_legend()
    assert legend is not None
    labels = [t.get_text() for t in legend.get_texts()]
    for status in ("ok", "degraded", "degenerate"):
        assert any(label.startswith(f"fixes {status} (") for label in labels), labels
    assert any("no position" in label for label in labels)
    # beside the axes, not over them
    renderer = FigureCanvasAgg(drawn[0]).get_renderer()  # type: ignore[no-untyped-call]
    box, frame = legend.get_window_extent(renderer), ax.get_window_extent(renderer)
    assert box.x0 >= frame.x1


def test_the_view_leaves_a_wild_outlier_out_and_says_so() -> None:
    beacons = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 3.0], [4.0, 3.0]])
    lo, hi = np.array([[1.0, -0.5]]), np.array([[2.0, 0.5]])  # an ellipse below the map
    scattered = np.array([[5.0, 1.0], [400.0, 300.0], [np.nan, np.nan]])
    view = fixes_view(beacons, lo, hi, scattered)
    assert view.x_m[0] < 0.0 and 5.0 < view.x_m[1] < 10.0
    assert view.y_m[0] < -0.5 and 3.0 < view.y_m[1] < 10.0
    assert view.outside == 1


def _synthetic_fixes(n: int = 40) -> tuple[Fixes, BeaconMap]:
    rng = np.random.default_rng(3)
    beacons = BeaconMap(
        np.array([3, 4, 5, 6], dtype=np.int64),
        np.array([[0.0, 0.0, 2.0], [5.0, 0.0, 2.0], [0.0, 4.0, 2.0], [5.0, 4.0, 2.0]]),
    )
    xy = np.column_stack([np.linspace(1.0, 4.0, n), np.full(n, 2.0)]) + rng.normal(0, 0.02, (n, 2))
    status = np.full(n, FixStatus.OK, dtype=np.uint8)
    status[::7] = FixStatus.DEGRADED
    status[3] = FixStatus.REJECTED
    fixes = Fixes(
        positions_map_m=np.column_stack([xy, np.zeros(n)]),
        covariance_xy_m2=np.tile(np.eye(2) * 1e-4, (n, 1, 1)),
        sigma_z_m=np.full(n, np.nan),
        range_sigma_m=np.full(n, 0.02),
        hdop=np.ones(n),
        residual_rms_m=np.full(n, 0.02),
        error_eq4_m=np.full(n, 0.01),
        used=np.ones((n, 4), dtype=bool),
        status=status,
        reason=np.zeros(n, dtype=np.uint16),
        beacon_addresses=beacons.addresses,
        method="robust",
        dims=2,
    )
    return fixes, beacons


def test_the_vendor_positions_are_drawn_over_the_ok_fixes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 29: the vendor's positions named in the legend were hidden under the fixes (drawn
    later at the same zorder); they are drawn over the ok fixes, under the flagged ones."""
    fixes, beacons = _synthetic_fixes()
    drawn: list[Figure] = []
    real_save = save_figure

    def keep(fig: Figure, path: Path, **kwargs: object) -> Path:
        drawn.append(fig)
        return real_save(fig, path, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr("omnical.reports.figures.ips.save_figure", keep)
    vendor = fixes.positions_map_m[:, :2] + 0.01
    plot_fixes(fixes, beacons, tmp_path / "fixes.png", vendor_xy=vendor, title="t")
    (ax,) = drawn[0].axes
    by_label = {str(line.get_label()): line for line in ax.get_lines()}
    vendor_line = by_label["vendor (Marvelmind)"]
    ok = next(line for label, line in by_label.items() if label.startswith("fixes ok ("))
    flagged = [line for label, line in by_label.items() if label.startswith("fixes re")]
    assert vendor_line.get_zorder() > ok.get_zorder()
    assert all(line.get_zorder() > vendor_line.get_zorder() for line in flagged)
    legend = ax.get_legend()
    assert legend is not None
    assert "vendor (Marvelmind)" in [t.get_text() for t in legend.get_texts()]
