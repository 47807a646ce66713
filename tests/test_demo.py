"""The demo end to end: before/after Lissajous, campaign, closed-loop paths, report."""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from omnical.cli.main import app
from omnical.reports import demo as demo_report
from omnical.reports.demo import DemoFiles, write_demo
from omnical.services import demo as demo_service
from omnical.services.demo import DemoResult, run_demo


@pytest.fixture(scope="module")
def demo() -> DemoResult:
    """The demo, run once for the whole suite (every demo test lives in this file, which
    ``make test`` gives to one worker whole: ``--dist loadfile``)."""
    return run_demo(seed=0)


@pytest.mark.slow
def test_demo_calibrated_lissajous_is_at_least_7x_better(demo: DemoResult) -> None:
    result = demo
    # the calibrated open-loop Lissajous has a ground-truth RMSE ≥ 7× lower
    assert result.improvement >= 7.0
    assert result.before["ground_truth"].rmse_m > 0.03
    # odometry follows the open-loop commands either way (it is what they integrate to)
    assert result.before["odometry"].rmse_m < 0.02
    assert result.after["multilateration"].rmse_m < result.before["multilateration"].rmse_m
    # what a user without ground truth sees (the smoothed estimate) shows the improvement too
    measured = result.measured_improvement
    assert measured is not None and measured > 0.5 * result.improvement
    assert result.navigation is not None and not result.navigation.navigation.collision
    assert all(leg.goal_error_m < 0.05 for leg in result.navigation.navigation.legs)
    assert len(result.seed003.tests) == 4
    for path in result.paths:
        assert path.final_vs_odometry_m < 0.03
        assert path.final_vs_ground_truth_m < 0.05


@dataclass(frozen=True)
class CliDemo:
    """``omnical demo --out omnical-out`` run once in ``base`` (a fresh directory)."""

    base: Path
    output: str
    files: DemoFiles  # what write_demo returned to the command


@pytest.fixture(scope="module")
def cli_demo(demo: DemoResult, tmp_path_factory: pytest.TempPathFactory) -> CliDemo:
    """The command on the fixture's run (not a second one), with a relative --out as `make run`
    gives it; the report is written once here for the tests below (writing it takes ~9 s)."""
    base = tmp_path_factory.mktemp("demo")
    calls: list[int] = []
    written: list[DemoFiles] = []

    def cached(
        *, seed: int = 0, progress: object = None, with_navigation: bool = True
    ) -> DemoResult:
        calls.append(seed)
        return demo

    def kept(*args: Any, **kwargs: Any) -> DemoFiles:
        files = write_demo(*args, **kwargs)
        written.append(files)
        return files

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(demo_service, "run_demo", cached)
        mp.setattr(demo_report, "write_demo", kept)
        mp.chdir(base)
        result = CliRunner().invoke(app, ["demo", "--out", "omnical-out", "--seed", "0"])
    assert result.exit_code == 0, result.output
    assert calls == [0] and len(written) == 1
    return CliDemo(base, result.output, written[0])


@pytest.mark.slow
def test_demo_writes_nothing_until_the_report_layer_does(
    demo: DemoResult, cli_demo: CliDemo, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    assert not any(tmp_path.iterdir())  # run_demo (the fixture) wrote nothing
    monkeypatch.chdir(cli_demo.base)  # the paths write_demo returned are relative to it
    files = cli_demo.files
    text = files.report.read_text(encoding="utf-8")
    assert "seed 000 Table 4" in text
    assert "Ziegler–Nichols" in text
    links = [line.split("](")[1].rstrip(")") for line in text.splitlines() if line.startswith("![")]
    linked = {(files.report.parent / link).resolve() for link in links}
    assert all(path.is_file() for path in linked)
    assert {f.resolve() for f in files.figures} <= linked
    assert len(linked) == 15  # 6 Lissajous, 2 seed 001 paths, 5 seed 003, 2 navigation
    for chapter in ("Seed 003 on its own robot", "Navigation (seed 001", "sensors alone"):
        assert chapter in text
    out = cli_demo.base / "omnical-out"
    assert files.report.resolve() == (out / "report.md").resolve()
    assert (out / "calibration" / "report.md").is_file()
    assert (out / "calibration" / "factors.yaml").is_file()
    assert files.recordings and all(p.is_dir() for p in files.recordings)


@pytest.mark.slow
def test_omnical_demo_prints_the_summary_and_writes_the_report(
    demo: DemoResult, cli_demo: CliDemo, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert "lower RMSE after calibration" in cli_demo.output
    assert "report: omnical-out/report.md" in cli_demo.output
    written = cli_demo.base / "omnical-out"
    assert (written / "report.md").is_file() and (written / "calibration" / "report.md").is_file()
    assert (written / "recordings" / "lissajous-calibrated").is_dir()
    # the second run on the same --out: refused without --overwrite, rewritten with it (on a
    # copy, so that the other tests read what the first run wrote)
    shutil.copytree(written, tmp_path / "omnical-out")
    calls: list[int] = []

    def cached(
        *, seed: int = 0, progress: object = None, with_navigation: bool = True
    ) -> DemoResult:
        calls.append(seed)
        return demo

    monkeypatch.setattr(demo_service, "run_demo", cached)  # the same run, not a second one
    monkeypatch.chdir(tmp_path)
    again = CliRunner().invoke(app, ["demo", "--out", "omnical-out"])
    assert again.exit_code == 2 and "add --overwrite" in again.output
    assert calls == []  # refused before running anything
    rewritten = CliRunner().invoke(app, ["demo", "--out", "omnical-out", "--overwrite"])
    assert rewritten.exit_code == 0, rewritten.output
    assert calls == [0]
    assert "report: omnical-out/report.md" in rewritten.output
