"""``omnical export``: a recording as CSV files or TUM trajectories."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.choices import ExportFormat, parse_choice
from omnical.cli.errors import handled_errors
from omnical.cli.options import choice_metavar
from omnical.cli.output import say

__all__ = ["export"]


def export(
    run: Annotated[Path, typer.Argument(help="Recording to export.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory.")],
    fmt: Annotated[
        str,
        typer.Option(
            "--format",
            "-f",
            metavar=choice_metavar(ExportFormat),
            help="csv (one file per topic) or tum (odometry, ground truth, IPS trajectories).",
        ),
    ] = ExportFormat.CSV.value,
) -> None:
    """Export a recording to CSV (one file per topic) or TUM trajectory files."""
    with handled_errors():
        _export(run, out, parse_choice(ExportFormat, fmt, "--format"))


def _export(run: Path, out: Path, fmt: ExportFormat) -> None:
    from omnical.recording.bag import read_bag
    from omnical.recording.export import export_csv, export_tum
    from omnical.recording.topics import GROUND_TRUTH, HEDGE_POS_ANG, ODOM

    exporter = {ExportFormat.CSV: export_csv, ExportFormat.TUM: export_tum}[fmt]
    # CSV writes every topic; TUM only the trajectories.
    topics = None if fmt == ExportFormat.CSV else (ODOM, GROUND_TRUTH, HEDGE_POS_ANG)
    for path in exporter(read_bag(run, topics), out):
        say(f"wrote {path}")
