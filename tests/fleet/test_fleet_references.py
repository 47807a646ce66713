"""``omnical fleet`` with the single commands' reference and odometry options (issue 27): the
same figures as ``evaluate`` / ``calibrate estimate`` / ``locate --plot`` on the same bag, on
real UWB data with motion-capture truth and on bags with wheel ticks and motion capture only."""

from __future__ import annotations

import csv
import importlib.util
import json
import sys
from importlib import resources
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from typer.testing import CliRunner

from omnical.bags.bag import write_bag
from omnical.bags.reference_topics import read_pose_topic
from omnical.calibration.factors_io import read_factors
from omnical.cli.main import app
from omnical.experiment.library import builtin_script_data
from omnical.experiment.script import parse_script
from omnical.robot.loader import load_robot
from omnical.twin.params import default_twin

runner = CliRunner()
TESTS = Path(__file__).resolve().parents[1]


def _helper(folder: str, name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, TESTS / folder / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(name, module)
    spec.loader.exec_module(module)
    return module


uwb = _helper("ips", "uwb_bags")
mocap = _helper("estimation", "mocap_bags")


def _invoke(*args: str | Path) -> str:
    result = runner.invoke(app, list(map(str, args)))
    assert result.exit_code == 0, result.output
    return result.output


def _rows(out: Path) -> list[dict[str, str]]:
    with (out / "fleet.csv").open(encoding="utf-8", newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def real(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The CUHK-SZ run (motion-capture truth) and the TU Chemnitz run as bags, each with its
    truth as a CSV reference beside it (``NAME.csv``: t_ns, x_m, y_m)."""
    folder = tmp_path_factory.mktemp("real")
    bags = {}
    for name, run in (("cuhksz", uwb.cuhksz_run()), ("tuc", uwb.tuc_run())):
        bags[name] = write_bag(run.recording, folder / f"{name}.mcap")
        with (folder / f"{name}.csv").open("w", encoding="utf-8", newline="") as f:
            w = csv.writer(f)
            w.writerow(["t_ns", "x_m", "y_m"])
            for t, (x, y) in zip(run.t_ns.tolist(), run.truth_xy_m.tolist(), strict=True):
                w.writerow([t, repr(x), repr(y)])
    return bags


def test_evaluate_with_each_recordings_reference_file_is_the_single_command(
    real: dict[str, Path], tmp_path: Path
) -> None:
    out = tmp_path / "fleet"
    template = str(real["cuhksz"].parent / "{stem}.csv")
    _invoke("fleet", "evaluate", real["cuhksz"], real["tuc"], "--reference-file", template,
            "--executor", "serial", "--out", out)  # fmt: skip
    rows = {row["name"]: row for row in _rows(out)}
    assert [rows[n]["status"] for n in ("cuhksz", "tuc")] == ["ok", "ok"], rows
    report = (out / "report.md").read_text(encoding="utf-8")
    assert f"Each recording's reference (given: {template})" in report
    for name, bag in real.items():
        single = tmp_path / f"single-{name}"
        printed = _invoke(
            "evaluate", bag, "--reference-file", bag.parent / f"{name}.csv", "--out", single
        )
        # the reference each row used, and the rule the single command prints for it
        assert rows[name]["reference"] == str(bag.parent / f"{name}.csv")
        assert f"reference times: {rows[name]['reference_times']}" in " ".join(printed.split())
        assert f"| {name} | {rows[name]['reference']} |" in report
        metrics = json.loads((single / "metrics.json").read_text(encoding="utf-8"))
        assert float(rows[name]["multilateration_rmse_m"]) == metrics["multilateration"]["rmse_m"]
        assert float(rows[name]["multilateration_max_m"]) == metrics["multilateration"]["max_m"]
        assert (out / "recordings" / name / "metrics.json").is_file()
    # the real runs' multilateration against motion capture: centimetres to decimetres
    assert 0.01 < float(rows["cuhksz"]["multilateration_rmse_m"]) < 0.5


def test_locate_plot_is_what_locate_draws(real: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "fleet"
    _invoke("fleet", "locate", real["cuhksz"], "--plot", "--executor", "serial", "--out", out)
    single = tmp_path / "single"
    single.mkdir()
    _invoke("locate", real["cuhksz"], "--out", single / "fixes.csv", "--plot", single / "f.png")
    mine = out / "recordings" / "cuhksz"
    assert (mine / "fixes.csv").read_bytes() == (single / "fixes.csv").read_bytes()
    assert (mine / "fixes.png").read_bytes() == (single / "f.png").read_bytes()


@pytest.fixture(scope="module")
def mocap_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A tour as a user's robot records it: wheel ticks and motion capture, no /odom, no IPS."""
    folder = tmp_path_factory.mktemp("mocap")
    preset = resources.files("omnical.data.robots").joinpath("rosy-mecanum.yaml")
    robot_file = folder / "robot.yaml"
    robot_file.write_text(mocap.robot_yaml(preset.read_text("utf-8")), encoding="utf-8")
    robot = load_robot("rosy-mecanum")
    tour = parse_script(builtin_script_data("tour"), robot.limits)
    mocap.twin_user_run(folder / "tour", tour, robot, default_twin(robot), 1)
    return {"robot": robot_file, "tour": folder / "tour"}


def test_calibrate_and_evaluate_with_wheels_and_motion_capture_are_the_single_commands(
    mocap_run: dict[str, Path], tmp_path: Path
) -> None:
    sources: list[str | Path] = ["--robot", mocap_run["robot"], "--wheel-topic", "/wheel_states"]
    sources += ["--reference-topic", "/mocap/pose"]
    out = tmp_path / "fleet"
    _invoke("fleet", "calibrate", mocap_run["tour"], *sources, "--executor", "serial",
            "--out", out)  # fmt: skip
    (row,) = _rows(out)
    assert row["status"] == "ok" and row["method"] == "joint", row
    single = tmp_path / "single.yaml"
    _invoke("calibrate", "estimate", mocap_run["tour"], *sources, "--out", single)
    mine = read_factors(out / "recordings" / "tour" / "factors.yaml").factors
    assert mine == read_factors(single).factors
    assert float(row["scale_lateral"]) == mine.scale_lateral
    # the files' comment: the single command's, with the fleet's name (review: it lacked the
    # odometry and reference options)
    said = (out / "recordings" / "tour" / "factors.yaml").read_text("utf-8").splitlines()[0]
    options = " --method joint --wheel-topic /wheel_states --reference-topic /mocap/pose"
    assert single.read_text("utf-8").splitlines()[0] == (
        f"# omnical calibrate estimate {mocap_run['tour']}{options}"
    )
    assert said == f"# omnical fleet calibrate {mocap_run['tour'].absolute()}{options}"
    assert (row["reference"], row["reference_times"]) == (
        "/mocap/pose",
        "message stamps (bag time)",
    )

    # the same motion capture as each recording's TUM file ({parent}/{stem}.tum)
    poses = read_pose_topic(mocap_run["tour"], "/mocap/pose").table
    with (mocap_run["tour"].parent / "tour.tum").open("w", encoding="utf-8") as f:
        for t, x, y, w in zip(
            poses.t_ns.tolist(), poses["x_m"], poses["y_m"], poses["yaw_rad"], strict=True
        ):
            f.write(
                f"{t / 1e9:.9f} {x:.6f} {y:.6f} 0 0 0 {np.sin(w / 2):.9f} {np.cos(w / 2):.9f}\n"
            )
    tum = tmp_path / "tum"
    _invoke("fleet", "calibrate", mocap_run["tour"], *sources[:4], "--reference-file",
            "{parent}/{stem}.tum", "--executor", "serial", "--out", tum)  # fmt: skip
    from_file = read_factors(tum / "recordings" / "tour" / "factors.yaml").factors
    tum_said = (tum / "recordings" / "tour" / "factors.yaml").read_text("utf-8").splitlines()[0]
    assert tum_said.endswith(f" --reference-file {mocap_run['tour'].parent / 'tour.tum'}")
    np.testing.assert_allclose(from_file.as_vector(), mine.as_vector(), atol=2e-5)  # 1 µm, 1 ns

    # evaluate: the wheels' odometry corrected by those factors, against the motion capture
    fleet_eval = tmp_path / "fleet-eval"
    _invoke("fleet", "evaluate", mocap_run["tour"], *sources, "--factors", single,
            "--executor", "serial", "--out", fleet_eval)  # fmt: skip
    (evaluated,) = _rows(fleet_eval)
    single_eval = tmp_path / "single-eval"
    _invoke("evaluate", mocap_run["tour"], *sources, "--factors", single, "--out", single_eval)
    metrics = json.loads((single_eval / "metrics.json").read_text(encoding="utf-8"))
    odometry = float(evaluated["odometry_rmse_m"])
    assert odometry == pytest.approx(metrics["odometry"]["rmse_m"], rel=1e-12)
    assert np.isfinite(odometry) and odometry < 0.2


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["--reference-topic", "/a", "--reference-file", "x.csv"], "give one reference"),
        (["--reference-file", "nowhere.csv"], "--reference-file nowhere.csv: no such file"),
        (["--reference", "circle", "--reference-topic", "/a"], "give one reference"),
        (["--odometry", "wheels"], "--odometry wheels needs --wheel-topic"),
        (["--factors", "nowhere.yaml"], "--factors nowhere.yaml: no such file"),
    ],
)
def test_a_bad_reference_or_odometry_is_one_line_before_anything_runs(
    tmp_path: Path, args: list[str], said: str
) -> None:
    out = tmp_path / "out"
    result = runner.invoke(app, ["fleet", "evaluate", "a.mcap", *args, "--out", str(out)])
    assert result.exit_code == 2, result.output
    assert said in result.output and "Traceback" not in result.output
    assert not out.exists()


