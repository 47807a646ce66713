"""Jobs onto an executor in chunks, a bounded number in flight (the coordinator holds no more
as the fleet grows); each chunk's rows written as it completes; the output directory, claimed
once and resumed only with the same settings.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import (
    FIRST_COMPLETED,
    BrokenExecutor,
    Executor,
    Future,
    ProcessPoolExecutor,
    wait,
)
from itertools import islice
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, Protocol, TypeVar

from omnical.errors import OmnicalError, OutputError
from omnical.fleet.table import INDEX, LOST, STATUS, ResultsTable, failure

if TYPE_CHECKING:
    from omnical.fleet.executors import ExecutorSpec

__all__ = [
    "MAX_AUTO_CHUNK",
    "SETTINGS",
    "Job",
    "auto_chunk",
    "prepare_out_dir",
    "run_chunk",
    "run_into_table",
    "run_jobs",
    "shared_path",
]

SETTINGS: Final = "settings.json"
"""What a fleet or sweep was started with, in its directory: ``--resume`` checks it."""

MAX_AUTO_CHUNK: Final = 4
"""Most campaigns a sweep's chunk holds when ``--chunk`` is left automatic: the last chunks of
a run keep one worker busy while the others wait, and four short campaigns already make Dask's
cost per task negligible (docs/DESIGN-NOTES.md, fleet). A fleet's job (a whole recording,
seconds) goes alone."""


class Job(Protocol):
    """A picklable job with its row's key."""

    @property
    def index(self) -> int:
        """Its row's key in the table."""


_J = TypeVar("_J", bound=Job)


