"""The runner: rows as chunks complete, a job's error a row, a dead worker a one-line stop that
keeps the rows done, a resume that redoes none of them (issue 27) but the executor's failures."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ParamSpec, TypeVar

import pytest

from omnical.errors import OmnicalError
from omnical.fleet.executors import open_executor, parse_executor
from omnical.fleet.runner import run_jobs
from omnical.fleet.table import LOST, ResultsTable, read_rows

HEADER = ["index", "status", "reason", "square"]
_P = ParamSpec("_P")
_T = TypeVar("_T")


@dataclass(frozen=True)
class _Job:
    index: int
    die: bool = False


def _work(jobs: Sequence[_Job]) -> list[dict[str, str]]:
    rows = []
    for job in jobs:
        if job.die:
            os._exit(1)  # the worker process dies, as when it is killed
        if job.index == 3:
            rows.append({"index": "3", "status": "error", "reason": "three is refused"})
        else:
            rows.append({"index": str(job.index), "status": "ok", "square": str(job.index**2)})
    return rows


def _failed(job: _Job, reason: str) -> dict[str, str]:
    return {"index": str(job.index), "status": "error", "reason": reason}


def _run(table: ResultsTable, jobs: list[_Job], executor: str) -> None:
    with open_executor(parse_executor(executor)) as pool:
        run_jobs(pool, _work, jobs, table, chunk=2, in_flight=2, failed=_failed)


def test_a_dead_worker_stops_the_run_and_resume_finishes_it(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    table = ResultsTable(path, HEADER, resume=False)
    jobs = [_Job(i, die=(i == 6)) for i in range(10)]
    with pytest.raises(OmnicalError, match=r"worker process died .* job.* --resume continues"):
        _run(table, jobs, "local:1")
    table.close(sort=False)
    _, kept = read_rows(path)
    done = {int(r["index"]) for r in kept}
    assert {0, 1, 2, 3} <= done and 6 not in done  # collected before the chunk of 6 was sent

    again = ResultsTable(path, HEADER, resume=True)
    assert again.done == done
    seen: list[int] = []

    def counting(jobs: Sequence[_Job]) -> list[dict[str, str]]:
        seen.extend(j.index for j in jobs)
        return _work(jobs)

    with open_executor(parse_executor("serial")) as pool:
        run_jobs(
            pool,
            counting,
            [_Job(i) for i in range(10)],
            again,
            chunk=2,
            in_flight=2,
            failed=_failed,
        )
    rows = again.close(sort=True)
    assert sorted(seen) == sorted(set(range(10)) - done)  # nothing done is redone
    assert [r["index"] for r in rows] == [str(i) for i in range(10)]
    assert rows[3]["status"] == "error" and rows[3]["reason"] == "three is refused"
    assert rows[9]["square"] == "81"


def test_a_cut_last_line_is_dropped_on_resume(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    path.write_text("index,status,reason,square\n0,ok,,0\n1,ok,,1\n2,o", encoding="utf-8")
    table = ResultsTable(path, HEADER, resume=True)
    assert table.done == {0, 1}
    table.close(sort=False)
    assert path.read_text(encoding="utf-8") == "index,status,reason,square\n0,ok,,0\n1,ok,,1\n"


def test_a_table_of_other_columns_is_not_resumed(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    path.write_text("index,other\n0,x\n", encoding="utf-8")
    with pytest.raises(OmnicalError, match="columns are not this command's"):
        ResultsTable(path, HEADER, resume=True)
    assert path.read_text(encoding="utf-8") == "index,other\n0,x\n"


class _Flaky(Executor):
    """Serial, but it refuses to submit a chunk holding job 1 and loses the one holding job 4
    (as Dask's KilledWorker): the executor's failures, not the jobs'."""

    def submit(self, fn: Callable[_P, _T], /, *args: _P.args, **kwargs: _P.kwargs) -> Future[_T]:
        indices = {job.index for job in args[0]}  # type: ignore[attr-defined]
        if 1 in indices:
            raise RuntimeError("the scheduler refused the task")
        future: Future[_T] = Future()
        if 4 in indices:
            future.set_exception(RuntimeError("KilledWorker: the task killed 3 workers"))
        else:
            future.set_result(fn(*args, **kwargs))
        return future


def test_the_executors_failures_are_lost_rows_resume_runs_again(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    table = ResultsTable(path, HEADER, resume=False)
    jobs = [_Job(i) for i in range(6)]
    run_jobs(_Flaky(), _work, jobs, table, chunk=1, in_flight=2, failed=_failed)
    rows = {int(r["index"]): r for r in table.close(sort=True)}
    assert rows[1]["status"] == LOST and rows[1]["reason"].endswith("scheduler refused the task")
    assert rows[4]["status"] == LOST and "KilledWorker" in rows[4]["reason"]
    assert rows[3]["status"] == "error"  # the job's own failure: done

    again = ResultsTable(path, HEADER, resume=True)
    assert again.done == {0, 2, 3, 5}
    with open_executor(parse_executor("serial")) as pool:
        run_jobs(pool, _work, jobs, again, chunk=1, in_flight=2, failed=_failed)
    rows_after = again.close(sort=True)
    assert [r["index"] for r in rows_after] == [str(i) for i in range(6)]  # one row each
    assert [r["status"] for r in rows_after] == ["ok", "ok", "ok", "error", "ok", "ok"]


def test_the_summary_line_counts_lost_rows_apart() -> None:
    from omnical.cli.fleet import failures

    assert failures([{"status": "error"}]) == "1 error"
    lost = failures([{"status": "error"}, {"status": LOST}, {"status": LOST}])
    assert lost == "1 error, 2 lost (the executor's: --resume runs them again)"


def test_the_reports_show_lost_rows_as_lost_with_the_resume(tmp_path: Path) -> None:
    from omnical.reports import fleet as report

    assert report.LOST == LOST  # the report layer's copy of the status
    rows = [
        {"index": "0", "name": "a", "status": "ok", "reason": "", "usable_fraction": "0.9"},
        {"index": "1", "name": "b", "status": "error", "reason": "b.mcap: cannot read bag"},
        {"index": "2", "name": "c", "status": LOST, "reason": "KilledWorker: 3 workers died"},
    ]
    header = ["index", "name", "recording", "status", "reason", "usable_fraction"]
    text = report.write_fleet_report(tmp_path / "f", "locate", header, rows).read_text("utf-8")
    assert "3 recordings: 1 ok, 1 error, 1 lost (" in text and "re-run with --resume)." in text
    assert "| c | lost | KilledWorker: 3 workers died (re-run with --resume) |" in text
    assert "| b | error | b.mcap: cannot read bag |" in text

    runs = [{**r, "x": "1", "err": "0.001"} for r in rows[:1]]
    runs += [{"index": "1", "status": LOST, "reason": "refused", "x": "", "err": ""}]
    sweep = report.write_sweep_report(
        tmp_path / "s", runs, ["x"], error="err", error_label="e", target=0.01, spec_text="x: 1"
    ).read_text("utf-8")
    assert "2 runs: 1 ok, 0 error, 1 lost (" in sweep
    assert "| lost | refused (re-run with --resume) | 1 |" in sweep


def test_resume_with_other_settings_names_the_first_that_differs(tmp_path: Path) -> None:
    from omnical.errors import OutputError
    from omnical.fleet.runner import claim_out_dir, open_place

    out = tmp_path / "run"
    started: dict[str, Any] = {"spec": "a: 1\nb: 2\n", "runs": 4, "options": {"method": "lsq"}}
    assert open_place(claim_out_dir(out, started, "t.csv", resume=False, overwrite=False)) == out
    (out / "t.csv").write_text("index\n", encoding="utf-8")
    changes: list[tuple[dict[str, Any], str]] = [
        ({"spec": "a: 1\nb: 3\n"}, 'spec line 2: "b: 2" then, "b: 3" now'),
        ({"runs": 5}, "runs: 4 then, 5 now"),
        ({"options": {"method": "grid"}}, 'options.method: "lsq" then, "grid" now'),
        ({"options": {"method": "lsq", "plot": True}}, "options.plot: not set then, true now"),
    ]
    for changed, said in changes:
        with pytest.raises(OutputError) as info:
            claim_out_dir(out, {**started, **changed}, "t.csv", resume=True, overwrite=False)
        assert said in str(info.value)
    again = claim_out_dir(out, started, "t.csv", resume=True, overwrite=False)  # the same
    assert (again.mode, open_place(again)) == ("resume", out)


def _first_only(jobs: Sequence[_Job]) -> list[dict[str, str]]:
    return _work(jobs[:1])  # as a chunk whose task was cancelled after its first job


def test_jobs_a_cancelled_chunk_did_not_start_are_lost_rows(tmp_path: Path) -> None:
    table = ResultsTable(tmp_path / "t.csv", HEADER, resume=False)
    with open_executor(parse_executor("serial")) as pool:
        run_jobs(pool, _first_only, [_Job(i) for i in range(4)], table, chunk=2, in_flight=1,
                 failed=_failed)  # fmt: skip
    rows = table.close(sort=True)
    assert [r["status"] for r in rows] == ["ok", LOST, "ok", LOST]
    assert rows[1]["reason"] == "its task was cancelled before it ran"


def test_the_report_names_the_reference_the_rows_were_measured_against(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Review: the evaluate figure said "RMSE against /ground_truth" whatever the reference."""
    from omnical.fleet import jobs
    from omnical.reports import fleet as report
    from omnical.reports.figures import fleet as figures

    assert (report.REFERENCE, report.REFERENCE_TIMES) == (jobs.REFERENCE, jobs.REFERENCE_TIMES)
    labels: list[str] = []
    real = figures.plot_column_per_recording

    def plot(rows: Any, columns: Any, ylabel: str, path: Path) -> Path:
        labels.append(ylabel)
        return real(rows, columns, ylabel, path)

    monkeypatch.setattr(figures, "plot_column_per_recording", plot)
    header = jobs.fleet_header("evaluate")
    base = {"index": "0", "name": "a", "status": "ok", "reason": "", "odometry_rmse_m": "0.1"}
    times = "absolute bag time (t_ns)"
    one = [{**base, "reference": "/data/a.tum", "reference_times": times}]
    text = report.write_fleet_report(
        tmp_path / "one", "evaluate", header, one, reference="{parent}/{stem}.tum"
    ).read_text("utf-8")
    assert f"Every recording against /data/a.tum; its times: {times}." in text
    assert labels.pop() == "RMSE against /data/a.tum, m"
    two = [*one, {**base, "index": "1", "name": "b", "reference": "/data/b.tum",
                  "reference_times": times}]  # fmt: skip
    text = report.write_fleet_report(
        tmp_path / "two", "evaluate", header, two, reference="{parent}/{stem}.tum"
    ).read_text("utf-8")
    assert f"| b | /data/b.tum | {times} |" in text
    assert "Each recording's reference (given: {parent}/{stem}.tum)" in text
    assert labels.pop() == "RMSE against each recording's {parent}/{stem}.tum, m"
    truth = [{**base, "reference": "/ground_truth", "reference_times": ""}]
    text = report.write_fleet_report(
        tmp_path / "truth", "evaluate", header, truth, reference="/ground_truth"
    ).read_text("utf-8")
    assert "Every recording against /ground_truth." in text
    assert labels.pop() == "RMSE against /ground_truth, m"


class _Held:
    """An executor as the runner sees it whose jobs never start: the first submitted
    completes at once, the others wait."""

    def __init__(self) -> None:
        self.futures: list[Future[Any]] = []

    def submit(self, fn: Callable[_P, _T], /, *args: _P.args, **kwargs: _P.kwargs) -> Future[_T]:
        future: Future[_T] = Future()
        if not self.futures:
            future.set_result(fn(*args, **kwargs))
        self.futures.append(future)
        return future


class _HeldPool(_Held, ProcessPoolExecutor):
    def __init__(self) -> None:
        ProcessPoolExecutor.__init__(self, max_workers=1)  # no process until a real submit
        _Held.__init__(self)


class _HeldOther(_Held, Executor):
    pass


class _StopError(Exception):
    pass


@pytest.mark.parametrize("pool", [_HeldPool, _HeldOther])
def test_a_stop_leaves_a_process_pools_waiting_jobs_to_its_shutdown(
    tmp_path: Path, pool: type[_Held]
) -> None:
    """A stop cancels the jobs not started; a process pool's in its own shutdown (open_executor,
    in its manager thread). Cancelled by the runner, they were failed again by that thread when
    it saw the forkserver or a worker die first (a SIGTERM to the process group): a traceback
    after "omnical: terminated" (CI, Python 3.11)."""
    held = pool()

    def stop(_: int) -> None:
        raise _StopError

    table = ResultsTable(tmp_path / "t.csv", HEADER, resume=False)
    with pytest.raises(_StopError):
        run_jobs(held, _work, [_Job(i) for i in range(4)], table, chunk=1, in_flight=3,  # type: ignore[arg-type]
                 failed=_failed, on_rows=stop)  # fmt: skip
    waiting = held.futures[1:]
    assert len(waiting) == 2
    if isinstance(held, ProcessPoolExecutor):
        assert not any(f.cancelled() for f in waiting)  # its shutdown's to cancel
        held.shutdown(wait=True, cancel_futures=True)
    else:
        assert all(f.cancelled() for f in waiting)


def test_the_per_recording_figure_leaves_out_a_column_without_values(tmp_path: Path) -> None:
    # UWB-only bags: the legend named odometry, IPS and smoothed bars that were not there
    import matplotlib.pyplot as plt

    from omnical.reports.figures import fleet as figures

    drawn: list[list[str]] = []
    real = plt.Axes.legend

    def legend(ax: Any, *args: Any, **kwargs: Any) -> Any:
        drawn.append(list(ax.get_legend_handles_labels()[1]))
        return real(ax, *args, **kwargs)

    rows = [{"name": n, "odometry_rmse_m": "", "multilateration_rmse_m": v}
            for n, v in (("a", "0.06"), ("b", "0.14"))]  # fmt: skip
    columns = ["odometry_rmse_m", "multilateration_rmse_m"]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(plt.Axes, "legend", legend)
        figures.plot_column_per_recording(rows, columns, "RMSE, m", tmp_path / "a.png")
        empty = [{**r, "multilateration_rmse_m": ""} for r in rows]  # nothing at all: all kept
        figures.plot_column_per_recording(empty, columns, "RMSE, m", tmp_path / "b.png")
    assert drawn == [["multilateration_rmse_m"], columns]
