"""The runner: rows as chunks complete, a job's error a row, a dead worker a one-line stop that
keeps the rows done, and a resume that redoes none of them (issue 27)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest

from omnical.errors import OmnicalError
from omnical.fleet.executors import open_executor, parse_executor
from omnical.fleet.runner import run_jobs
from omnical.fleet.table import ResultsTable, read_rows

HEADER = ["index", "status", "reason", "square"]


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
