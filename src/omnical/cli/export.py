"""``omnical export``: a recording as CSV files or TUM trajectories."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.choices import ExportFormat, parse_choice
from omnical.cli.errors import handled_errors
from omnical.cli.options import Overwrite, choice_metavar
from omnical.cli.output import say

__all__ = ["export"]


def export(
    run: Annotated[Path, typer.Argument(help="Recording to export.")],
    out: Annotated[
        Path,
        typer.Option(
            "--out", "-o", help="Output directory (new, empty, or an earlier omnical output)."
        ),
    ],
    fmt: Annotated[
        str,
        typer.Option(
            "--format",
            "-f",
            metavar=choice_metavar(ExportFormat),
            help="csv (one file per topic) or tum (odometry, ground truth, IPS trajectories).",
        ),
    ] = ExportFormat.CSV.value,
    overwrite: Overwrite = False,
) -> None:
    """Export a recording to CSV (one file per topic) or TUM trajectory files."""
    with handled_errors():
        _export(run, out, parse_choice(ExportFormat, fmt, "--format"), overwrite)


def _export(run: Path, out: Path, fmt: ExportFormat, overwrite: bool = False) -> None:
    from omnical.errors import RecordingError
    from omnical.recording.bag import read_bag, resolve_source
    from omnical.recording.export import export_csv, export_tum
    from omnical.recording.topics import GROUND_TRUTH, HEDGE_POS_ANG, ODOM
    from omnical.reports.outputs import claim_directory

    exporter = {ExportFormat.CSV: export_csv, ExportFormat.TUM: export_tum}[fmt]
    # CSV writes every topic; TUM only the trajectories.
    topics = None if fmt == ExportFormat.CSV else (ODOM, GROUND_TRUTH, HEDGE_POS_ANG)
    resolve_source(run)  # a missing bag is refused before the output directory is made
    directory = claim_directory(out, overwrite=overwrite, writer="omnical export")
    recording = read_bag(run, topics)
    for note in recording.notes:
        typer.echo(f"omnical: warning: {note}", err=True)
    written = exporter(recording, directory) if recording.message_count else []
    if not written:
        wanted = (
            "a topic omnical reads"
            if topics is None
            else "a trajectory (" + ", ".join(topics) + ")"
        )
        skipped = ", ".join(f"{k} [{v}]" for k, v in recording.skipped_topics.items())
        msg = f"{run}: nothing to export: no message of {wanted}" + (
            f"; the bag holds {skipped}" if skipped else ""
        )
        raise RecordingError(msg)
    for path in written:
        say(f"wrote {path}")
