"""``omnical fleet`` and ``sweep`` outputs and inputs, found by a new user: ``--overwrite`` keeps
the earlier output until the new run is complete (stopped or failed: the new rows beside it in
``DIR.partial``, which ``--resume --overwrite`` continues); ``--previous``, the file options and
the recordings checked before anything is written; a sweep with no result exits 3."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import pytest
from typer.testing import CliRunner

from omnical.cli.main import app
from omnical.fleet import recordings, sweep
from omnical.fleet.jobs import FleetJob, fleet_header
from omnical.fleet.sweep import SweepJob
from omnical.fleet.table import read_rows

runner = CliRunner()

_Chunk = Callable[[Sequence[FleetJob]], list[dict[str, str]]]


def _bags(folder: Path, count: int) -> list[Path]:
    """``count`` files standing for recordings (the fake jobs below never read them)."""
    bags = []
    for name in "abcdef"[:count]:
        bags.append(folder / f"{name}.mcap")
        bags[-1].write_bytes(b"")
    return bags


def _fleet_chunk(made: str, stop_at: int = -1, error: BaseException | None = None) -> _Chunk:
    """A fleet's chunk that writes ``made`` in each recording's folder and an ok row, and
    raises ``error`` at job ``stop_at`` (as a Ctrl-C there, or a failure)."""

    def chunk(jobs: Sequence[FleetJob]) -> list[dict[str, str]]:
        rows = []
        for job in jobs:
            if job.index == stop_at and error is not None:
                raise error
            Path(job.out_dir).mkdir(parents=True, exist_ok=True)
            (Path(job.out_dir) / "made.txt").write_text(made, encoding="utf-8")
            row = {"index": str(job.index), "name": job.name, "recording": job.recording}
            rows.append({**row, "status": "ok", "reason": "", "usable_fraction": "1.0"})
        return rows

    return chunk


def _files(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _hidden(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if p.name.startswith(".")]


def _locate(bags: Sequence[Path], out: Path, *extra: str) -> tuple[int, str]:
    args = ["fleet", "locate", *map(str, bags), "--executor", "serial", "--out", str(out)]
    result = runner.invoke(app, [*args, *extra])
    return result.exit_code, result.output


def test_a_stopped_overwrite_keeps_the_earlier_fleet_and_resume_overwrite_finishes_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Found by a new user: Ctrl-C during ``--overwrite`` left 2 rows where 6 had been, the
    earlier report, figures and recordings gone, no ``.partial``."""
    bags = _bags(tmp_path, 6)
    out = tmp_path / "fle1"
    monkeypatch.setattr(recordings, "run_fleet_chunk", _fleet_chunk("first"))
    assert _locate(bags, out)[0] == 0
    before = _files(out)
    assert "report.md" in before and len(read_rows(out / "fleet.csv")[1]) == 6

    # the serial executor's Ctrl-C at the 6th job: the 5 done before it written (there were
    # 4 when it ran 4 jobs before writing their rows: the 5th's was lost)
    stop = _fleet_chunk("second", stop_at=5, error=KeyboardInterrupt())
    monkeypatch.setattr(recordings, "run_fleet_chunk", stop)
    status, said = _locate(bags, out, "--overwrite")
    assert status == 130, said
    assert _files(out) == before  # the earlier output exactly as it was
    partial = tmp_path / "fle1.partial"
    assert sorted(r["index"] for r in read_rows(partial / "fleet.csv")[1]) == list("01234")
    line = (
        f"omnical: 5 rows kept in {partial / 'fleet.csv'}; the earlier {out} was not touched; "
        "--resume --overwrite continues them, then replaces it"
    )
    assert said.splitlines()[-2:] == [line, "omnical: interrupted"]
    assert _hidden(tmp_path) == []  # no staging left

    monkeypatch.setattr(recordings, "run_fleet_chunk", _fleet_chunk("second"))
    status, said = _locate(bags, out, "--resume")  # out itself: the partial left, and said
    assert status == 0 and "(6 done before the resume)" in said, said
    assert f"the stopped --overwrite run in {partial} is left as it is" in said
    assert _files(out)["recordings/a/made.txt"] == b"first" and partial.is_dir()

    status, said = _locate(bags, out, "--resume", "--overwrite")
    assert status == 0 and "6 ok, 0 error (5 done before the resume)" in said, said
    assert not partial.exists() and _hidden(tmp_path) == []
    made = {p.parent.name: p.read_text() for p in (out / "recordings").glob("*/made.txt")}
    assert made == dict.fromkeys("abcdef", "second")  # the new run, replacing the earlier
    assert len(read_rows(out / "fleet.csv")[1]) == 6 and (out / "report.md").is_file()


