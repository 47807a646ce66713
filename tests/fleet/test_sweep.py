"""``omnical sweep``: the same table whatever the executor, the spec's errors in one line, the
draws of run i independent of N (issue 27)."""

from __future__ import annotations

import contextlib
import socket
import warnings
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from omnical.cli.main import app
from omnical.fleet.sweep import parse_sweep_spec, sample_run

runner = CliRunner()

SPEC = """\
robot: rosy-mecanum
twin: default
iterations: 1
target: 0.002
parameters:
  true_factors.scale.longitudinal: {uniform: [0.98, 1.04]}
  ips.distance_noise_m: {loguniform: [0.005, 0.03]}
  room_scale: {choice: [0.8, 1.0, 1.3]}
  slip_sigma: 0.002
  procedure.rotation.turns: {choice: [2, 3]}
"""


@pytest.fixture(scope="module")
def spec_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("spec") / "spec.yaml"
    path.write_text(SPEC, encoding="utf-8")
    return path


def _sweep(spec: Path, out: Path, executor: str, *extra: str) -> str:
    args = ["sweep", str(spec), "--runs", "4", "--seed", "11", "--executor", executor]
    result = runner.invoke(app, [*args, "--out", str(out), "--chunk", "1", *extra])
    assert result.exit_code == 0, result.output
    return (out / "sweep.csv").read_text(encoding="utf-8")


def test_local_and_dask_local_give_identical_tables(spec_file: Path, tmp_path: Path) -> None:
    serial = _sweep(spec_file, tmp_path / "serial", "serial")
    local = _sweep(spec_file, tmp_path / "local", "local:2")
    # one Dask worker (two fewer processes than two workers): putting results that arrive
    # out of order back in order is the runner's, the same for every executor (local:2)
    with contextlib.ExitStack() as stack:
        # Dask's default HTTP port taken (another sweep running): no warning, the port not needed
        taken = stack.enter_context(socket.socket())
        with contextlib.suppress(OSError):
            taken.bind(("127.0.0.1", 8787))
            taken.listen()
        said = stack.enter_context(warnings.catch_warnings(record=True))
        warnings.simplefilter("always")
        dask = _sweep(spec_file, tmp_path / "dask", "dask-local:1")
    assert not [w for w in said if "8787" in str(w.message)], [str(w.message) for w in said]
    assert local == serial
    assert dask == serial
    lines = serial.splitlines()
    assert len(lines) == 5 and lines[0].startswith("index,seed,status,reason,ips.distance_noise_m")
    rows = [line.split(",") for line in lines[1:]]
    assert [r[0] for r in rows] == ["0", "1", "2", "3"]
    assert all(r[2] == "ok" for r in rows)
    header = lines[0].split(",")
    truth = [float(r[header.index("scale_longitudinal_true")]) for r in rows]
    drawn = [float(r[header.index("true_factors.scale.longitudinal")]) for r in rows]
    assert truth == drawn  # the twin ran with the drawn truth
    error = [abs(float(r[header.index("scale_longitudinal_error")])) for r in rows]
    assert max(error) < 0.02  # a campaign recovers the drawn factor
    turns = [float(r[header.index("procedure.rotation.turns")]) for r in rows]
    robot_s = [float(r[header.index("robot_time_s")]) for r in rows]
    assert set(turns) == {2.0, 3.0}  # a turn more, a longer rotation procedure
    assert all(
        (t1 > t2) == (s1 > s2)
        for t1, s1 in zip(turns, robot_s, strict=True)
        for t2, s2 in zip(turns, robot_s, strict=True)
        if t1 != t2
    )
    report = (tmp_path / "serial" / "report.md").read_text(encoding="utf-8")
    assert "## Against room_scale" in report
    assert "% of the runs within 0.002" in report  # the spec's target, answered per parameter
    assert (tmp_path / "serial" / "figures" / "room_scale.png").is_file()


def test_run_i_is_the_same_whatever_the_number_of_runs() -> None:
    spec = parse_sweep_spec(
        {"parameters": {"slip_sigma": {"uniform": [0.0, 0.01]}}}, "spec.yaml", ""
    )
    children = np.random.SeedSequence(5).spawn(10)
    for i in (0, 3, 9):
        draws, campaign = children[i].spawn(2)
        expected = np.random.default_rng(draws).uniform(0.0, 0.01)
        values, seed = sample_run(spec, 5, i)
        assert values["slip_sigma"] == expected
        assert seed == int(campaign.generate_state(1, np.uint64)[0] >> np.uint64(1))


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("parameters: {wheel_count: 3}", "parameters.wheel_count': unknown"),
        ("parameters: {slip_sigma: {uniform: [1, 0]}}", "low ≤ high"),
        ("parameters: {slip_sigma: {uniform: [0, 1], normal: [0, 1]}}", "exactly one"),
        ("iterations: 0", "field 'iterations'"),
        ("robots: x", "field 'robots'"),
        ("[1, 2]", "a sweep spec is a mapping"),
        ("twin: {slip_sigma: 9}", "field 'slip_sigma'"),
        ("robot: nosuchbot", "bad.yaml: robot: unknown robot preset 'nosuchbot'"),
    ],
)
def test_bad_spec_is_one_line_and_exit_2(tmp_path: Path, text: str, expected: str) -> None:
    spec = tmp_path / "bad.yaml"
    spec.write_text(text + "\n", encoding="utf-8")
    result = runner.invoke(app, ["sweep", str(spec), "--runs", "2", "--out", str(tmp_path / "o")])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and expected in lines[0] and str(spec) in lines[0], result.output
    assert not (tmp_path / "o").exists()


def test_an_impossible_run_is_an_error_row(tmp_path: Path) -> None:
    spec = tmp_path / "spec.yaml"
    spec.write_text("parameters: {room_scale: {choice: [1.0, 0.05]}}\n", encoding="utf-8")
    args = ["sweep", str(spec), "--runs", "4", "--seed", "3", "--executor", "serial"]
    result = runner.invoke(app, [*args, "--out", str(tmp_path / "o")])
    assert result.exit_code == 0, result.output
    text = (tmp_path / "o" / "sweep.csv").read_text(encoding="utf-8").splitlines()
    statuses = [line.split(",")[2] for line in text[1:]]
    assert "error" in statuses and "ok" in statuses
    assert all("room_scale 0.05: outside 0.1 to 20" in ln for ln in text[1:] if ",error," in ln)
