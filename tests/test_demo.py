"""The demo end to end: before/after Lissajous, campaign, closed-loop paths, report.

Its chapters are the suite's acceptance runs too (the demo is run once here, not again by the
chapter's own tests): seed 0 of issue 11's sensor-based improvement and the lab-8x6 SLAM and
navigation targets.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from omnical.cli.main import app
from omnical.errors import ConfigError
from omnical.evaluation.metrics import GROUND_TRUTH_KEY, SMOOTHED_KEY
from omnical.reports import demo as demo_report
from omnical.reports.demo import DemoFiles, write_demo
from omnical.reports.outputs import claim_directory
from omnical.services import demo as demo_service
from omnical.services.demo import DemoResult, run_demo
from omnical.services.navigation import LAB_START, navigate
from omnical.twin.params import default_twin


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


@pytest.mark.slow
def test_demo_sensor_based_improvement_is_the_true_one(demo: DemoResult) -> None:
    """Seed 0 of tests/evaluation/test_smoothed.py::test_sensor_based_improvement_over_seeds
    (the same runs: run_demo is that test's procedure on seed 0): the smoothed Lissajous RMSE
    within 5 mm of the ground truth's, before and after, and the sensor-measured improvement
    within 20 % of the true one."""
    for metrics in (demo.before, demo.after):
        assert abs(metrics[SMOOTHED_KEY].rmse_m - metrics[GROUND_TRUTH_KEY].rmse_m) < 0.005
    measured = demo.measured_improvement
    assert measured is not None
    assert abs(measured / demo.improvement - 1.0) < 0.20, (measured, demo.improvement)


@pytest.mark.slow
def test_demo_lab_map_and_trajectory_targets(demo: DemoResult) -> None:
    """SLAM on the lab-8x6 mapping tour (the issue's targets, on the twin)."""
    assert demo.navigation is not None
    run = demo.navigation.mapping
    assert run.score.occupied_precision >= 0.95
    assert run.score.recall_seen >= 0.90
    assert run.score.free_but_occupied <= 0.01
    assert run.trajectory_rmse_m <= 0.02
    assert math.degrees(run.yaw_rmse_rad) <= 0.5
    assert len(run.slam.keyframes) > 20 and len(run.slam.loop_closures) > 0


@pytest.mark.slow
def test_demo_lab_navigation_on_the_slam_map(demo: DemoResult) -> None:
    assert demo.navigation is not None
    nav = demo.navigation.navigation
    assert [leg.controller for leg in nav.legs] == ["waypoint", "tracking", "waypoint"]
    assert nav.collision == ""
    assert nav.reached
    assert nav.min_clearance_m > 0.0
    assert all(leg.goal_error_m <= 0.05 for leg in nav.legs)


def test_navigation_controller_choices_are_checked(demo: DemoResult) -> None:
    assert demo.navigation is not None
    world, grid = demo.navigation.world, demo.navigation.mapping.slam.grid
    robot = demo.robot
    params = replace(default_twin(robot), start_pose_map=LAB_START)
    with pytest.raises(ConfigError, match="2 controller choices for 1 goals"):
        navigate(world, grid, robot, params, [(6.5, 1.0)], controller=("waypoint", "waypoint"))
    with pytest.raises(ConfigError, match="unknown controller 'pid'"):
        navigate(world, grid, robot, params, [(6.5, 1.0)], controller="pid")  # type: ignore[arg-type]


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
    # the navigation chapter: its section and its two figures
    assert "figures/navigation-mapping.png" in text and "figures/navigation-goals.png" in text
    assert "occupied precision" in text and "tracking" in text
    for name in ("navigation-mapping.png", "navigation-goals.png"):
        figure = files.report.parent / "figures" / name
        assert figure.read_bytes().startswith(b"\x89PNG")
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

    overwrites: list[bool] = []

    def swapped(result: DemoResult, out_dir: Path, **kwargs: Any) -> DemoFiles:
        """write_demo's claim and swap, over the first run's output, without its 7 s of CPU
        on figures (cli_demo above writes them all, once)."""
        overwrites.append(kwargs["overwrite"])
        claimed = claim_directory(out_dir, overwrite=kwargs["overwrite"], writer="omnical demo")
        with claimed.staged() as staging:
            report = staging / "report.md"
            report.write_text("rewritten\n", encoding="utf-8")
        return replace(cli_demo.files, report=claimed.final(report))

    monkeypatch.setattr(demo_service, "run_demo", cached)  # the same run, not a second one
    monkeypatch.setattr(demo_report, "write_demo", swapped)
    monkeypatch.chdir(tmp_path)
    again = CliRunner().invoke(app, ["demo", "--out", "omnical-out"])
    assert again.exit_code == 2 and "add --overwrite" in again.output
    assert calls == [] and overwrites == []  # refused before running anything
    rewritten = CliRunner().invoke(app, ["demo", "--out", "omnical-out", "--overwrite"])
    assert rewritten.exit_code == 0, rewritten.output
    assert calls == [0] and overwrites == [True]
    assert "report: omnical-out/report.md" in rewritten.output
    assert (tmp_path / "omnical-out" / "report.md").read_text(encoding="utf-8") == "rewritten\n"
    assert not (tmp_path / "omnical-out" / "figures").exists()  # the earlier output replaced
