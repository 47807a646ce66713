"""``omnical fleet``: many recordings through one single command on an executor, one row each
in ``DIR/fleet.csv``, each recording's outputs in ``DIR/recordings/NAME/``, ``DIR/report.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path
from typing import Final

from omnical.fleet.executors import ExecutorSpec
from omnical.fleet.jobs import (
    FleetJob,
    FleetOptions,
    error_row,
    fleet_header,
    fleet_job_name,
    reference_label,
    run_fleet_chunk,
)
from omnical.fleet.runner import prepare_out_dir, run_into_table, shared_path
from omnical.fleet.table import read_rows

__all__ = ["FLEET_TABLE", "FleetRun", "run_fleet"]

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
    on_stop: Callable[[Path, int], None] | None = None,
) -> FleetRun:
    """Run ``options.command`` on every recording (see the module).

    ``chunk``: recordings per task (0: one: a recording is seconds of work, a task's dispatch
    milliseconds);
    ``on_start(total, done)`` once the work is known, ``on_rows(n)`` as rows complete,
    ``on_stop(table, rows)`` on Ctrl-C / SIGTERM, the rows kept written (before it goes on).

    Raises:
        OutputError: ``out`` cannot take the run (:func:`~omnical.fleet.runner.prepare_out_dir`).
        RecordingError: ``previous`` has no readable ``fleet.csv``, or two rows of one name.
        ConfigError: the executor cannot be had, or a recording is given twice.
    """
    from omnical.calibration.drift import check_unique_names, factor_alerts, fleet_spread
    from omnical.errors import RecordingError
    from omnical.kinematics.factors import FACTORS
    from omnical.reports.fleet import write_fleet_report

    earlier: list[dict[str, str]] = []
    if previous is not None:
        where = previous / FLEET_TABLE if previous.is_dir() else previous
        if not where.is_file():
            raise RecordingError(f"--previous {previous}: no {FLEET_TABLE} there")
        earlier = read_rows(where)[1]
        check_unique_names(earlier, f"--previous {where}")  # refused before the fleet runs
    # absolute (workers elsewhere read this path), its folder resolved (`..` as the system
    # reads it) and its own name kept (a link's is the row's): a resume from another folder,
    # or through `..`, names the same recordings
    paths = [shared_path(p) for p in recordings]
    names = fleet_job_name(paths)
    out = shared_path(out)
    settings = {
        "command": options.command,
        "options": asdict(options),
        "recordings": [str(p) for p in paths],
    }
    claim = partial(prepare_out_dir, out, settings, FLEET_TABLE, resume=resume, overwrite=overwrite)
    claim(check_only=True)  # refused before an executor starts
    jobs = [
        FleetJob(i, str(p), name, str(out / "recordings" / name), options)
        for i, (p, name) in enumerate(zip(paths, names, strict=True))
    ]
    header = fleet_header(options.command)
    rows, done_before = run_into_table(
        executor, run_fleet_chunk, jobs, (out / FLEET_TABLE, header), claim=claim, resume=resume,
        chunk=chunk or 1, failed=error_row, on_start=on_start, on_rows=on_rows, on_stop=on_stop,
    )  # fmt: skip
    fields = [f.field for f in FACTORS]
    alerts = []
    spreads = []
    if options.command == "calibrate":
        alerts = factor_alerts(rows, fields, earlier)
        spreads = fleet_spread(rows, fields)
    report = write_fleet_report(
        out,
        options.command,
        header,
        rows,
        factors=fields,
        spreads=spreads,
        alerts=alerts,
        previous=str(previous) if previous is not None else "",
        reference=reference_label(options),
    )
    return FleetRun(out / FLEET_TABLE, report, tuple(rows), done_before, len(alerts))