def test_installed_factors_do_not_go_with_computed_odometry(tmp_path: Path) -> None:
    (tmp_path / "f.yaml").write_text("x: 1\n", encoding="utf-8")
    args = ["fleet", "calibrate", "a.mcap", "--wheel-topic", "/w", "--installed"]
    result = runner.invoke(app, [*args, str(tmp_path / "f.yaml"), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and "drop --installed" in result.output, result.output


def test_locate_poor_fixes_are_an_error_row_unless_allowed_as_locate_exits(
    real: dict[str, Path], tmp_path: Path
) -> None:
    """CUHK-SZ without self-calibration: fewer than half the fixes usable, where `omnical
    locate` warns and exits 3 unless --allow-poor; in the fleet an error row saying so (the
    fixes written), and with --allow-poor an ok row with the same fixes."""
    single = runner.invoke(app, ["locate", str(real["cuhksz"]), "--no-self-calibration",
                                 "--out", str(tmp_path / "single.csv")])  # fmt: skip
    assert single.exit_code == 3, single.output
    args = ["fleet", "locate", real["cuhksz"], real["tuc"], "--no-self-calibration"]
    result = runner.invoke(app, [*map(str, args), "--executor", "serial", "--out",
                                 str(tmp_path / "poor")])  # fmt: skip
    assert result.exit_code == 0, result.output  # one recording gave a result
    rows = {r["name"]: r for r in _rows(tmp_path / "poor")}
    assert rows["cuhksz"]["status"] == "error"
    assert rows["cuhksz"]["reason"].startswith("only ") and "usable" in rows["cuhksz"]["reason"]
    assert rows["tuc"]["status"] == "ok", rows["tuc"]
    fixes = tmp_path / "poor" / "recordings" / "cuhksz" / "fixes.csv"
    assert fixes.read_bytes() == (tmp_path / "single.csv").read_bytes()
    _invoke(*args, "--allow-poor", "--executor", "serial", "--out", tmp_path / "allowed")
    allowed = {r["name"]: r for r in _rows(tmp_path / "allowed")}
    assert allowed["cuhksz"]["status"] == "ok"
    assert float(allowed["cuhksz"]["usable_fraction"]) < 0.5