def auto_chunk(jobs: int, workers: int) -> int:
    """Short jobs per chunk: about eight chunks per worker, at most :data:`MAX_AUTO_CHUNK`."""
    per = -(-jobs // max(1, 8 * max(1, workers)))
    return max(1, min(MAX_AUTO_CHUNK, per))


def _chunks(jobs: Sequence[_J], size: int) -> Iterator[list[_J]]:
    it = iter(jobs)
    while chunk := list(islice(it, size)):
        yield chunk


_NOT_RUN: Final = "its task was cancelled before it ran"


def _broken(err: BaseException, batch: Sequence[Job], table: Path) -> OmnicalError:
    first, last = batch[0].index, batch[-1].index
    jobs = f"job {first}" if first == last else f"jobs {first}–{last}"
    msg = (
        f"a worker process died (killed, or out of memory) with {jobs} ({failure(err)}); "
        f"the rows done are kept in {table}: --resume continues"
    )
    return OmnicalError(msg)


def run_jobs(
    executor: Executor,
    work: Callable[[Sequence[_J]], list[dict[str, str]]],
    jobs: Sequence[_J],
    table: ResultsTable,
    *,
    chunk: int,
    in_flight: int,
    failed: Callable[[_J, str], dict[str, str]],
    on_rows: Callable[[int], None] | None = None,
) -> None:
    """Run ``work`` on ``jobs`` (those not done in ``table`` already), ``chunk`` at a time, at
    most ``in_flight`` chunks submitted at once, appending each chunk's rows as it completes.

    A chunk whose task fails as a whole (the executor refused it, or Dask gave up on it after
    it killed its workers) becomes ``failed(job, reason)`` rows of status
    :data:`~omnical.fleet.table.LOST`, which ``--resume`` runs again. A stop (Ctrl-C, SIGTERM)
    cancels what has not started (a process pool's: its shutdown with ``cancel_futures=True``,
    as :func:`~omnical.fleet.executors.open_executor` does), and a process pool whose worker
    died cannot run anything more (:class:`OmnicalError`); either way the rows written stay and
    ``--resume`` does the rest.

    Raises:
        OmnicalError: the process pool broke (a worker was killed).
    """

    def lost(batch: Sequence[_J], err: Exception | str) -> list[dict[str, str]]:
        # the executor's failure, not the jobs': --resume runs them again
        reason = err if isinstance(err, str) else failure(err)
        return [{**failed(job, reason), STATUS: LOST} for job in batch]

    todo = [job for job in jobs if job.index not in table.done]
    chunks = _chunks(todo, max(1, chunk))
    pending: dict[Future[list[dict[str, str]]], list[_J]] = {}

    def fill() -> None:
        while len(pending) < max(1, in_flight):
            batch = next(chunks, None)
            if batch is None:
                return
            try:
                pending[executor.submit(work, batch)] = batch
            except BrokenExecutor as err:
                raise _broken(err, batch, table.path) from None
            except Exception as err:  # the executor refused it: its rows say so
                table.append(lost(batch, err))
                if on_rows is not None:
                    on_rows(len(batch))

    try:
        fill()
        while pending:
            done, _ = wait(list(pending), return_when=FIRST_COMPLETED)
            for future in done:
                batch = pending.pop(future)
                try:
                    rows = future.result()
                except BrokenExecutor as err:  # the pool is gone: no job can run any more
                    raise _broken(err, batch, table.path) from None
                except Exception as err:  # e.g. Dask's KilledWorker, after its retries
                    rows = lost(batch, err)
                given = {row[INDEX] for row in rows}
                # a chunk whose task was cancelled stops between its jobs: none goes missing
                rows += lost([j for j in batch if str(j.index) not in given], _NOT_RUN)
                table.append(rows)
                if on_rows is not None:
                    on_rows(len(rows))
            fill()
    finally:
        # a stop: what has not started is cancelled; a process pool's by its own shutdown
        # (open_executor), in its manager thread. Cancelled here, a pool whose forkserver or
        # worker died first (SIGTERM to the process group: CI) had its manager thread fail
        # them again: "Exception in thread ... InvalidStateError: CANCELLED" on Python 3.11
        if not isinstance(executor, ProcessPoolExecutor):
            for future in pending:
                future.cancel()


def run_chunk(run_one: Callable[[_J], dict[str, str]], jobs: Sequence[_J]) -> list[dict[str, str]]:
    """The rows of a chunk of jobs, run one after another in the worker; none started once
    the task is cancelled (a stop: :func:`~omnical.fleet.executors.task_wanted`)."""
    from omnical.fleet.executors import task_wanted

    rows: list[dict[str, str]] = []
    for job in jobs:
        if rows and not task_wanted():
            break
        rows.append(run_one(job))
    return rows


def run_into_table(
    executor: ExecutorSpec,
    work: Callable[[Sequence[_J]], list[dict[str, str]]],
    jobs: Sequence[_J],
    table: tuple[Path, list[str]],
    *,
    claim: Callable[[], object],
    resume: bool,
    chunk: int,
    failed: Callable[[_J, str], dict[str, str]],
    on_start: Callable[[int, int], None] | None = None,
    on_rows: Callable[[int], None] | None = None,
    on_stop: Callable[[Path, int], None] | None = None,
) -> tuple[list[dict[str, str]], int]:
    """:func:`run_jobs` on ``executor`` into the table (path, header), the directory claimed
    once the executor is had; its rows in index order and how many a resume found done.
    ``chunk`` 0: :func:`auto_chunk`; the callbacks: :func:`~omnical.fleet.recordings.run_fleet`'s.
    """
    from omnical.fleet.executors import open_executor

    with open_executor(executor) as pool:  # no scheduler: nothing written
        claim()
        results = ResultsTable(table[0], table[1], resume=resume)
        done_before = len(results.done)
        if on_start is not None:
            on_start(len(jobs), done_before)
        workers = executor.workers or 2
        try:
            run_jobs(
                pool,
                work,
                jobs,
                results,
                chunk=chunk or auto_chunk(len(jobs) - done_before, workers),
                in_flight=2 * workers,
                failed=failed,
                on_rows=on_rows,
            )
        except BaseException as stop:
            kept = results.close(sort=False)
            if on_stop is not None and isinstance(stop, KeyboardInterrupt):
                on_stop(results.path, len(kept))
            raise
    return results.close(sort=True), done_before


def shared_path(path: Path) -> Path:
    """``path`` absolute, its folder resolved (``..`` as the system reads it) and its own name
    kept (a link's): the same for a worker elsewhere and for a resume from another folder."""
    absolute = path.absolute()
    if absolute.name in ("", ".", ".."):
        return absolute.resolve()
    return absolute.parent.resolve() / absolute.name


def prepare_out_dir(
    out: Path,
    settings: Mapping[str, Any],
    table_name: str,
    *,
    resume: bool,
    overwrite: bool,
    check_only: bool = False,
) -> None:
    """Make ``out`` ready for a run with ``settings``: a new directory, an earlier omnical one
    (``--overwrite``), or the same run to continue (``--resume``: the settings must match).
    ``check_only``: say whether it can be, writing nothing (before an executor starts).

    Raises:
        OutputError: a file or someone else's directory is there, an earlier run without
            ``--overwrite`` / ``--resume``, or ``--resume`` with other settings.
    """
    import shutil

    from omnical.reports.outputs import MARKER, is_marked

    text = json.dumps(settings, indent=1, sort_keys=True) + "\n"
    where = out / SETTINGS
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise OutputError(f"{out}: not a directory; give a directory for the results")
    if out.is_dir() and any(out.iterdir()):
        if not is_marked(out):
            raise OutputError(f"{out}: holds files omnical did not write; give another --out")
        if resume:
            if not where.exists() or not (out / table_name).exists():
                raise OutputError(f"{out}: nothing to resume (no {SETTINGS} or {table_name})")
            found = where.read_text(encoding="utf-8")
            if found != text:
                msg = (
                    f"{out}: --resume with other settings than the run there was started with: "
                    f"{_difference(found, settings)} (see {where}); give the same ones, or "
                    "--overwrite to start again"
                )
                raise OutputError(msg)
            return
        if check_only and overwrite:
            return
        if not overwrite:
            msg = f"{out}: an earlier run is there; --resume continues it, --overwrite replaces it"
            raise OutputError(msg)
        shutil.rmtree(out)
    elif resume:
        raise OutputError(f"{out}: nothing to resume there")
    if check_only:
        return
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / MARKER).write_text("written by omnical fleet/sweep\n", encoding="utf-8")
        where.write_text(text, encoding="utf-8")
    except OSError as err:
        raise OutputError(f"{out}: cannot write: {err.strerror or err}") from None


