"""``omnical fleet``: one row per recording from the single commands' own calls, a broken
recording one error row, 3σ maintenance alerts against the fleet and --previous (issue 27)."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
from typer.testing import CliRunner

from omnical.bags.bag import write_bag
from omnical.cli.main import app
from omnical.experiment.library import builtin_script_data
from omnical.experiment.script import parse_script
from omnical.robot.loader import load_robot
from omnical.twin.params import default_twin, parse_twin
from omnical.twin.session import simulate_run

runner = CliRunner()


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Four tours of the default twin (one with its lateral scaling drifted by 5 %) and a file
    that is not a bag."""
    folder = tmp_path_factory.mktemp("fleet")
    robot = load_robot("rosy-mecanum")
    script = parse_script(builtin_script_data("tour"), robot.limits)
    drifted = parse_twin({"true_factors": {"scale": {"lateral": 1.19}}}, robot)
    bags = []
    for i, twin in enumerate([default_twin(robot)] * 3 + [drifted]):
        rec = simulate_run(script, robot, twin, seed=10 + i)
        bags.append(write_bag(rec, folder / f"robot{i}.mcap"))
    broken = folder / "broken.mcap"
    broken.write_bytes(b"not a bag at all\n")
    return [*bags, broken]


def _rows(out: Path) -> list[dict[str, str]]:
    with (out / "fleet.csv").open(encoding="utf-8", newline="") as f:
        return list(csv.DictReader(f))


def _fleet(*args: str | Path) -> str:
    result = runner.invoke(app, ["fleet", *map(str, args)])
    assert result.exit_code == 0, result.output
    return result.output


def test_calibrate_fleet_rows_alerts_and_the_single_command(
    fleet: list[Path], tmp_path: Path
) -> None:
    out = tmp_path / "fleet"
    printed = _fleet("calibrate", *fleet, "--executor", "local:2", "--out", out)
    rows = _rows(out)
    assert [r["name"] for r in rows] == ["robot0", "robot1", "robot2", "robot3", "broken"]
    assert [r["status"] for r in rows] == ["ok"] * 4 + ["error"]
    assert "broken.mcap: cannot read bag" in rows[4]["reason"]
    assert "broken: error:" in printed
    # the drifted robot, and only its lateral scaling, is flagged against the fleet
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "| robot3 | scale_lateral |" in report
    assert report.count("| fleet |") == 1
    assert (out / "figures" / "factors.png").is_file()
    # the single command's own estimate of that recording, byte for byte in its factors
    single = tmp_path / "single.yaml"
    result = runner.invoke(app, ["calibrate", "estimate", str(fleet[3]), "--out", str(single)])
    assert result.exit_code == 0, result.output
    from omnical.calibration.factors_io import read_factors

    mine = read_factors(out / "recordings" / "robot3" / "factors.yaml").factors
    assert mine == read_factors(single).factors
    assert float(rows[3]["scale_lateral"]) == mine.scale_lateral
    assert (out / "recordings" / "robot3" / "factors.h").is_file()
    assert not (out / "recordings" / "broken").exists()

    # against a previous calibration: robot0's previous lateral scaling 5 % lower
    previous = tmp_path / "previous"
    previous.mkdir()
    with (out / "fleet.csv").open(encoding="utf-8") as f:
        text = f.read()
    old = rows[0]["scale_lateral"]
    (previous / "fleet.csv").write_text(text.replace(old, repr(float(old) / 1.05), 1))
    again = tmp_path / "again"
    _fleet("calibrate", *fleet[:4], "--executor", "serial", "--out", again, "--previous", previous)
    report = (again / "report.md").read_text(encoding="utf-8")
    assert "| robot0 | scale_lateral |" in report and "| previous |" in report


