"""``omnical plan`` writes its figure beside the path CSV, as ``map`` does beside its YAML
(issue 29), through the same output checks: omnical's own files only are replaced."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from omnical.cli.main import app
from omnical.reports.outputs import is_figure

_PLAN = ["plan", "lab-8x6", "--from", "1.5,1.2", "--to", "2.5,1.2", "--nodes", "100"]


def test_plan_writes_its_figure_beside_the_csv(tmp_path: Path) -> None:
    out = tmp_path / "path.csv"
    res = CliRunner().invoke(app, [*_PLAN, "--out", str(out)])
    assert res.exit_code == 0, res.output
    png = tmp_path / "path.png"
    assert is_figure(png)  # a PNG with omnical's Software record
    assert out.read_text(encoding="utf-8").startswith("x_m,y_m\n")
    assert res.output.strip().endswith(f"wrote {out}, {png}")
    again = CliRunner().invoke(app, [*_PLAN, "--out", str(out)])
    assert again.exit_code == 2 and "--overwrite" in again.output
    res = CliRunner().invoke(app, [*_PLAN, "--out", str(out), "--overwrite"])
    assert res.exit_code == 0, res.output


def test_a_users_png_beside_is_never_replaced(tmp_path: Path) -> None:
    mine = tmp_path / "path.png"
    mine.write_bytes(b"\x89PNG\r\n\x1a\nmy drawing")
    out = tmp_path / "path.csv"
    res = CliRunner().invoke(app, [*_PLAN, "--out", str(out), "--overwrite"])
    assert res.exit_code == 2, res.output
    assert "path.png" in res.output and "not written by omnical" in res.output
    assert mine.read_bytes() == b"\x89PNG\r\n\x1a\nmy drawing" and not out.exists()


def test_the_csv_of_an_earlier_plan_is_still_recognised(tmp_path: Path) -> None:
    """A path CSV an earlier omnical wrote without a figure (nor a manifest) is replaced."""
    out = tmp_path / "path.csv"
    out.write_text("x_m,y_m\n1.5,1.2\n2.5,1.2\n", encoding="utf-8")
    res = CliRunner().invoke(app, [*_PLAN, "--out", str(out), "--overwrite"])
    assert res.exit_code == 0, res.output
    assert is_figure(tmp_path / "path.png")


def test_a_png_is_not_taken_for_the_csv(tmp_path: Path) -> None:
    res = CliRunner().invoke(app, [*_PLAN, "--out", str(tmp_path / "path.png")])
    assert res.exit_code == 2 and "CSV" in res.output
    assert not any(tmp_path.iterdir())
