"""``omnical evaluate``: one time rule for reference files, stated in one line; a table of errors
against the reference that leaves out the reference itself and warns when it is the odometry."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from omnical.bags.bag import read_bag
from omnical.cli.main import app

runner = CliRunner()


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sim") / "run.mcap"
    result = runner.invoke(app, ["simulate", "straight-10m", "--seed", "1", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out.with_suffix("")


@pytest.fixture(scope="module")
def default(
    bag: Path, tmp_path_factory: pytest.TempPathFactory
) -> tuple[dict[str, dict[str, float]], str]:
    out = tmp_path_factory.mktemp("ev") / "default"
    result = runner.invoke(app, ["evaluate", str(bag), "--out", str(out)], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    return json.loads((out / "metrics.json").read_text(encoding="utf-8")), result.output


def _evaluate(bag: Path, out: Path, *extra: str) -> tuple[dict[str, dict[str, float]], str]:
    """``evaluate --no-figures``: the tests of the metrics and the messages (the figures are
    half the CPU of a short run's evaluation)."""
    result = runner.invoke(
        app,
        ["evaluate", str(bag), "--out", str(out), "--no-figures", *extra],
        env={"COLUMNS": "200"},
    )
    assert result.exit_code == 0, result.output
    return json.loads((out / "metrics.json").read_text(encoding="utf-8")), result.output


def test_no_figures_writes_the_same_metrics_and_a_report_without_figures(
    bag: Path, default: tuple[dict[str, dict[str, float]], str], tmp_path: Path
) -> None:
    drawn = Path(default[1].split("report.md and 3 figures in ")[1].split()[0])
    assert sorted(p.name for p in drawn.glob("*.png")) == ["path.png", "speeds.png", "xy-time.png"]
    assert "## Figures" in (drawn / "report.md").read_text(encoding="utf-8")
    metrics, output = _evaluate(bag, tmp_path / "e")
    assert metrics == default[0]
    assert "report.md and 0 figures in" in " ".join(output.split())
    assert not list((tmp_path / "e").glob("*.png"))
    report = (tmp_path / "e" / "report.md").read_text(encoding="utf-8")
    assert "## Tracking errors" in report and "## Figures" not in report


def test_against_the_ground_truth_it_is_not_a_row(
    default: tuple[dict[str, dict[str, float]], str],
) -> None:
    metrics, output = default
    assert "errors (m) against the reference (/ground_truth), alignment se2" in output
    assert "tracking errors" not in output
    assert "ground_truth" not in metrics and "│ ground_truth" not in output
    assert {"odometry", "ips", "multilateration", "smoothed"} <= set(metrics)


def test_the_ground_truth_topic_as_reference_is_not_a_row_either(bag: Path, tmp_path: Path) -> None:
    metrics, output = _evaluate(bag, tmp_path / "e", "--reference-topic", "ground_truth")
    assert "ground_truth" not in metrics
    assert "against the reference (ground_truth)" in output


def test_the_odometry_as_its_own_reference_is_warned(bag: Path, tmp_path: Path) -> None:
    metrics, output = _evaluate(bag, tmp_path / "e", "--reference-topic", "/odom")
    assert output.count("omnical: warning: the reference /odom is the odometry evaluated") == 1
    assert metrics["odometry"]["rmse_m"] < 1e-9
    assert "ground_truth" in metrics  # here a real comparison


def _ground_truth_csv(bag: Path, path: Path, column: str) -> Path:
    rec = read_bag(bag, ["/ground_truth"])
    gt = rec.topic("/ground_truth")
    if column == "t_ns":
        times = [str(t) for t in gt.t_ns.tolist()]
    elif column == "epoch":
        times = [f"{t // 10**9}.{t % 10**9:09d}" for t in gt.t_ns.tolist()]
    else:
        times = [repr(t) for t in gt.t_s(rec.start_ns).tolist()]
    name = "t_ns" if column == "t_ns" else "t_s"
    with path.open("w", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream)
        writer.writerow([name, "x_m", "y_m", "yaw_rad"])
        writer.writerows(
            zip(times, gt["x_m"].tolist(), gt["y_m"].tolist(), gt["yaw_rad"].tolist(), strict=True)
        )
    return path


@pytest.mark.parametrize(
    ("column", "note"),
    [
        ("epoch", "reference times: absolute bag time (t_s ≥ 1e8 s)"),
        ("t_ns", "reference times: absolute bag time (t_ns)"),
        ("relative", "reference times: relative to the bag start (t_s < 1e8 s)"),
    ],
)
def test_reference_csv_times_follow_one_rule_and_say_which(
    bag: Path,
    tmp_path: Path,
    default: tuple[dict[str, dict[str, float]], str],
    column: str,
    note: str,
) -> None:
    """Unix-epoch t_s were refused, t_ns was 'missing t_s'; all three are the ground truth."""
    ref = _ground_truth_csv(bag, tmp_path / f"{column}.csv", column)
    metrics, output = _evaluate(bag, tmp_path / "e", "--reference-file", str(ref))
    assert f"{bag.name}: reference {ref} (" in output and note in output
    assert metrics["ground_truth"]["max_m"] < 1e-6  # the file is the ground truth, in time
    assert metrics["odometry"]["rmse_m"] == pytest.approx(
        default[0]["odometry"]["rmse_m"], abs=1e-6
    )


def test_a_reference_covering_a_sliver_of_the_run_is_warned(bag: Path, tmp_path: Path) -> None:
    """Found by a new user: a reference of 3 poses over 0.094 s of a 270-s run gave an RMSE
    and exit 0 without a word on how little of the run it measured."""
    whole = _ground_truth_csv(bag, tmp_path / "whole.csv", "t_ns").read_text().splitlines()
    sliver = tmp_path / "sliver.csv"
    sliver.write_text("\n".join([whole[0], *whole[500:600]]) + "\n", encoding="utf-8")  # 2 s
    _, output = _evaluate(bag, tmp_path / "e", "--reference-file", str(sliver), "--align", "none")
    warned = [line for line in output.splitlines() if "pair with the reference" in line]
    assert len(warned) == 1 and warned[0].startswith("omnical: warning: only ")
    assert warned[0].endswith("): the measures speak for that part only")
    _, output = _evaluate(bag, tmp_path / "f", "--reference-file", str(_ground_truth_csv(
        bag, tmp_path / "all.csv", "t_ns")), "--align", "none")  # fmt: skip
    assert "pair with the reference" not in output


def test_omnicals_own_csv_export_is_a_reference(bag: Path, tmp_path: Path) -> None:
    result = runner.invoke(app, ["export", str(bag), "--out", str(tmp_path / "csv")])
    assert result.exit_code == 0, result.output
    ref = tmp_path / "csv" / "ground_truth.csv"
    metrics, output = _evaluate(bag, tmp_path / "e", "--reference", str(ref), "--align", "none")
    assert "reference times: absolute bag time (t_ns)" in output
    assert metrics["ground_truth"]["max_m"] == 0.0


def test_export_names_every_topic_it_leaves_out(tmp_path: Path) -> None:
    import importlib.util
    import sys

    import numpy as np

    path = Path(__file__).resolve().parents[1] / "estimation" / "mocap_bags.py"
    spec = importlib.util.spec_from_file_location("mocap_bags", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("mocap_bags", module)
    spec.loader.exec_module(module)
    static = {"base_link": np.zeros((1, 3)), "laser": np.ones((1, 3))}
    t_ns = np.array([1_700_000_000_000_000_000], dtype=np.int64)
    module.write_pose_bag(tmp_path / "b", "/tf_static", "tf2_msgs/msg/TFMessage", t_ns, static)
    result = runner.invoke(
        app, ["export", str(tmp_path / "b"), "--format", "tum", "--out", str(tmp_path / "x")]
    )
    assert result.exit_code == 2
    for child in static:
        line = f"skipped /tf_static → {child} (tf2_msgs/msg/TFMessage): a single pose, not a trajectory"
        assert line in result.output
    assert "nothing to export" in result.output


@pytest.fixture(scope="module")
def circle_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The built-in circle driven open loop on the twin, as a user's bag."""
    from dataclasses import replace

    from omnical.bags.bag import write_bag
    from omnical.experiment.script import TwistSequence
    from omnical.robot.loader import load_robot
    from omnical.trajectory.references import circle
    from omnical.trajectory.scripts import feedforward_commands
    from omnical.twin.params import default_twin
    from omnical.twin.session import simulate_run

    robot = load_robot("rosy-mecanum")
    ref = circle()
    t, twists = feedforward_commands(ref, 50.0, limits=robot.limits)
    commands = TwistSequence.from_arrays("circle", t, twists, rate_hz=50.0)
    start = (float(ref.poses[0, 0]), float(ref.poses[0, 1]), float(ref.poses[0, 2]))
    params = replace(default_twin(robot), start_pose_map=start)
    rec = simulate_run(commands, robot, params, seed=3).without("/ground_truth")
    return write_bag(rec, tmp_path_factory.mktemp("circle") / "circle.mcap")


@pytest.mark.parametrize(
    ("which", "reference", "off"),
    [
        ("circle", "circle", None),
        ("circle", "square", 0.38),  # measured 0.38 m
        ("straight", "circle", None),
    ],
)
def test_a_builtin_reference_the_run_does_not_follow_exits_3(
    bag: Path, circle_run: Path, tmp_path: Path, which: str, reference: str, off: float | None
) -> None:
    """Issue 29: --reference circle on a run that is not one gave errors of 0.86 m everywhere
    with exit 0. The files are written all the same (path.png shows it)."""
    run = circle_run if which == "circle" else bag
    out = tmp_path / "ev"
    result = runner.invoke(
        app,
        ["evaluate", str(run), "--reference", reference, "--out", str(out)],
        env={"COLUMNS": "200"},
    )
    text = " ".join(result.output.split())
    assert (out / "metrics.json").is_file() and (out / "path.png").is_file()
    if which == "circle" and reference == "circle":
        assert result.exit_code == 0, result.output
        assert "does not follow" not in text
        return
    assert result.exit_code == 3, result.output
    assert (
        f"--reference {reference}: the recording does not follow the built-in {reference}" in text
    )
    if off is not None:
        assert f"is {off:.2f} m RMS from it after se2 alignment" in text
