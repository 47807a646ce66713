"""Every command that writes checks its outputs first: a user's own files are never replaced."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from omnical.cli.main import app

runner = CliRunner()


@pytest.fixture(scope="module")
def run_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("bag") / "run.mcap"
    result = runner.invoke(app, ["simulate", "straight-10m", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out


def test_locate_never_replaces_a_users_csv_and_checks_before_the_work(
    run_bag: Path, tmp_path: Path
) -> None:
    mine = tmp_path / "mine.csv"
    mine.write_text("precious\n", encoding="utf-8")
    for extra in ([], ["--overwrite"]):
        result = runner.invoke(app, ["locate", str(run_bag), "--out", str(mine), *extra])
        assert result.exit_code == 2, result.output
        assert "not written by omnical" in result.output
    assert mine.read_text(encoding="utf-8") == "precious\n"
    result = runner.invoke(app, ["locate", str(run_bag), "--out", "/proc/self/fixes.csv"])
    assert result.exit_code == 2 and "cannot write" in result.output  # before multilaterating
    ours = tmp_path / "fixes.csv"
    assert runner.invoke(app, ["locate", str(run_bag), "--out", str(ours)]).exit_code == 0
    again = runner.invoke(app, ["locate", str(run_bag), "--out", str(ours)])
    assert again.exit_code == 2 and "add --overwrite" in again.output
    args = ["locate", str(run_bag), "--out", str(ours), "--overwrite"]
    assert runner.invoke(app, args).exit_code == 0


def test_evaluate_refuses_a_directory_of_the_users_files(run_bag: Path, tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "path.png").write_bytes(b"my own figure")
    for extra in ([], ["--overwrite"]):
        result = runner.invoke(app, ["evaluate", str(run_bag), "--out", str(mine), *extra])
        assert result.exit_code == 2, result.output
        assert "not written by omnical" in result.output
    assert (mine / "path.png").read_bytes() == b"my own figure"


def test_run_on_the_twin_installs_the_factors_it_is_given(tmp_path: Path) -> None:
    factors = tmp_path / "f.yaml"
    factors.write_text(
        "# omnical\nscale: {longitudinal: 1.02, lateral: 1.13, rotational: 1.0236}\n"
        "crosstalk_rad_per_m: {forward: 0, reverse: 0, left: 0, right: 0}\n",
        encoding="utf-8",
    )
    out = tmp_path / "r.mcap"
    args = ["run", "straight-10m", "--robot", "twin", "--hedge", "twin", "--yes", "--out", str(out)]
    result = runner.invoke(app, [*args, "--factors", str(factors)])
    assert result.exit_code == 0, result.output
    assert "installed" in result.output
    bad = runner.invoke(app, [*args[:-1], str(tmp_path / "r2.mcap"), "--factors", "/nope.yaml"])
    assert bad.exit_code == 2 and "nope.yaml" in bad.output


def test_evaluate_on_the_omni_x_robot_measures_seed_003s_estimate(tmp_path: Path) -> None:
    import json

    bag = tmp_path / "omni.mcap"
    sim = ["simulate", "straight-10m", "--robot", "omni-x", "--out", str(bag)]
    assert runner.invoke(app, sim).exit_code == 0
    out = tmp_path / "ev"
    result = runner.invoke(app, ["evaluate", str(bag), "--robot", "omni-x", "--out", str(out)])
    assert result.exit_code == 0, result.output
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    # the dead wheels + IMU estimate beats the omni wheels' own odometry on the omni-X twin
    assert metrics["seed003"]["rmse_m"] < metrics["odometry"]["rmse_m"]
