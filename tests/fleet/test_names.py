"""A fleet's recording names: unique and the same whatever the order (each names an output
directory and is what ``--previous`` matches by), and drift refusing a table of repeated names."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
from typer.testing import CliRunner

from omnical.calibration.drift import factor_alerts
from omnical.cli.main import app
from omnical.errors import ConfigError, RecordingError
from omnical.fleet.jobs import fleet_header, fleet_job_name

runner = CliRunner()


def _names(*paths: str) -> list[str]:
    return fleet_job_name([Path(p) for p in paths])


def test_a_name_a_repeat_would_take_is_not_taken_twice() -> None:
    assert _names("/f/x/r1.mcap", "/f/y/r1.mcap", "/f/z/r1-2.mcap") == ["x_r1", "y_r1", "r1-2"]


def test_names_do_not_depend_on_the_order() -> None:
    assert _names("/f/robot1/run.mcap", "/f/robot2/run.mcap") == ["robot1_run", "robot2_run"]
    assert _names("/f/robot2/run.mcap", "/f/robot1/run.mcap") == ["robot2_run", "robot1_run"]
    assert _names("/f/a/r.mcap", "/f/b/r.mcap", "/f/c/a_r.mcap") == ["f_a_r", "b_r", "c_a_r"]


def test_names_unique_ignoring_case_and_once_the_directories_run_out() -> None:
    assert _names("/f/A/Run.mcap", "/f/b/run.bag", "/f/q.mcap") == ["A_Run", "b_run", "q"]
    names = _names("/f/x/run.mcap", "/f/x/run.bag", "/f/y/run")
    assert names[2] == "y_run"
    assert names[0] != names[1] and all(n.startswith("f_x_run-") for n in names[:2])
    assert names == _names("/f/x/run.mcap", "/f/x/run.bag", "/f/y/run")  # a digest: stable


def test_the_same_recording_twice_is_refused() -> None:
    with pytest.raises(ConfigError, match="given twice"):
        _names("/f/x/run.mcap", "/f/x/../x/run.mcap")


def test_the_fleet_table_has_one_row_and_directory_per_name(tmp_path: Path) -> None:
    bags = []
    for folder, name in (("x", "r1"), ("y", "r1"), ("z", "r1-2")):
        (tmp_path / folder).mkdir()
        bags.append(tmp_path / folder / f"{name}.mcap")
        bags[-1].write_bytes(b"not a bag\n")
    out = tmp_path / "out"
    result = runner.invoke(
        app, ["fleet", "locate", *map(str, bags), "--executor", "serial", "--out", str(out)]
    )
    assert result.exit_code == 3, result.output  # every one broken: rows, no result
    with (out / "fleet.csv").open(encoding="utf-8", newline="") as f:
        names = [row["name"] for row in csv.DictReader(f)]
    assert names == ["x_r1", "y_r1", "r1-2"]


def _row(name: str, value: float) -> dict[str, str]:
    return {
        "name": name,
        "status": "ok",
        "scale_lateral": repr(value),
        "scale_lateral_sigma": "0.001",
    }


def test_drift_refuses_two_rows_of_one_name() -> None:
    rows = [_row(n, 1.1) for n in ("a", "b", "c", "d")]
    assert factor_alerts(rows, ["scale_lateral"], [_row("a", 1.0)])  # a moved: alerted
    with pytest.raises(RecordingError, match=r"previous fleet\.csv: two rows are named 'a'"):
        factor_alerts(rows, ["scale_lateral"], [_row("a", 1.1), _row("a", 1.0)])
    with pytest.raises(RecordingError, match="fleet: two rows are named 'b'"):
        factor_alerts([*rows, _row("b", 1.3)], ["scale_lateral"])


def test_a_previous_table_of_repeated_names_is_refused_before_the_fleet_runs(
    tmp_path: Path,
) -> None:
    previous = tmp_path / "previous"
    previous.mkdir()
    with (previous / "fleet.csv").open("w", encoding="utf-8", newline="") as f:
        writer = csv.DictWriter(f, fleet_header("calibrate"))  # a calibrate table's columns
        writer.writeheader()
        writer.writerows(
            [
                {"index": 0, "name": "r1-2", "status": "ok"},
                {"index": 1, "name": "r1-2", "status": "ok"},
            ]
        )
    bag = tmp_path / "run.mcap"
    bag.write_bytes(b"not a bag\n")
    out = tmp_path / "out"
    result = runner.invoke(
        app,
        ["fleet", "calibrate", str(bag), "--previous", str(previous), "--out", str(out)],
    )
    assert result.exit_code == 2, result.output
    assert "two rows are named 'r1-2'" in result.output
    assert result.output.count("omnical: error:") == 1 and "Traceback" not in result.output
    assert not out.exists()