@pytest.mark.parametrize("failure", ["worker", "report"])
def test_a_failed_overwrite_keeps_the_earlier_fleet(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, failure: str
) -> None:
    """A failure after rows were written (a worker process killed; the report not written):
    one line saying where the new rows are, the earlier output untouched."""
    from omnical.errors import RecordingError
    from omnical.reports import fleet as report

    bags = _bags(tmp_path, 6)
    out = tmp_path / "o"
    monkeypatch.setattr(recordings, "run_fleet_chunk", _fleet_chunk("first"))
    assert _locate(bags, out)[0] == 0
    before = _files(out)
    partial = tmp_path / "o.partial"
    if failure == "worker":
        died = _fleet_chunk("second", stop_at=5, error=BrokenProcessPool("killed"))
        monkeypatch.setattr(recordings, "run_fleet_chunk", died)
        said = f"the rows done are kept in {partial / 'fleet.csv'}: the earlier {out} was not "
    else:
        monkeypatch.setattr(recordings, "run_fleet_chunk", _fleet_chunk("second"))

        def refused(*args: object, **kwargs: object) -> Path:
            raise RecordingError("report.md: cannot write report: No space left on device")

        monkeypatch.setattr(report, "write_fleet_report", refused)
        said = f"what was written is kept in {partial}: the earlier {out} was not touched"
    status, output = _locate(bags, out, "--overwrite")
    assert status == 2, output
    (line,) = [ln for ln in output.splitlines() if ln.startswith("omnical:")]
    assert said in line and line.endswith("--resume --overwrite continues them, then replaces it")
    assert _files(out) == before
    kept = {r["index"] for r in read_rows(partial / "fleet.csv")[1]}
    if failure == "worker":  # the chunks done before the dead one's (4 in flight, then 4 or 5)
        assert {"0", "1", "2", "3"} <= kept and "5" not in kept
    else:
        assert kept == {"0", "1", "2", "3", "4", "5"}
    assert _hidden(tmp_path) == []


def _sweep_chunk(stop_at: int) -> Callable[[Sequence[SweepJob]], list[dict[str, str]]]:
    def chunk(jobs: Sequence[SweepJob]) -> list[dict[str, str]]:
        rows = []
        for job in jobs:
            if job.index == stop_at:
                raise KeyboardInterrupt
            rows.append({"index": str(job.index), "seed": "1", "status": "ok", "reason": "",
                         "max_scale_error": "0.0005"})  # fmt: skip
        return rows

    return chunk