def _difference(found: str, settings: Mapping[str, Any]) -> str:
    """The first setting that differs between a run's ``settings.json`` (``found``) and
    ``settings``: ``KEY: OLD then, NEW now`` (a text's first differing line; a list's first
    differing item or its length)."""
    try:
        old: Any = json.loads(found)
    except ValueError:
        return f"{SETTINGS} is not readable JSON"
    new: Any = json.loads(json.dumps(settings))  # as written: tuples are lists
    return _first_difference(old, new, "") or "the same settings written otherwise"


def _first_difference(old: Any, new: Any, key: str) -> str:
    """``KEY: OLD then, NEW now`` for the first place ``old`` and ``new`` differ, "" if none."""

    def said(value: Any) -> str:
        text = json.dumps(value, ensure_ascii=False)
        return text if len(text) <= 80 else text[:77] + "..."

    def at(name: str) -> str:
        return f"{key}.{name}" if key else name

    if isinstance(old, dict) and isinstance(new, dict):
        for name in sorted(set(old) | set(new)):
            if name not in old:
                return f"{at(name)}: not set then, {said(new[name])} now"
            if name not in new:
                return f"{at(name)}: {said(old[name])} then, not set now"
            if (why := _first_difference(old[name], new[name], at(name))) != "":
                return why
        return ""
    if isinstance(old, list) and isinstance(new, list):
        for i, (a, b) in enumerate(zip(old, new, strict=False)):
            if (why := _first_difference(a, b, f"{key}[{i}]")) != "":
                return why
        if len(old) != len(new):
            return f"{key}: {len(old)} then, {len(new)} now"
        return ""
    if isinstance(old, str) and isinstance(new, str) and "\n" in old + new:
        lines = zip(old.splitlines(), new.splitlines(), strict=False)
        for i, (a, b) in enumerate(lines, start=1):
            if a != b:
                return f"{key} line {i}: {said(a)} then, {said(b)} now"
        return f"{key}: {len(old.splitlines())} lines then, {len(new.splitlines())} now"
    if old != new:
        return f"{key}: {said(old)} then, {said(new)} now"
    return ""
