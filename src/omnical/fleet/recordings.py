"""``omnical fleet``: many recordings through one single command on an executor, one row each
in ``DIR/fleet.csv``, each recording's outputs in ``DIR/recordings/NAME/``, ``DIR/report.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Final

from omnical.fleet.executors import ExecutorSpec
from omnical.fleet.jobs import (
    FleetJob,
    FleetOptions,
    check_files,
    error_row,
    fleet_header,
    fleet_job_name,
    reference_label,
    run_fleet_chunk,
)
from omnical.fleet.runner import claim_out_dir, run_into_table, shared_path

__all__ = ["FLEET_TABLE", "FleetRun", "previous_rows", "run_fleet"]

FLEET_TABLE: Final = "fleet.csv"


@dataclass(frozen=True)
class FleetRun:
    """What a fleet run left.

    Attributes:
        table: ``DIR/fleet.csv``; report: ``DIR/report.md``.
        rows: the rows, in index order; done_before: rows a ``--resume`` found done.
        alerts: the maintenance alerts (``calibrate``).
    """

    table: Path
    report: Path
    rows: tuple[dict[str, str], ...]
    done_before: int
    alerts: int


def run_fleet(
    recordings: Sequence[Path],
    options: FleetOptions,
    executor: ExecutorSpec,
    out: Path,
    *,
    chunk: int = 0,
    resume: bool = False,
    overwrite: bool = False,
    previous: Path | None = None,
    on_start: Callable[[int, int], None] | None = None,
    on_rows: Callable[[int], None] | None = None,
    on_stop: Callable[[Path, int, str], None] | None = None,
    notify: Callable[[str], None] | None = None,
) -> FleetRun:
    """Run ``options.command`` on every recording (see the module).

    ``chunk``: recordings per task (0: one: a recording is seconds of work, a task's dispatch
    milliseconds);
    ``on_start(total, done)`` once the work is known, ``on_rows(n)`` as rows complete,
    ``on_stop(table, rows, how to go on)`` on Ctrl-C / SIGTERM, the rows kept written (before
    it goes on; with ``overwrite`` in ``OUT.partial``, the earlier output untouched until the
    run is complete: :func:`~omnical.fleet.runner.run_into_table`); ``notify`` what killed runs
    left (:func:`~omnical.fleet.runner.claim_out_dir`). Everything given is checked before
    anything is written.

    Raises:
        OutputError: ``out`` cannot take the run (:func:`~omnical.fleet.runner.claim_out_dir`).
        RecordingError: no such recording; ``previous`` is not a readable ``fleet calibrate``
            table with a recording of this fleet, or has two rows of one name.
        ConfigError: the executor cannot be had, a recording is given twice, a file option the
            same for every recording is bad (:func:`~omnical.fleet.jobs.check_files`).
    """
    from omnical.calibration.drift import factor_alerts, fleet_spread
    from omnical.kinematics.factors import FACTORS
    from omnical.reports.fleet import write_fleet_report

    _check_recordings(recordings)
    # absolute (workers elsewhere read this path), its folder resolved (`..` as the system
    # reads it) and its own name kept (a link's is the row's): a resume from another folder,
    # or through `..`, names the same recordings
    paths = [shared_path(p) for p in recordings]
    names = fleet_job_name(paths)
    earlier = [] if previous is None else previous_rows(previous, names)
    check_files(options)
    out = shared_path(out)
    settings = {
        "command": options.command,
        "options": asdict(options),
        "recordings": [str(p) for p in paths],
    }
    claim = claim_out_dir(
        out, settings, FLEET_TABLE, resume=resume, overwrite=overwrite, notify=notify
    )  # refused before an executor starts

    def jobs(place: Path) -> list[FleetJob]:
        return [
            FleetJob(i, str(p), name, str(place / "recordings" / name), options)
            for i, (p, name) in enumerate(zip(paths, names, strict=True))
        ]

    fields = [f.field for f in FACTORS]
    header = fleet_header(options.command)

    def report(place: Path, rows: list[dict[str, str]]) -> tuple[Path, int]:
        alerts = []
        spreads = []
        if options.command == "calibrate":
            alerts = factor_alerts(rows, fields, earlier)
            spreads = fleet_spread(rows, fields)
        written = write_fleet_report(
            place,
            options.command,
            header,
            rows,
            factors=fields,
            spreads=spreads,
            alerts=alerts,
            previous=str(previous) if previous is not None else "",
            reference=reference_label(options),
        )
        return written, len(alerts)

    rows, done_before, (written, alerts) = run_into_table(
        executor, run_fleet_chunk, jobs, header, claim=claim, chunk=chunk or 1, failed=error_row,
        report=report, on_start=on_start, on_rows=on_rows, on_stop=on_stop,
    )  # fmt: skip
    return FleetRun(out / FLEET_TABLE, out / written.name, tuple(rows), done_before, alerts)


def _check_recordings(recordings: Sequence[Path]) -> None:
    """Every recording is there (as a bag's reader finds it), checked before anything is
    written: a missing one is the single commands' line, not an error row.

    Raises:
        RecordingError: ``PATH: no such bag``.
    """
    from omnical.bags.bag import bag_location
    from omnical.errors import RecordingError

    for path in recordings:
        folder = bag_location(path)  # `RUN.mcap` names the ROS 2 bag `RUN/`
        if not path.exists() and not (folder != path and (folder / "metadata.yaml").is_file()):
            raise RecordingError(f"{path}: no such bag")


def previous_rows(previous: Path, names: Sequence[str]) -> list[dict[str, str]]:
    """The rows of ``--previous`` (an earlier ``fleet calibrate`` DIR, or its table), checked
    before any job: a ``fleet calibrate`` table, well formed, with an ok row of at least one
    of ``names`` (the fleet's recordings), no name twice.

    Raises:
        RecordingError: ``--previous FILE: ...``: no such table, another command's table,
            malformed at line N (its fields, status or figures), two rows of one name, or no
            recording in common.
    """
    import csv
    import io

    from omnical.calibration.drift import check_unique_names
    from omnical.errors import OmnicalError, RecordingError
    from omnical.fleet.jobs import FLEET_COMMANDS
    from omnical.fleet.table import LOST, STATUS
    from omnical.kinematics.factors import FACTORS
    from omnical.userfiles import read_text_file

    where = previous / FLEET_TABLE if previous.is_dir() else previous
    said = f"--previous {where}"
    if not where.is_file():
        raise RecordingError(f"--previous {previous}: no {FLEET_TABLE} there")
    try:
        text = read_text_file(where, "fleet calibrate table")
    except OmnicalError as err:
        raise RecordingError(f"--previous {err}") from None
    figures = [c for f in FACTORS for c in (f.field, f"{f.field}_sigma")]
    reader = csv.reader(io.StringIO(text))
    rows = []
    try:
        header = next(reader, [])
        missing = [c for c in ("name", STATUS, *figures) if c not in header]
        if missing:
            other = [c for c in FLEET_COMMANDS if header == fleet_header(c)]
            what = f"a fleet {other[0]} table" if other else f"no {missing[0]} column"
            if not header:
                what = "empty"
            msg = (
                f"{said}: not a fleet calibrate table ({what}); give an earlier fleet calibrate DIR"
            )
            raise RecordingError(msg)
        for values in reader:
            if not values:  # a blank line
                continue
            row = dict(zip(header, values, strict=False))
            why = _malformed(row, len(values), len(header), figures, ("ok", "error", LOST))
            if why:
                raise RecordingError(f"{said}: malformed at line {reader.line_num}: {why}")
            rows.append(row)
    except csv.Error as err:
        raise RecordingError(f"{said}: malformed at line {reader.line_num}: {err}") from None
    check_unique_names(rows, said)  # drift is matched by name
    there = sorted({row["name"] for row in rows if row[STATUS] == "ok"})
    if not set(there) & set(names):
        msg = (
            f"{said}: no recording in common with this fleet (there: {_few(there) or 'no ok row'}; "
            f"here: {_few(names)}): factors are compared by recording name"
        )
        raise RecordingError(msg)
    return rows


def _malformed(
    row: dict[str, str], fields: int, columns: int, figures: Sequence[str], statuses: Sequence[str]
) -> str:
    """What is wrong with a row of a ``fleet calibrate`` table ("" if nothing)."""
    if fields != columns:
        return f"{fields} fields, the header has {columns}"
    if row["status"] not in statuses:
        return f"status {row['status']!r} (not {', '.join(statuses)})"
    if row["status"] == "ok":
        for column in figures:
            try:
                float(row[column] or "nan")  # "" is a figure not estimated
            except ValueError:
                return f"{column} {row[column]!r} is not a number"
    return ""


def _few(names: Sequence[str], most: int = 4) -> str:
    """Up to ``most`` names, then how many more."""
    shown = ", ".join(names[:most])
    return shown + (f" and {len(names) - most} more" if len(names) > most else "")