def test_a_stopped_sweep_overwrite_keeps_the_earlier_sweep(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Found by a new user: a sweep of 40 rows was 12 after a stopped ``--overwrite``."""
    spec = tmp_path / "spec.yaml"
    spec.write_text("twin: default\n", encoding="utf-8")
    out = tmp_path / "sw3"
    args = ["sweep", str(spec), "--runs", "8", "--seed", "7", "--executor", "serial"]
    monkeypatch.setattr(sweep, "run_sweep_chunk", _sweep_chunk(-1))
    first = runner.invoke(app, [*args, "--out", str(out), "--chunk", "1"])
    assert first.exit_code == 0, first.output
    before = _files(out)
    monkeypatch.setattr(sweep, "run_sweep_chunk", _sweep_chunk(6))
    stopped = runner.invoke(app, [*args, "--out", str(out), "--chunk", "1", "--overwrite"])
    assert stopped.exit_code == 130, stopped.output
    assert _files(out) == before
    partial = tmp_path / "sw3.partial"
    assert len(read_rows(partial / "sweep.csv")[1]) == 6  # each of the 6 done was written
    assert f"omnical: 6 rows kept in {partial / 'sweep.csv'}; the earlier {out} was" in (
        stopped.output
    )


def _calibrate_table(rows: Sequence[str]) -> str:
    return ",".join(fleet_header("calibrate")) + "\n" + "".join(f"{r}\n" for r in rows)


_OK = "0,a,/x/a.mcap,ok,,procedures," + ",".join(["1.0", "0.01"] * 7) + ",,IPS,"


_EVALUATE = ",".join(fleet_header("evaluate")) + "\n0,a,/x/a.mcap,ok,\n"
_NOT_CALIBRATE = "not a fleet calibrate table"
_IN_COMMON = "no recording in common with this fleet"


@pytest.mark.parametrize(
    ("table", "said"),
    [
        (_EVALUATE, f"{_NOT_CALIBRATE} (a fleet evaluate table); give an earlier fleet calibrate"),
        ("", f"{_NOT_CALIBRATE} (empty)"),
        ("index,name,value\n0,a,1\n", f"{_NOT_CALIBRATE} (no status column)"),
        (_calibrate_table([_OK, "1,b,/x/b.mcap,ok"]), "malformed at line 3: 4 fields, the header"),
        (_calibrate_table([_OK.replace(",1.0,", ",one,", 1)]), "line 2: scale_longitudinal 'one'"),
        (_calibrate_table([_OK.replace(",ok,", ",fine,")]), "malformed at line 2: status 'fine'"),
        (_calibrate_table([_OK.replace(",a,", ",z,")]), f"{_IN_COMMON} (there: z; here: a, b): "),
        (_calibrate_table([_OK.replace(",ok,", ",error,")]), f"{_IN_COMMON} (there: no ok row;"),
    ],
)
def test_a_previous_table_that_compares_nothing_is_one_line_before_any_job(
    tmp_path: Path, table: str, said: str
) -> None:
    """Found by a new user: ``--previous`` naming an evaluate table, a malformed one or one
    without these recordings exited 0, the report claiming alerts against it."""
    previous = tmp_path / "previous"
    previous.mkdir()
    (previous / "fleet.csv").write_text(table, encoding="utf-8")
    out = tmp_path / "o"
    bags = _bags(tmp_path, 2)
    args = ["fleet", "calibrate", *map(str, bags), "--previous", str(previous), "--out", str(out)]
    result = runner.invoke(app, [*args, "--executor", "serial"])
    assert result.exit_code == 2, result.output
    (line,) = [ln for ln in result.output.splitlines() if ln.startswith("omnical:")]
    assert line.startswith(f"omnical: error: --previous {previous / 'fleet.csv'}: "), line
    assert said in line, line
    assert not out.exists()


_NAN_FACTORS = """\
scale: {longitudinal: 1.0, lateral: .nan, rotational: 1.0}
crosstalk_rad_per_m: {forward: 0.0, reverse: 0.0, left: 0.0, right: 0.0}
"""


@pytest.mark.parametrize(
    ("command", "option", "name", "text", "said"),
    [
        ("evaluate", "--factors", "nan2.yaml", _NAN_FACTORS,
         "field 'scale.lateral': nan is not a plausible scaling"),
        ("calibrate", "--installed", "nan2.yaml", _NAN_FACTORS, "field 'scale.lateral'"),
        ("locate", "--beacons", "beacons.yaml", "beacons: 5\n", "beacons"),
        ("evaluate", "--reference-file", "ref.csv", "t_s,x_m,y_m\n0,0,0\n1,1,nan\n",
         "line 3: y_m: not a finite number"),
        ("evaluate", "--reference", "ref.tum", "0 0 0 0 0 0 0 1\n1 1 1\n",
         "line 2: a TUM line is 'timestamp tx ty tz qx qy qz qw'"),
    ],
)  # fmt: skip
def test_a_bad_file_option_is_one_line_before_anything_is_written(
    tmp_path: Path, command: str, option: str, name: str, text: str, said: str
) -> None:
    """Found by a new user: ``--factors`` with a NaN made DIR with an error row per recording
    and exit 3; the options are "checked before any job starts"."""
    bad = tmp_path / name
    bad.write_text(text, encoding="utf-8")
    out = tmp_path / "flc7"
    args = ["fleet", command, *map(str, _bags(tmp_path, 2)), option, name, "--out", str(out)]
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(tmp_path)  # the file as a user names it, here
        result = runner.invoke(app, [*args, "--executor", "serial"])
    assert result.exit_code == 2, result.output
    (line,) = [ln for ln in result.output.splitlines() if ln.startswith("omnical:")]
    assert line.startswith(f"omnical: error: {option} {bad}: ") and said in line, line
    assert not out.exists()


def test_a_reference_file_in_bag_time_is_left_to_each_recording(tmp_path: Path) -> None:
    """Absolute times are checked against each recording's start (its job): not refused up
    front for not starting at 0."""
    reference = tmp_path / "ref.csv"
    reference.write_text("t_s,x_m,y_m\n1700000000.0,0,0\n1700000001.0,1,1\n", encoding="utf-8")
    out = tmp_path / "o"
    args = ["fleet", "evaluate", *map(str, _bags(tmp_path, 1)), "--reference-file", str(reference)]
    result = runner.invoke(app, [*args, "--executor", "serial", "--out", str(out)])
    assert result.exit_code == 3, result.output  # the (empty) recording's own error row
    assert "cannot read bag" in read_rows(out / "fleet.csv")[1][0]["reason"]


def test_a_recording_that_is_not_there_is_one_line_before_anything_is_written(
    tmp_path: Path,
) -> None:
    """Found by a new user: ``fleet locate nosuchbag`` made DIR with an error row, exit 3."""
    out = tmp_path / "fly"
    there = _bags(tmp_path, 1)[0]
    missing = tmp_path / "nosuchbag"
    result = runner.invoke(app, ["fleet", "locate", str(there), str(missing), "--out", str(out)])
    assert result.exit_code == 2, result.output
    assert result.output.splitlines() == [f"omnical: error: {missing}: no such bag"]
    assert not out.exists()
    # RUN.mcap names the ROS 2 bag folder RUN/, as for the single commands: not refused
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "metadata.yaml").write_text("x: 1\n", encoding="utf-8")
    result = runner.invoke(app, ["fleet", "locate", str(tmp_path / "run.mcap"), "--out", str(out),
                                 "--executor", "serial"])  # fmt: skip
    assert result.exit_code == 3, result.output  # its row: a bag that cannot be read


def test_a_sweep_where_every_run_failed_exits_3(tmp_path: Path) -> None:
    """Found by a new user: ``2 campaigns, 0 ok, 2 error`` exited 0, where such a fleet exits
    3. The table and report are written, then exit 3."""
    spec = tmp_path / "spec.yaml"
    spec.write_text("parameters: {room_scale: 0.05}\n", encoding="utf-8")
    out = tmp_path / "o"
    args = ["sweep", str(spec), "--runs", "2", "--executor", "serial", "--out", str(out)]
    result = runner.invoke(app, args)
    assert result.exit_code == 3, result.output
    assert "2 campaigns, 0 ok, 2 error" in result.output
    assert "2 runs: error: room_scale 0.05: outside 0.1 to 20" in result.output
    assert result.output.rstrip().endswith(
        f"omnical: no campaign gave a result (every run failed: see {out / 'report.md'})"
    )
    assert [r["status"] for r in read_rows(out / "sweep.csv")[1]] == ["error", "error"]
    assert (out / "report.md").is_file()
