"""The results table of a fleet or a sweep: rows appended as they complete (one line, flushed),
read back to resume, and sorted by job index once every job is done.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Final

from omnical.errors import OutputError, RecordingError

__all__ = ["INDEX", "LOST", "REASON", "STATUS", "ResultsTable", "failure", "read_rows"]

INDEX: Final = "index"
"""Column of the job's index (its place in the command line, or the run number)."""
STATUS: Final = "status"
"""Column ``ok``, ``error`` (the job failed) or :data:`LOST`."""
LOST: Final = "lost"
"""Status of a job the executor failed to run (a refused submit, Dask's ``KilledWorker``): not
done, so ``--resume`` runs it again (a job's own ``error`` is done, and stays)."""
REASON: Final = "reason"
"""Column: why a job failed, one line ("" when ok)."""


def failure(err: BaseException) -> str:
    """The one-line reason of a job that raised ``err``: omnical's message as it is, anything
    else with its type (a bug, or the executor's own failure)."""
    from omnical.errors import OmnicalError

    text = str(err).strip()
    if not isinstance(err, OmnicalError):
        text = f"{type(err).__name__}: {text}" if text else type(err).__name__
    return (text.splitlines() or ["failed"])[0]


def _line(values: Sequence[str]) -> str:
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerow(values)
    return text.getvalue()


def read_rows(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    """The header and the complete rows of a results CSV (a last line cut short by a kill is
    left out).

    Raises:
        RecordingError: the file cannot be read or has no header.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise RecordingError(f"{path}: cannot read: {err}") from None
    if not text.endswith("\n"):  # the write of the last row was cut short
        text = text[: text.rfind("\n") + 1]
    reader = csv.reader(io.StringIO(text))
    header = next(reader, None)
    if not header:
        raise RecordingError(f"{path}: no header line: not a results table")
    rows = [
        dict(zip(header, values, strict=True)) for values in reader if len(values) == len(header)
    ]
    return header, rows


class ResultsTable:
    """``DIR/fleet.csv`` or ``DIR/sweep.csv``: one row per job, in the order they complete.

    Opening with ``resume`` keeps the complete rows already there (a cut last line is dropped,
    and so are the :data:`LOST` rows, whose jobs are to run again) and tells which job indices
    are done; without it the file starts empty.
    """

    def __init__(self, path: Path, header: Sequence[str], *, resume: bool) -> None:
        self.path = path
        self.header = list(header)
        self.done: set[int] = set()
        kept: list[dict[str, str]] = []
        if resume and path.exists():
            found, kept = read_rows(path)
            if found != self.header:
                msg = (
                    f"{path}: its columns are not this command's: resume it with the options "
                    "it was started with, or start again without --resume"
                )
                raise OutputError(msg)
            kept = [row for row in kept if row.get(STATUS) != LOST]
            self.done = {int(row[INDEX]) for row in kept}
        try:
            # the rows kept written anew beside it, then swapped in: a kill meanwhile loses none
            fresh = path.with_name(f".{path.name}.resuming")
            with fresh.open("w", encoding="utf-8", newline="") as f:
                f.write(_line(self.header))
                for row in kept:
                    f.write(_line([row[c] for c in self.header]))
            fresh.replace(path)
            self._file = path.open("a", encoding="utf-8", newline="")
        except OSError as err:
            raise OutputError(f"{path}: cannot write: {err.strerror or err}") from None

    def append(self, rows: Iterable[Mapping[str, str]]) -> None:
        """Write ``rows`` (each with every column) and flush them to the file."""
        try:
            for row in rows:
                self._file.write(_line([row.get(c, "") for c in self.header]))
                self.done.add(int(row[INDEX]))
            self._file.flush()
            os.fsync(self._file.fileno())
        except OSError as err:
            raise OutputError(f"{self.path}: cannot write: {err.strerror or err}") from None

    def close(self, *, sort: bool) -> list[dict[str, str]]:
        """Close the file; ``sort``: rewrite it ordered by index (every job done). Its rows."""
        self._file.close()
        _, rows = read_rows(self.path)
        if not sort:
            return rows
        rows.sort(key=lambda row: int(row[INDEX]))
        partial = self.path.with_name(f".{self.path.name}.sorting")
        try:
            with partial.open("w", encoding="utf-8", newline="") as f:
                f.write(_line(self.header))
                for row in rows:
                    f.write(_line([row[c] for c in self.header]))
            partial.replace(self.path)
        except OSError as err:
            raise OutputError(f"{self.path}: cannot write: {err.strerror or err}") from None
        finally:
            partial.unlink(missing_ok=True)
        return rows
