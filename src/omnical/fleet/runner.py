"""Jobs onto an executor in chunks, a bounded number in flight (the coordinator holds no more
as the fleet grows); each chunk's rows written as it completes; the output directory, claimed
once, resumed only with the same settings, an earlier one replaced only by a complete run.
"""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import (
    FIRST_COMPLETED,
    BrokenExecutor,
    Executor,
    Future,
    ProcessPoolExecutor,
    wait,
)
from contextlib import suppress
from dataclasses import dataclass
from itertools import islice
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, Literal, Protocol, TypeAlias, TypeVar

from omnical.errors import OmnicalError, OutputError
from omnical.fleet.table import INDEX, LOST, STATUS, ResultsTable, failure, read_rows

if TYPE_CHECKING:
    from omnical.fleet.executors import ExecutorSpec

__all__ = [
    "MAX_AUTO_CHUNK",
    "SETTINGS",
    "Job",
    "OutClaim",
    "auto_chunk",
    "claim_out_dir",
    "open_place",
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


def _broken(err: BaseException, batch: Sequence[Job], table: Path, continues: str) -> OmnicalError:
    first, last = batch[0].index, batch[-1].index
    jobs = f"job {first}" if first == last else f"jobs {first}–{last}"
    msg = (
        f"a worker process died (killed, or out of memory) with {jobs} ({failure(err)}); "
        f"the rows done are kept in {table}: {continues}"
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
    continues: str = "--resume continues",
) -> None:
    """Run ``work`` on ``jobs`` (those not done in ``table`` already), ``chunk`` at a time, at
    most ``in_flight`` chunks submitted at once, appending each chunk's rows as it completes.

    A chunk whose task fails as a whole (the executor refused it, or Dask gave up on it after
    it killed its workers) becomes ``failed(job, reason)`` rows of status
    :data:`~omnical.fleet.table.LOST`, which ``--resume`` runs again. A stop (Ctrl-C, SIGTERM)
    cancels what has not started (a process pool's: its shutdown with ``cancel_futures=True``,
    as :func:`~omnical.fleet.executors.open_executor` does), and a process pool whose worker
    died cannot run anything more (:class:`OmnicalError`); either way the rows written stay and
    ``--resume`` does the rest (``continues``: how to go on, in the error's line).

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
                raise _broken(err, batch, table.path, continues) from None
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
                    raise _broken(err, batch, table.path, continues) from None
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


_R = TypeVar("_R")

Mode: TypeAlias = Literal["new", "resume", "replace", "continue"]
"""How a run takes its directory (:class:`OutClaim`)."""


@dataclass(frozen=True)
class OutClaim:
    """Where a fleet or a sweep writes, checked before its executor starts (:func:`claim_out_dir`).

    Attributes:
        out: the output directory (``--out``).
        settings: ``settings.json`` as the run writes it.
        table: the table's file name (``fleet.csv``, ``sweep.csv``).
        mode: ``new`` (``out`` made, or empty), ``resume`` (``out`` continued in place),
            ``replace`` (``--overwrite`` of an earlier output: the run is written in a hidden
            staging directory beside ``out`` and swapped in once complete; stopped, it is kept
            as ``OUT.partial``, the earlier output untouched) or ``continue`` (``--resume
            --overwrite``: ``partial``, what a stopped ``replace`` left, continued and swapped in).
        partial: the ``OUT.partial`` continued (``continue``).
    """

    out: Path
    settings: str
    table: str
    mode: Mode
    partial: Path | None = None

    @property
    def resume(self) -> bool:
        """Whether the rows already written are kept, not redone."""
        return self.mode in ("resume", "continue")

    @property
    def aside(self) -> bool:
        """Whether the run is written beside ``out`` and swapped in once complete."""
        return self.mode in ("replace", "continue")

    def continues(self) -> str:
        """How to go on after a stop, for the line that says where the rows are."""
        if not self.aside:
            return "--resume continues"
        if self.out.exists() or self.out.is_symlink():
            return (
                f"the earlier {self.out} was not touched; --resume --overwrite continues them, "
                "then replaces it"
            )
        return f"--resume --overwrite continues them, then puts them at {self.out}"


def run_into_table(
    executor: ExecutorSpec,
    work: Callable[[Sequence[_J]], list[dict[str, str]]],
    jobs: Callable[[Path], Sequence[_J]],
    header: Sequence[str],
    *,
    claim: OutClaim,
    chunk: int,
    failed: Callable[[_J, str], dict[str, str]],
    report: Callable[[Path, list[dict[str, str]]], _R],
    on_start: Callable[[int, int], None] | None = None,
    on_rows: Callable[[int], None] | None = None,
    on_stop: Callable[[Path, int, str], None] | None = None,
) -> tuple[list[dict[str, str]], int, _R]:
    """:func:`run_jobs` of ``jobs(place)`` on ``executor`` into the table, then ``report(place,
    rows)``; ``place`` is where ``claim`` writes (:func:`open_place`, once the executor is had),
    an ``aside`` one swapped in for ``claim.out`` once all is written. Its rows in index order,
    how many a resume found done, and what ``report`` returned.

    A stop or a failure keeps the rows written (an ``aside`` run's as ``OUT.partial``, the
    earlier output untouched): ``on_stop(table, rows, how to go on)`` says where, on a stop
    (and on a failure of an ``aside`` run that is not omnical's one line, which says it).
    ``chunk`` 0: :func:`auto_chunk`; the ``serial`` executor runs and writes one job at a time
    whatever ``chunk`` says; the callbacks: :func:`~omnical.fleet.recordings.run_fleet`'s.
    """
    from omnical.fleet.executors import open_executor

    place: Path | None = None
    results: ResultsTable | None = None
    try:
        with open_executor(executor) as pool:  # no scheduler: nothing written
            place = open_place(claim)
            results = ResultsTable(place / claim.table, header, resume=claim.resume)
            done_before = len(results.done)
            todo = jobs(place)
            if on_start is not None:
                on_start(len(todo), done_before)
            workers = executor.workers or 2
            if executor.kind == "serial":  # each job's row written as it ends: a stop loses none
                size, in_flight = 1, 1
            else:
                size, in_flight = chunk or auto_chunk(len(todo) - done_before, workers), 2 * workers
            run_jobs(
                pool,
                work,
                todo,
                results,
                chunk=size,
                in_flight=in_flight,
                failed=failed,
                on_rows=on_rows,
                continues=claim.continues(),
            )
        # the pool is shut down: no worker writes in place any more
        rows = results.close(sort=True)
        made = report(place, rows)
    except BaseException as stop:
        if place is not None:
            _kept_after(stop, claim, place, results, on_stop)
        raise
    if claim.aside:

        def said(kept: Path) -> None:
            if on_stop is not None:
                on_stop(kept / claim.table, len(rows), claim.continues())

        _put_in_place(claim, place, said)
    return rows, done_before, made


def _kept_after(
    stop: BaseException,
    claim: OutClaim,
    place: Path,
    results: ResultsTable | None,
    on_stop: Callable[[Path, int, str], None] | None,
) -> None:
    """After a stop or a failure of the run writing at ``place``: the table closed, an
    ``aside`` run moved to a free ``OUT.partial`` name (removed if it holds no table yet),
    ``stop``'s message naming where the rows are, ``on_stop`` told (see :func:`run_into_table`)."""
    from omnical.bags.staging import renamed_in_message

    if results is not None:
        with suppress(OmnicalError):  # unreadable: the rows are where they are
            results.close(sort=False)
    if claim.mode == "replace" and not (place / claim.table).is_file():
        shutil.rmtree(place, ignore_errors=True)  # nothing written: nothing to keep
        return
    kept = _kept_aside(claim, place)
    renamed_in_message(stop, place, kept)
    table = kept / claim.table
    if isinstance(stop, OmnicalError):
        if claim.aside and len(stop.args) == 1 and str(kept) not in str(stop.args[0]):
            where = f"; what was written is kept in {kept}: {claim.continues()}"
            stop.args = (f"{stop.args[0]}{where}",)
        return
    if on_stop is not None and (isinstance(stop, KeyboardInterrupt) or claim.aside):
        try:
            count = len(read_rows(table)[1])
        except OmnicalError:
            count = 0
        on_stop(table, count, claim.continues())


def _kept_aside(claim: OutClaim, place: Path) -> Path:
    """Where a stopped run's rows stay: a ``replace`` run's staging directory moved to a free
    ``OUT.partial`` name beside ``out``; any other where it is."""
    from omnical.bags.staging import keep_beside

    return keep_beside(place, claim.out) if claim.mode == "replace" else place


def _put_in_place(claim: OutClaim, place: Path, said: Callable[[Path], None]) -> None:
    """The complete ``aside`` run at ``place`` swapped in for ``claim.out`` (the earlier output
    removed), stop signals held meanwhile; a stop that came before keeps it aside instead,
    ``said(where)``, and is raised once the swap would have ended.

    Raises:
        OutputError: someone else's files took ``out`` meanwhile, or the rename failed: the new
            run kept aside, where said.
    """
    from omnical.bags.staging import held_stops, swap_into_place
    from omnical.reports.outputs import is_marked

    out = claim.out
    with held_stops() as stopped:
        taken = out.is_symlink() or (
            out.exists() and (not out.is_dir() or (any(out.iterdir()) and not is_marked(out)))
        )
        if taken:
            kept = _kept_aside(claim, place)
            msg = f"{out}: taken meanwhile by files omnical did not write; the new run is in {kept}"
            raise OutputError(msg)
        if stopped():  # a stop came while it was written: the earlier output stays
            said(_kept_aside(claim, place))
            return
        try:
            swap_into_place(place, out)
        except OSError as err:
            kept = _kept_aside(claim, place)
            msg = f"{out}: cannot put the new run in place ({err.strerror or err}); it is in {kept}"
            raise OutputError(msg) from None


def shared_path(path: Path) -> Path:
    """``path`` absolute, its folder resolved (``..`` as the system reads it) and its own name
    kept (a link's): the same for a worker elsewhere and for a resume from another folder."""
    absolute = path.absolute()
    if absolute.name in ("", ".", ".."):
        return absolute.resolve()
    return absolute.parent.resolve() / absolute.name


def claim_out_dir(
    out: Path,
    settings: Mapping[str, Any],
    table: str,
    *,
    resume: bool,
    overwrite: bool,
    notify: Callable[[str], None] | None = None,
) -> OutClaim:
    """Check that ``out`` can take a run with ``settings`` (:class:`OutClaim`): a new or empty
    directory, an earlier omnical one (``overwrite``: replaced once the new run is complete),
    or the same run to continue (``resume``: the settings must match; with ``overwrite``, the
    newest ``OUT.partial`` a stopped ``--overwrite`` run left, first). Nothing is written but
    what killed runs left, kept (``notify`` told: :func:`_keep_killed`).

    Raises:
        OutputError: a file or someone else's directory is there, an earlier run without
            ``--overwrite`` / ``--resume``, or ``--resume`` with other settings.
    """
    from omnical.reports.outputs import is_marked

    text = json.dumps(settings, indent=1, sort_keys=True) + "\n"
    where = out / SETTINGS
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise OutputError(f"{out}: not a directory; give a directory for the results")
    _keep_killed(out, table, notify)
    filled = out.is_dir() and any(out.iterdir())
    if filled and not is_marked(out):
        raise OutputError(f"{out}: holds files omnical did not write; give another --out")
    partial = _partial_of(out, text, table) if resume else None
    if partial is not None and overwrite:
        return OutClaim(out, text, table, "continue", partial)
    if resume:
        hint = (
            ""
            if partial is None
            else f"; the stopped --overwrite run in {partial} has these settings: --resume "
            "--overwrite continues it"
        )
        if not filled:
            raise OutputError(f"{out}: nothing to resume there{hint}")
        if not where.exists() or not (out / table).exists():
            raise OutputError(f"{out}: nothing to resume (no {SETTINGS} or {table}){hint}")
        found = where.read_text(encoding="utf-8")
        if found != text:
            msg = (
                f"{out}: --resume with other settings than the run there was started with: "
                f"{_difference(found, settings)} (see {where}); give the same ones, or "
                "--overwrite to start again"
            )
            raise OutputError(msg + hint)
        if partial is not None and notify is not None:
            left = f"the stopped --overwrite run in {partial} is left as it is"
            notify(f"resuming {out} itself; {left}: --resume --overwrite continues that one")
        return OutClaim(out, text, table, "resume")
    if not filled:
        return OutClaim(out, text, table, "new")
    if not overwrite:
        msg = f"{out}: an earlier run is there; --resume continues it, --overwrite replaces it"
        raise OutputError(msg)
    return OutClaim(out, text, table, "replace")


def open_place(claim: OutClaim) -> Path:
    """Where the run of ``claim`` writes, made: ``out`` (``new``: created, with omnical's
    marker and the settings; ``resume``: as it is), a hidden staging directory beside it
    (``replace``: the marker and the settings in it) or the ``OUT.partial`` continued.

    Raises:
        OutputError: the place cannot be written.
    """
    from omnical.bags.staging import make_staging
    from omnical.reports.outputs import MARKER

    if claim.mode == "resume":
        return claim.out
    if claim.partial is not None:  # continue
        return claim.partial
    place = claim.out if claim.mode == "new" else make_staging(claim.out, "out")
    try:
        place.mkdir(parents=True, exist_ok=True)
        (place / MARKER).write_text("written by omnical fleet/sweep\n", encoding="utf-8")
        (place / SETTINGS).write_text(claim.settings, encoding="utf-8")
    except OSError as err:
        if place != claim.out:
            shutil.rmtree(place, ignore_errors=True)
        raise OutputError(f"{claim.out}: cannot write: {err.strerror or err}") from None
    return place


_PARTIAL: Final = r"\.partial(-[0-9]+)?"
"""What follows ``OUT`` in the name of a stopped run kept aside (:func:`~omnical.bags.staging.
free_name`)."""


def _partial_of(out: Path, settings: str, table: str) -> Path | None:
    """The newest ``OUT.partial`` (``OUT.partial-2``, ...) holding a run started with
    ``settings`` (omnical's marker, ``settings.json`` the same, the table there); None if none."""
    from omnical.reports.outputs import is_marked

    name = re.compile(re.escape(out.name) + _PARTIAL)
    found: list[tuple[float, Path]] = []
    with suppress(OSError):
        for entry in out.parent.iterdir():
            if not name.fullmatch(entry.name) or entry.is_symlink() or not entry.is_dir():
                continue
            try:
                same = (entry / SETTINGS).read_text(encoding="utf-8") == settings
                if same and is_marked(entry) and (entry / table).is_file():
                    found.append(((entry / table).stat().st_mtime, entry))
            except (OSError, UnicodeDecodeError):
                continue
    return max(found)[1] if found else None


def _keep_killed(out: Path, table: str, notify: Callable[[str], None] | None) -> None:
    """What killed runs writing ``out`` left (:func:`~omnical.bags.staging.sweep_staging`): an
    earlier output moved aside for a swap put back; a staging directory holding a table kept
    as ``OUT.partial`` (``--resume --overwrite`` continues it), ``notify`` told; one without,
    removed."""
    from omnical.bags.staging import keep_beside, sweep_staging

    for staging in sweep_staging(out):
        if staging.kind != "out":
            continue
        if not (staging.path / table).is_file():
            shutil.rmtree(staging.path, ignore_errors=True)
            continue
        kept = keep_beside(staging.path, out)
        if notify is not None:
            notify(f"an omnical run writing {out} was killed; what it wrote is in {kept}")


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
