"""Figures (Figures 16–17 of seed 000, speeds of seed 001) and the Markdown report."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from omnical.errors import GeometryError, RecordingError
from omnical.evaluation.metrics import TrackingMetrics, track_recording
from omnical.paper import SEED000_TABLE4
from omnical.recording.recording import Recording
from omnical.reports.figures.trajectory import (
    confidence_radius_m,
    plot_position_time,
    plot_speeds,
    plot_tracking_paths,
)
from omnical.reports.markdown import (
    FigureLink,
    MarkdownTable,
    Section,
    render_markdown,
    write_markdown_report,
)
from omnical.reports.tables import table4

PNG = b"\x89PNG\r\n\x1a\n"


def _figures(rec: Recording, out: Path) -> list[Path]:
    tracked = track_recording(rec)
    ref = tracked["ground_truth"].association
    mlat = tracked["multilateration"]
    cmd, odom = rec.topic("/cmd_vel"), rec.topic("/odom")
    t0 = rec.start_ns
    return [
        plot_tracking_paths(
            out / "path.png",
            reference_xy_m=ref.reference_xy_m,
            odometry_xy_m=tracked["odometry"].alignment.xy_m,
            ips_xy_m=tracked["ips"].alignment.xy_m,
            multilateration_xy_m=mlat.alignment.xy_m,
            multilateration_cov_xy_m2=mlat.covariance_xy_m2,
            frame="map",
        ),
        plot_position_time(
            out / "xy.png",
            reference=(ref.t_s, ref.reference_xy_m),
            estimates={k: (v.association.t_s, v.alignment.xy_m) for k, v in tracked.items()},
        ),
        plot_speeds(
            out / "speeds.png",
            cmd_t_s=cmd.t_s(t0),
            cmd_twist=np.column_stack([cmd["vx_mps"], cmd["vy_mps"], cmd["wz_radps"]]),
            odom_t_s=odom.t_s(t0),
            odom_twist=np.column_stack([odom["vx_mps"], odom["vy_mps"], odom["wz_radps"]]),
        ),
    ]


def test_figures_are_written(default_tour: Recording, tmp_path: Path) -> None:
    paths = _figures(default_tour, tmp_path / "figs")
    assert [p.name for p in paths] == ["path.png", "xy.png", "speeds.png"]
    for p in paths:
        data = p.read_bytes()
        assert data.startswith(PNG) and len(data) > 20_000


def test_figure_inputs_are_checked(tmp_path: Path) -> None:
    with pytest.raises(GeometryError):
        plot_tracking_paths(tmp_path / "a.png", reference_xy_m=np.zeros(3))
    with pytest.raises(GeometryError):
        plot_speeds(tmp_path / "b.png", cmd_t_s=np.zeros(3), cmd_twist=np.zeros((3, 2)))
    with pytest.raises(GeometryError):
        plot_position_time(
            tmp_path / "c.png", reference=(np.zeros(2), np.zeros((3, 2))), estimates={}
        )
    assert not any(tmp_path.iterdir())


def test_confidence_radius_holds_the_ellipse() -> None:
    cov = np.array([[[4e-4, 0.0], [0.0, 1e-4]], [[1e-4, 0.0], [0.0, 1e-4]]])
    np.testing.assert_allclose(confidence_radius_m(cov, scale=1.0), [0.02, 0.01])
    assert confidence_radius_m(cov)[1] == pytest.approx(0.01 * np.sqrt(5.991), rel=1e-3)


def _m(rmse_x: float, rmse_y: float) -> TrackingMetrics:
    return TrackingMetrics(float(np.hypot(rmse_x, rmse_y)), rmse_x, rmse_y, 0.5, 0.1, 10)


def test_table4_layout() -> None:
    before = {"odometry": _m(0.03, 0.04), "ips": _m(0.1, 0.05)}
    after = {"odometry": _m(0.006, 0.008)}
    t = table4(before, after)
    assert t.header[1:5] == (
        "uncalibrated odometry",
        "uncalibrated odometry (paper)",
        "uncalibrated IPS",
        "uncalibrated IPS (paper)",
    )
    rows = {r[0]: r[1:] for r in t.rows}
    assert rows["x"] == ("0.0300", "0.0089", "0.1000", "0.1518", "0.0060", "0.0086", "—", "0.0168")
    assert rows["y"][:4] == ("0.0400", "0.0076", "0.0500", "0.0445")
    per_axis = rows["position (Table 4: √((x²+y²)/2))"]
    assert per_axis[:2] == (f"{np.sqrt((0.03**2 + 0.04**2) / 2):.4f}", "0.0083")
    euclid = rows["position, Euclidean (evo APE)"]
    assert euclid[:2] == ("0.0500", f"({np.hypot(0.0089, 0.0076):.4f})")
    assert SEED000_TABLE4["calibrated"]["ips"] == (0.0171, 0.0168, 0.0173)
    without_paper = table4(before, None, None, ips_key="multilateration")
    assert len(without_paper.header) == 5
    assert {r[0]: r[1:] for r in without_paper.rows}["x"] == ("0.0300", "—", "—", "—")


def test_report_is_written(default_tour: Recording, tmp_path: Path) -> None:
    out = tmp_path / "report"
    figs = _figures(default_tour, out / "figures")
    results = {name: t.metrics for name, t in track_recording(default_tour).items()}
    rows = tuple((name, f"{m.rmse_m:.4f}", f"{m.max_m:.4f}") for name, m in results.items())
    report = write_markdown_report(
        out,
        "Tour | twin",
        [
            Section(
                "Errors",
                (
                    "Against the twin's ground truth.",
                    MarkdownTable(("estimate", "RMSE (m)", "max (m)"), rows),
                    table4(results, None),
                    Section("Figures", tuple(FigureLink(p, p.stem) for p in figs)),
                ),
            )
        ],
    )
    text = report.read_text(encoding="utf-8")
    assert report == out / "report.md"
    assert text.startswith("# Tour | twin\n\n## Errors\n")
    assert "### Figures" in text
    assert "![path](figures/path.png)" in text
    assert f"| odometry | {results['odometry'].rmse_m:.4f} |" in text
    assert "| :--- | ---: | ---: |" in text
    assert "uncalibrated odometry (paper)" in text


def test_report_refusals(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="does not exist"):
        render_markdown("t", [Section("s", (FigureLink(Path("nope.png")),))], base_dir=tmp_path)
    with pytest.raises(RecordingError, match="cells"):
        MarkdownTable(("a", "b"), (("1",),))
    with pytest.raises(RecordingError, match="level"):
        Section("s", level=7)
    text = render_markdown(
        "t", [Section("s", (MarkdownTable(("a|b",), (("x|y",),)),))], base_dir=tmp_path
    )
    assert "| a\\|b |" in text and "| x\\|y |" in text


def test_a_report_in_a_relative_directory_links_figures_made_there(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    out = Path("omnical-out")  # relative, as `omnical demo --out omnical-out` gives it
    figure = out / "figures" / "a.png"
    figure.parent.mkdir(parents=True)
    figure.write_bytes(PNG)
    report = write_markdown_report(out, "t", [Section("s", (FigureLink(figure, "a"),))])
    assert "![a](figures/a.png)" in report.read_text(encoding="utf-8")
    inside = FigureLink(Path("figures/a.png"), "b")  # relative to the report directory
    assert "![b](figures/a.png)" in render_markdown("t", [Section("s", (inside,))], base_dir=out)


def _captured_calls(monkeypatch: pytest.MonkeyPatch) -> dict[str, dict[str, object]]:
    """Record the keyword arguments :func:`tracking_figures` draws each figure with."""
    from omnical.reports.figures import trajectory

    calls: dict[str, dict[str, object]] = {}

    def capture(name: str) -> object:
        def draw(path: Path, **kwargs: object) -> Path:
            calls[name] = kwargs
            return Path(path)

        return draw

    for name in ("plot_tracking_paths", "plot_position_time", "plot_speeds"):
        monkeypatch.setattr(trajectory, name, capture(name))
    return calls


def test_ground_truth_is_drawn_once(
    default_tour: Recording, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from omnical.reports.tracking import tracking_figures

    calls = _captured_calls(monkeypatch)
    # against /ground_truth: the ground truth is the reference, drawn and listed once as it
    tracked = track_recording(default_tour)
    tracking_figures(tracked, default_tour, tmp_path, stem="", title="t")
    paths, over_time = calls["plot_tracking_paths"], calls["plot_position_time"]
    assert "ground_truth" not in paths["lines_xy_m"]  # type: ignore[operator]
    assert "ground_truth" not in over_time["estimates"]  # type: ignore[operator]
    assert paths["reference_label"] == over_time["reference_label"] == "reference = ground truth"
    # against another reference (here the odometry's path): the ground truth is drawn as a
    # line, and the odometry, now the reference, is drawn once as it
    odom = default_tour.topic("/odom")
    ref = (odom.t_s(default_tour.start_ns), np.column_stack([odom["x_m"], odom["y_m"]]))
    tracked = track_recording(default_tour, ref, smooth=False)
    tracking_figures(tracked, default_tour, tmp_path, stem="", title="t")
    paths, over_time = calls["plot_tracking_paths"], calls["plot_position_time"]
    assert "ground_truth" in paths["lines_xy_m"]  # type: ignore[operator]
    assert "ground_truth" in over_time["estimates"]  # type: ignore[operator]
    assert "odometry" not in over_time["estimates"]  # type: ignore[operator]
    assert paths["odometry_xy_m"] is None
    assert paths["reference_label"] == "reference = odometry"


def test_long_titles_are_wrapped_to_the_figure() -> None:
    from omnical.reports.figures._common import wrap_title

    title = (
        "Lissajous, uncalibrated kinematics (seed 000 Figures 16–17, seed 001 Figure 9): "
        "paths against the reference"
    )
    lines = wrap_title(title, 8.0).splitlines()
    assert len(lines) == 2 and " ".join(lines) == title
    assert wrap_title("run: x(t) and y(t)", 9.0) == "run: x(t) and y(t)"
