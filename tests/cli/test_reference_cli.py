"""``calibrate estimate`` and ``evaluate`` on a bag with wheel ticks and motion capture only.

The bags are shaped like a real Mecanum robot's (``tests/estimation/mocap_bags.py``: JointState
ticks at 777 counts per wheel revolution under the driver's joint names, PoseStamped motion
capture at 100 Hz in its own frame, no /odom, no /cmd_vel, no IPS), made from the twin so
that the true factors are known. Calibrated on the tour, checked on a held-out Lissajous run.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from dataclasses import replace
from importlib import resources
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from typer.testing import CliRunner

from omnical.bags.reference_topics import read_pose_topic
from omnical.calibration.factors_io import read_factors
from omnical.cli.main import app
from omnical.experiment.library import builtin_script_data
from omnical.experiment.script import TwistSequence, parse_script
from omnical.robot.loader import load_robot
from omnical.trajectory.references import lissajous
from omnical.trajectory.scripts import feedforward_commands
from omnical.twin.params import default_twin

runner = CliRunner()
ROBOT = load_robot("rosy-mecanum")
PARAMS = default_twin(ROBOT)
TRUTH = PARAMS.true_factors
SCALES = ("scale_longitudinal", "scale_lateral", "scale_rotational")
CROSSTALKS = (
    "crosstalk_forward_rad_per_m",
    "crosstalk_reverse_rad_per_m",
    "crosstalk_left_rad_per_m",
    "crosstalk_right_rad_per_m",
)


def _mocap_bags() -> ModuleType:
    path = Path(__file__).resolve().parents[1] / "estimation" / "mocap_bags.py"
    spec = importlib.util.spec_from_file_location("mocap_bags", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("mocap_bags", module)
    spec.loader.exec_module(module)
    return module


mocap = _mocap_bags()


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("mocap")
    preset = resources.files("omnical.data.robots").joinpath("rosy-mecanum.yaml")
    robot_file = folder / "robot.yaml"
    robot_file.write_text(mocap.robot_yaml(preset.read_text("utf-8")), encoding="utf-8")
    tour = parse_script(builtin_script_data("tour"), ROBOT.limits)
    mocap.twin_user_run(folder / "tour", tour, ROBOT, PARAMS, 1)
    ref = lissajous()
    t, twists = feedforward_commands(ref, 50.0, limits=ROBOT.limits)
    commands = TwistSequence.from_arrays("lissajous", t, twists, rate_hz=50.0)
    start = (float(ref.poses[0, 0]), float(ref.poses[0, 1]), float(ref.poses[0, 2]))
    mocap.twin_user_run(folder / "liss", commands, ROBOT, replace(PARAMS, start_pose_map=start), 2)
    return {"robot": robot_file, "tour": folder / "tour", "liss": folder / "liss", "dir": folder}


def _calibrate(runs: dict[str, Path], out: Path, *extra: str) -> tuple[int, str]:
    args = ["calibrate", "estimate", str(runs["tour"]), "--robot", str(runs["robot"])]
    result = runner.invoke(
        app, [*args, "--wheel-topic", "/wheel_states", "--out", str(out), *extra]
    )
    return result.exit_code, result.output


@pytest.fixture(scope="module")
def calibrated(runs: dict[str, Path]) -> tuple[Path, str]:
    out = runs["dir"] / "cal" / "factors.yaml"
    code, output = _calibrate(runs, out, "--reference-topic", "/mocap/pose")
    assert code == 0, output
    return out, output


def test_calibration_against_motion_capture_finds_the_twins_factors(
    calibrated: tuple[Path, str],
) -> None:
    out, output = calibrated
    assert "odometry: wheel encoders on /wheel_states" in output
    assert "reference /mocap/pose (geometry_msgs/PoseStamped, mocap_world)" in output
    got = read_factors(out)
    assert not got.held  # every factor determined
    for name in SCALES:  # measured: within 0.05 % (0.9 σ) of the truth
        assert abs(getattr(got.factors, name) / getattr(TRUTH, name) - 1.0) < 0.0015, name
    for name in CROSSTALKS:  # measured: within 1.1 mrad/m (≤ 1.5 σ)
        assert abs(getattr(got.factors, name) - getattr(TRUTH, name)) < 0.0025, name
    # the motion-capture body's offset from base_link is found (printed as the hedgehog's)
    assert "x +0.040 m, y -0.020 m" in output


def _rmse(runs: dict[str, Path], out: Path, *extra: str) -> float:
    args = ["evaluate", str(runs["liss"]), "--robot", str(runs["robot"]), "--out", str(out)]
    args += ["--wheel-topic", "/wheel_states", "--reference-topic", "/mocap/pose", *extra]
    args += ["--no-figures"]  # the metrics only (the figures: half of the CPU)
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert list(metrics) == ["odometry"]
    return float(metrics["odometry"]["rmse_m"])


def test_held_out_odometry_improves_against_motion_capture(
    runs: dict[str, Path], calibrated: tuple[Path, str]
) -> None:
    nominal = _rmse(runs, runs["dir"] / "ev-nominal")
    corrected = _rmse(runs, runs["dir"] / "ev-calibrated", "--factors", str(calibrated[0]))
    # measured: 0.078 m nominal, 0.0034 m calibrated (the twin's true error is 0.080 m)
    assert nominal > 0.05
    assert corrected < 0.008
    assert nominal / corrected > 10.0


def test_a_tum_file_is_the_same_reference(
    runs: dict[str, Path], calibrated: tuple[Path, str]
) -> None:
    poses = read_pose_topic(runs["tour"], "/mocap/pose").table
    lines = [
        f"{t / 1e9:.9f} {x:.6f} {y:.6f} 0 0 0 {np.sin(w / 2):.9f} {np.cos(w / 2):.9f}"
        for t, x, y, w in zip(
            poses.t_ns.tolist(), poses["x_m"], poses["y_m"], poses["yaw_rad"], strict=True
        )
    ]
    tum = runs["dir"] / "mocap.tum"
    tum.write_text("\n".join(lines) + "\n", encoding="utf-8")
    out = runs["dir"] / "cal-tum" / "factors.yaml"
    code, output = _calibrate(runs, out, "--reference-file", str(tum))
    assert code == 0, output
    a, b = read_factors(out).factors.as_vector(), read_factors(calibrated[0]).factors.as_vector()
    np.testing.assert_allclose(a, b, atol=2e-5)  # the file's 1 µm / 1 ns rounding


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--reference-topic", "/robot/pose"], "no topic /robot/pose (pose topics: /mocap/pose)"),
        (
            ["--reference-topic", "/mocap/pose", "--reference-file", "x.tum"],
            "give one reference",
        ),
        (["--reference-child", "robot"], "--reference-child selects a frame"),
        (["--reference-topic", "/mocap/pose", "--method", "procedures"], "joint method"),
        (["--reference-topic", "/mocap/pose", "--odometry", "seed003"], "does not go with"),
        (["--reference-topic", "/mocap/pose", "--installed", "f.yaml"], "drop --installed"),
    ],
)
def test_user_mistakes_are_one_line_and_exit_2(
    runs: dict[str, Path], tmp_path: Path, extra: list[str], message: str
) -> None:
    code, output = _calibrate(runs, tmp_path / "f.yaml", *extra)
    assert code == 2, output
    assert message in output
    assert output.count("omnical: error") == 1


def test_without_wheel_topic_or_joint_mapping(runs: dict[str, Path], tmp_path: Path) -> None:
    base = ["calibrate", "estimate", str(runs["tour"]), "--reference-topic", "/mocap/pose"]
    result = runner.invoke(
        app, [*base, "--robot", str(runs["robot"]), "--out", str(tmp_path / "a.yaml")]
    )
    text = " ".join(result.output.split())
    assert result.exit_code == 2
    # issue 29: it named no topic; evaluate named the bag's JointState topic
    assert "no /odom; its wheel encoders are on /wheel_states: --wheel-topic /wheel_states" in text
    # the preset names its joints like its wheels: the bag's driver does not
    args = [*base, "--wheel-topic", "/wheel_states", "--out", str(tmp_path / "b.yaml")]
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    assert "no joint named 'rear_left' (joints: wheel_fl_joint, wheel_fr_joint" in result.output
    assert "wheel_encoders.joints" in result.output


def test_evaluate_without_a_reference_says_how_to_give_one(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    args = [
        "evaluate",
        str(runs["liss"]),
        "--robot",
        str(runs["robot"]),
        "--out",
        str(tmp_path / "e"),
    ]
    result = runner.invoke(app, [*args, "--wheel-topic", "/wheel_states"])
    assert result.exit_code == 2
    assert "has no /ground_truth; give the reference: --reference-topic" in result.output


def test_an_unknown_odometry_source_is_refused_naming_every_source() -> None:
    result = runner.invoke(app, ["evaluate", "x", "--out", "y", "--odometry", "ticks"])
    assert result.exit_code == 2
    assert "--odometry: unknown value 'ticks'; choose odom, wheels or seed003" in result.output


def _evaluate_liss(runs: dict[str, Path], out: Path, *reference: str) -> tuple[float, str]:
    args = ["evaluate", str(runs["liss"]), "--robot", str(runs["robot"]), "--out", str(out)]
    result = runner.invoke(
        app, [*args, "--wheel-topic", "/wheel_states", "--no-figures", *reference]
    )
    assert result.exit_code == 0, result.output
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    return float(metrics["odometry"]["rmse_m"]), result.output


@pytest.mark.parametrize("fmt", ["tum", "csv"])
def test_an_exported_motion_capture_topic_is_the_same_reference(
    runs: dict[str, Path], fmt: str
) -> None:
    """export writes /mocap/pose (it skipped it silently, or refused with --format tum); the
    file it writes gives the same errors as the topic itself."""
    out = runs["dir"] / f"export-{fmt}"
    result = runner.invoke(app, ["export", str(runs["liss"]), "--format", fmt, "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert f"wrote {out / f'mocap_pose.{fmt}'}" in result.output
    assert "skipped /mocap/pose" not in result.output
    if fmt == "tum":  # every topic not written is named, with its type
        assert "skipped /imu (sensor_msgs/msg/Imu): not a trajectory" in result.output
        assert "skipped /wheel_states (sensor_msgs/msg/JointState)" in result.output
    topic, _ = _evaluate_liss(
        runs, runs["dir"] / f"ev-topic-{fmt}", "--reference-topic", "/mocap/pose"
    )
    ref_file = out / f"mocap_pose.{fmt}"
    got, output = _evaluate_liss(
        runs, runs["dir"] / f"ev-file-{fmt}", "--reference-file", str(ref_file)
    )
    assert got == pytest.approx(topic, rel=1e-9, abs=1e-12)
    assert "reference times: absolute bag time" in output
    assert "errors (m) against the reference (mocap_pose." in output


def test_without_ips_or_reference_the_pose_topic_is_suggested(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """Issue 29: a bag with a pose topic but no IPS said "nothing to multilaterate" only."""
    code, output = _calibrate(runs, tmp_path / "f.yaml")
    text = " ".join(output.split())
    assert code == 2, output
    assert "no IPS raw distances (/beacon_raw_distance) to calibrate against" in text
    assert "--reference-topic /mocap/pose" in text
    assert not list(tmp_path.iterdir())  # nothing left behind


def test_encoder_counts_without_counts_per_rev_are_refused(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """Issue 29: ticks read as radians gave an odometry RMSE of 51 m with exit 0; the only clue
    was "4879 encoder steps taken as counter resets"."""
    text = runs["robot"].read_text(encoding="utf-8")
    lines = [line for line in text.splitlines() if "counts_per_rev" not in line]
    robot = tmp_path / "no-counts.yaml"
    robot.write_text("\n".join(lines) + "\n", encoding="utf-8")
    args = ["evaluate", str(runs["liss"]), "--robot", str(robot), "--out", str(tmp_path / "ev")]
    args += ["--wheel-topic", "/wheel_states", "--reference-topic", "/mocap/pose"]
    result = runner.invoke(app, args)
    text = " ".join(result.output.split())
    assert result.exit_code == 2, result.output
    assert "encoder counts, not radians; give wheel_encoders.counts_per_rev" in text
    # a preset's user cannot edit the preset: told how to change it in a file of their own
    assert "'base: PRESET' and 'wheel_encoders: {counts_per_rev: N}', given as --robot FILE" in text
    assert not (tmp_path / "ev").exists()


def test_a_robot_file_based_on_the_preset_is_the_whole_description(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """What the counts refusal tells a preset's user to write: ``base: rosy-mecanum`` and the
    ``wheel_encoders`` section give the same odometry as the preset copied with that section."""
    text = runs["robot"].read_text(encoding="utf-8")
    based = tmp_path / "based.yaml"
    section = text[text.index("wheel_encoders:") :]
    based.write_text("base: rosy-mecanum\n" + section, encoding="utf-8")
    args = ["evaluate", str(runs["liss"]), "--robot", str(based), "--out", str(tmp_path / "ev")]
    args += ["--wheel-topic", "/wheel_states", "--reference-topic", "/mocap/pose"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert f"robot: rosy-mecanum (file {based}, wheel encoders 777 counts/rev)" in result.output
    got = json.loads((tmp_path / "ev" / "metrics.json").read_text(encoding="utf-8"))
    assert float(got["odometry"]["rmse_m"]) == pytest.approx(
        _rmse(runs, tmp_path / "ev-full"), rel=1e-12
    )
