"""``omnical info``: what a recording holds."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.output import console

__all__ = ["info"]


def info(
    run: Annotated[
        Path, typer.Argument(help="Recording (ROS 2 bag directory or .mcap, ROS 1 .bag).")
    ],
) -> None:
    """Topics with message counts and rates, duration and distance travelled of a recording."""
    with handled_errors():
        _print_summary(run)


def _print_summary(run: Path) -> None:
    from rich.markup import escape
    from rich.table import Table

    from omnical.recording.baginfo import summarize_bag

    # Counts and times from the bag's index; only /odom and /ground_truth are decoded.
    summary = summarize_bag(run)
    table = Table(title=escape(str(run)))
    table.add_column("topic")
    table.add_column("messages", justify="right")
    table.add_column("rate (Hz)", justify="right")
    for topic in summary.topics:
        rate = f"{topic.rate_hz:.1f}" if topic.rate_hz else "-"
        table.add_row(topic.name, str(topic.count), rate)
    out = console()
    out.print(table)
    out.print(f"duration: {summary.duration_s:.2f} s")
    if summary.distance_odom_m is not None:
        out.print(f"distance travelled (odometry): {summary.distance_odom_m:.3f} m")
    if summary.distance_ground_truth_m is not None:
        out.print(f"distance travelled (ground truth): {summary.distance_ground_truth_m:.3f} m")
