"""The odometry's yaw dead band is the robot description's (``odom_yaw_resolution_radps``).

The status frames of the vehicle controller round the yaw rate to 1 mrad/s, so the presets'
default dead band (1.5 mrad/s) takes slower odometry yaw as no rotation; a robot whose /odom
resolves a slow yaw (gyro-fused) says ``odom_yaw_resolution_radps: 0`` and keeps it, and
odometry that omnical computes from the wheels' positions never gets the band.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

import omnical.calibration.joint.problem as joint_problem
import omnical.calibration.procedures.tracks as analysis_tracks
from omnical.bags.bag import write_bag
from omnical.calibration.campaign import estimate_factors
from omnical.calibration.procedures.scripts import longitudinal_procedure
from omnical.calibration.procedures.tracks import ODOM_YAW_DEADBAND_RADPS, yaw_deadband_radps
from omnical.cli.main import app
from omnical.errors import ConfigError
from omnical.experiment.script import parse_script
from omnical.recording.recording import Recording
from omnical.robot.loader import load_robot
from omnical.twin.params import default_twin
from omnical.twin.session import simulate_run

ROBOT = load_robot("rosy-mecanum")
runner = CliRunner()


class _SeenError(Exception):
    """Raised by the spy once it has seen the dead band (the rest of the work is not needed)."""


@pytest.fixture
def seen(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """The dead bands ``resolved_odometry`` is called with, by the procedures or the joint
    estimate (each stopped there)."""
    calls: list[float] = []

    def spy(t_s: Any, pose: Any, deadband_radps: float) -> Any:
        calls.append(deadband_radps)
        raise _SeenError

    monkeypatch.setattr(analysis_tracks, "resolved_odometry", spy)
    monkeypatch.setattr(joint_problem, "resolved_odometry", spy)
    return calls


@pytest.fixture(scope="module")
def run() -> Recording:
    script = parse_script(longitudinal_procedure(), ROBOT.limits)
    return simulate_run(script, ROBOT, default_twin(ROBOT), seed=3)


def _robot_file(tmp_path: Path, **fields: object) -> Path:
    preset = Path(analysis_tracks.__file__).parents[2] / "data" / "robots" / "rosy-mecanum.yaml"
    data = yaml.safe_load(preset.read_text(encoding="utf-8"))
    data.update(fields)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def test_the_presets_band_is_the_status_frames() -> None:
    assert ROBOT.odom_yaw_resolution_radps == pytest.approx(1e-3)
    assert yaw_deadband_radps(ROBOT.odom_yaw_resolution_radps) == ODOM_YAW_DEADBAND_RADPS
    assert yaw_deadband_radps(0.0) == 0.0


def test_a_robot_file_sets_the_resolution_and_a_bad_one_is_one_line(tmp_path: Path) -> None:
    robot = load_robot(_robot_file(tmp_path, odom_yaw_resolution_radps=0.0))
    assert robot.odom_yaw_resolution_radps == 0.0
    with pytest.raises(ConfigError, match="odom_yaw_resolution_radps"):
        load_robot(_robot_file(tmp_path, odom_yaw_resolution_radps=-0.001))


@pytest.mark.parametrize("method", ["procedures", "joint"])
def test_estimate_factors_hands_the_band_to_both_methods(
    run: Recording, seen: list[float], method: str
) -> None:
    with pytest.raises(_SeenError):
        estimate_factors([run], method=method, odom_yaw_deadband_radps=0.004)  # type: ignore[arg-type]
    assert seen == [0.004]


def test_no_band_keeps_the_odometrys_slow_yaw(run: Recording) -> None:
    """A steady 1 mrad/s of odometry yaw on a straight move (a gyro-fused /odom's real
    rotation): dropped with the presets' band, kept whole without one."""
    odom = run.topic("/odom")
    t_s = odom.t_s(int(odom.t_ns[0]))
    pose = np.column_stack([odom["x_m"], odom["y_m"], odom["yaw_rad"] + 1e-3 * t_s])
    moving = np.abs(np.asarray(odom["vx_mps"])) > 0.05
    kept = analysis_tracks.resolved_odometry(t_s, pose, 0.0)
    banded = analysis_tracks.resolved_odometry(t_s, pose, ODOM_YAW_DEADBAND_RADPS)
    turned_kept = np.diff(kept[:, 2])[moving[1:]].sum()
    turned_banded = np.diff(banded[:, 2])[moving[1:]].sum()
    assert turned_kept == pytest.approx(np.diff(pose[:, 2])[moving[1:]].sum())
    assert abs(turned_banded) < 0.05 * abs(turned_kept)


def test_the_cli_takes_the_robots_band_for_the_bags_odom(
    run: Recording, seen: list[float], tmp_path: Path
) -> None:
    bag = write_bag(run, tmp_path / "long.mcap")
    robot = _robot_file(tmp_path, odom_yaw_resolution_radps=0.002)
    result = runner.invoke(
        app,
        ["calibrate", "estimate", str(bag), "--robot", str(robot), "--out", str(tmp_path / "f.yaml")],
    )  # fmt: skip
    assert "_SeenError" in result.output  # the spy stopped it there (reported as a bug)
    assert seen == [pytest.approx(0.003)]