def test_locate_fleet_is_what_locate_writes(fleet: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "locate"
    _fleet("locate", fleet[0], fleet[4], "--executor", "serial", "--out", out)
    rows = _rows(out)
    assert [r["status"] for r in rows] == ["ok", "error"]
    single = tmp_path / "fixes.csv"
    result = runner.invoke(app, ["locate", str(fleet[0]), "--out", str(single)])
    assert result.exit_code == 0, result.output
    mine = (out / "recordings" / "robot0" / "fixes.csv").read_bytes()
    assert mine == single.read_bytes()
    assert int(rows[0]["fixes"]) == len(mine.splitlines()) - 1


def test_evaluate_fleet_is_what_evaluate_measures(fleet: list[Path], tmp_path: Path) -> None:
    import json

    out = tmp_path / "evaluate"
    _fleet("evaluate", fleet[1], "--executor", "serial", "--out", out)
    (row,) = _rows(out)
    single = tmp_path / "single"
    result = runner.invoke(app, ["evaluate", str(fleet[1]), "--out", str(single)])
    assert result.exit_code == 0, result.output
    metrics = json.loads((single / "metrics.json").read_text(encoding="utf-8"))
    for estimate in ("odometry", "ips", "multilateration", "smoothed"):
        assert float(row[f"{estimate}_rmse_m"]) == pytest.approx(
            metrics[estimate]["rmse_m"], rel=1e-12
        )
    assert (out / "recordings" / "robot1" / "metrics.json").is_file()
    assert (row["reference"], row["reference_times"]) == ("/ground_truth", "")
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "Every recording against /ground_truth." in report


def test_the_output_directory_is_claimed(fleet: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "o"
    first = runner.invoke(
        app, ["fleet", "locate", str(fleet[4]), "--executor", "serial", "--out", str(out)]
    )
    assert first.exit_code == 3, first.output  # its one recording is broken: no result
    again = runner.invoke(app, ["fleet", "locate", str(fleet[4]), "--out", str(out)])
    assert again.exit_code == 2 and "--resume continues it, --overwrite" in again.output
    other = runner.invoke(
        app, ["fleet", "locate", str(fleet[4]), "--method", "lsq", "--out", str(out), "--resume"]
    )
    assert other.exit_code == 2 and "other settings" in other.output
    assert 'options.method: "robust" then, "lsq" now' in other.output  # which one differs
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "mine.txt").write_text("x")
    refused = runner.invoke(app, ["fleet", "locate", str(fleet[4]), "--out", str(foreign)])
    assert refused.exit_code == 2 and "did not write" in refused.output
    assert (foreign / "mine.txt").read_text() == "x"


def test_a_fleet_where_every_recording_failed_exits_3(fleet: list[Path], tmp_path: Path) -> None:
    """Found by a new user: every row an error still exited 0. The table is written; exit 3."""
    out = tmp_path / "none"
    result = runner.invoke(app, ["fleet", "locate", str(fleet[-1]), "--out", str(out)])
    assert result.exit_code == 3, result.output
    assert "no recording gave a result" in result.output
    assert [r["status"] for r in _rows(out)] == ["error"]
    assert result.output.startswith("broken: error: ")  # no blank line first


def test_a_folder_that_is_not_a_bag_is_named_as_a_folder(tmp_path: Path) -> None:
    folder = tmp_path / "run7"
    folder.mkdir()
    (folder / "run7_0.mcap").write_bytes(b"")
    out = tmp_path / "o"
    result = runner.invoke(app, ["fleet", "locate", str(folder), "--out", str(out)])
    assert result.exit_code == 3, result.output
    (row,) = _rows(out)
    assert row["reason"] == (
        f"{folder}: cannot read bag (a folder without metadata.yaml: not a ROS 2 bag; it "
        "holds run7_0.mcap: give a file)"
    )


def test_a_built_in_reference_the_recording_does_not_follow_is_an_error_row(
    fleet: list[Path], tmp_path: Path
) -> None:
    """As omnical evaluate, which writes its files and exits 3: the files kept, the row says why."""
    out = tmp_path / "circle"
    args = ["fleet", "evaluate", str(fleet[0]), "--reference", "circle", "--executor", "serial"]
    result = runner.invoke(app, [*args, "--out", str(out)])
    assert result.exit_code == 3, result.output
    (row,) = _rows(out)
    assert row["status"] == "error"
    assert row["reason"].startswith("--reference circle: the recording does not follow the ")
    assert (out / "recordings" / "robot0" / "metrics.json").is_file()


def test_a_recording_with_nothing_to_evaluate_is_an_error_row(
    fleet: list[Path], tmp_path: Path
) -> None:
    """Only /ground_truth and /imu: omnical evaluate refuses it (exit 2); the fleet's row
    said "ok" with every measure empty (found by a review, issue 24)."""
    from omnical.bags.bag import read_bag

    tour = read_bag(fleet[0])
    bare = write_bag(
        tour.without(*(t for t in tour.topics if t not in ("/ground_truth", "/imu"))),
        tmp_path / "bare.mcap",
    )
    single = runner.invoke(app, ["evaluate", str(bare), "-o", str(tmp_path / "one")])
    assert single.exit_code == 2, single.output
    out = tmp_path / "fleet"
    result = runner.invoke(
        app, ["fleet", "evaluate", str(bare), "--executor", "serial", "--out", str(out)]
    )
    assert result.exit_code == 3, result.output
    (row,) = _rows(out)
    assert (row["status"], row["reason"]) == (
        "error",
        "bare: nothing to evaluate: no /odom and no positioning topics",
    )


def test_a_resume_through_dot_dot_names_the_same_recordings(
    fleet: list[Path], tmp_path: Path
) -> None:
    """Found by a new user: ``--resume`` with ``sub/../`` in the paths was refused
    ('"…/sub/../robot0.mcap" then, "…/robot0.mcap" now')."""
    out = tmp_path / "o"
    _fleet("locate", fleet[0], "--executor", "serial", "--out", out)
    (tmp_path / "sub").mkdir()
    roundabout = fleet[0].parent / "sub" / ".." / fleet[0].name
    (fleet[0].parent / "sub").mkdir(exist_ok=True)
    printed = _fleet(
        "locate", roundabout, "--executor", "serial", "--out", tmp_path / "sub" / ".." / "o",
        "--resume",
    )  # fmt: skip
    assert "(1 done before the resume)" in printed
    assert _rows(out)[0]["recording"] == str(fleet[0])


def _single_line(output: str, start: str) -> str:
    """The line of a single command's output that starts with ``start``."""
    (line,) = [ln for ln in output.splitlines() if ln.startswith(start)]
    return line


def test_locate_fixes_locate_finds_not_plausible_are_an_error_row_with_its_line(
    fleet: list[Path], tmp_path: Path
) -> None:
    """Review: --hedge-z that the ranges contradict exited 3 in omnical locate but was an ok
    row in the fleet. Now the same reason, as the row's, the fixes kept as locate keeps them."""
    out = tmp_path / "fleet"
    args = ["fleet", "locate", str(fleet[0]), str(fleet[1]), "--hedge-z", "50"]
    result = runner.invoke(app, [*args, "--executor", "serial", "--out", str(out)])
    assert result.exit_code == 3, result.output  # no recording gave a result
    single = runner.invoke(app, ["locate", str(fleet[0]), "--hedge-z", "50", "--out",
                                 str(tmp_path / "single.csv")])  # fmt: skip
    assert single.exit_code == 3, single.output
    said = _single_line(single.output, "omnical: the fixes are not plausible: ")
    rows = _rows(out)
    assert [r["status"] for r in rows] == ["error", "error"]
    assert rows[0]["reason"] == said.removeprefix("omnical: ")
    assert "--hedge-z 50 m: " in rows[1]["reason"]
    mine = out / "recordings" / "robot0" / "fixes.csv"
    assert mine.read_bytes() == (tmp_path / "single.csv").read_bytes()
    # the right height: plausible, an ok row
    good = tmp_path / "good"
    _fleet("locate", fleet[0], "--hedge-z", "0.4", "--executor", "serial", "--out", good)
    assert [r["status"] for r in _rows(good)] == ["ok"]


def test_each_recordings_beacons_and_factors_by_stem_and_parent(
    fleet: list[Path], tmp_path: Path
) -> None:
    """Review: {stem} / {parent} in --beacons, --installed, --factors passed the check but were
    read as they were (no such file: an error row each). Each recording now reads its own."""
    import numpy as np

    from omnical.bags.bag import read_bag
    from omnical.calibration.factors_io import write_factors
    from omnical.ips.beacons import BeaconMap, save_beacon_map
    from omnical.ips.from_recording import beacon_map_of
    from omnical.kinematics.correction import CorrectionFactors

    folder = tmp_path / "own"
    folder.mkdir()
    bags = [folder / "robot0", folder / "robot1"]
    for src, dst in zip(fleet[:2], bags, strict=True):
        dst.symlink_to(src)
    own = beacon_map_of(read_bag(bags[0]), None)
    save_beacon_map(own, folder / "robot0.beacons.yaml")
    moved = own.positions_m + np.array(
        [0.5, 0.0, 0.0]
    )  # robot1's map: every beacon 0.5 m further in x
    save_beacon_map(BeaconMap(own.addresses, moved), folder / "robot1.beacons.yaml")
    out = tmp_path / "locate"
    _fleet("locate", *bags, "--beacons", "{parent}/{stem}.beacons.yaml", "--executor",
           "serial", "--out", out)  # fmt: skip
    assert [r["status"] for r in _rows(out)] == ["ok", "ok"], _rows(out)
    for bag in bags:
        single = tmp_path / f"{bag.stem}.csv"
        args = ["locate", str(bag), "--beacons", str(folder / f"{bag.stem}.beacons.yaml")]
        result = runner.invoke(app, [*args, "--out", str(single)])
        assert result.exit_code == 0, result.output
        mine = out / "recordings" / bag.stem / "fixes.csv"
        assert mine.read_bytes() == single.read_bytes()
    a, b = (_fixes_x(out / "recordings" / n / "fixes.csv") for n in ("robot0", "robot1"))
    assert 0.3 < b - a < 0.7  # robot1's fixes in its own, moved map

    factors = CorrectionFactors(scale_lateral=1.03)
    write_factors(folder / "robot1.factors.yaml", factors)
    evaluated = tmp_path / "evaluate"
    _fleet("evaluate", bags[1], "--factors", "{parent}/{stem}.factors.yaml", "--executor",
           "serial", "--out", evaluated)  # fmt: skip
    (row,) = _rows(evaluated)
    single_eval = tmp_path / "single-eval"
    args = ["evaluate", str(bags[1]), "--factors", str(folder / "robot1.factors.yaml")]
    result = runner.invoke(app, [*args, "--out", str(single_eval)])
    assert result.exit_code == 0, result.output
    import json

    metrics = json.loads((single_eval / "metrics.json").read_text(encoding="utf-8"))
    assert float(row["odometry_rmse_m"]) == pytest.approx(metrics["odometry"]["rmse_m"], rel=1e-12)

    write_factors(folder / "robot1.installed.yaml", factors)
    calibrated = tmp_path / "calibrate"
    _fleet("calibrate", bags[1], "--installed", "{parent}/{stem}.installed.yaml", "--executor",
           "serial", "--out", calibrated)  # fmt: skip
    single_yaml = tmp_path / "single.yaml"
    args = ["calibrate", "estimate", str(bags[1]), "--installed"]
    result = runner.invoke(app, [*args, str(folder / "robot1.installed.yaml"), "--out",
                                 str(single_yaml)])  # fmt: skip
    assert result.exit_code == 0, result.output
    from omnical.calibration.factors_io import read_factors

    estimated = read_factors(calibrated / "recordings" / "robot1" / "factors.yaml").factors
    assert estimated == read_factors(single_yaml).factors


def _fixes_x(path: Path) -> float:
    import numpy as np

    with path.open(encoding="utf-8", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["status"] == "ok"]
    return float(np.median([float(r["x_m"]) for r in rows]))


def test_an_option_the_robot_cannot_take_is_one_line_before_any_job(
    fleet: list[Path], tmp_path: Path
) -> None:
    """Review: --odometry seed003 on a robot without dead wheels was an error row per
    recording; it is one line, exit 2, before anything is written."""
    out = tmp_path / "o"
    for command in ("evaluate", "calibrate"):
        args = ["fleet", command, str(fleet[0]), str(fleet[1]), "--odometry", "seed003"]
        result = runner.invoke(app, [*args, "--out", str(out)])
        assert result.exit_code == 2, result.output
        (line,) = [ln for ln in result.output.splitlines() if ln.startswith("omnical:")]
        assert line == (
            "omnical: error: --odometry seed003: robot rosy-mecanum has no dead wheels: seed 003's "
            "odometry needs them"
        )
        assert "Traceback" not in result.output and not out.exists()
