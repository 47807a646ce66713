"""``omnical info``: what a recording holds, every topic of it, understood by omnical or not."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.output import console

__all__ = ["info"]

_NS_PER_S = 1_000_000_000


def info(
    run: Annotated[
        Path, typer.Argument(help="Recording (ROS 2 bag directory or .mcap, ROS 1 .bag).")
    ],
) -> None:
    """Every topic of a recording (type, messages, rate, time span, whether omnical reads it),
    its duration and the distance travelled."""
    with handled_errors():
        _print_summary(run)


def _print_summary(run: Path) -> None:
    from rich import box
    from rich.markup import escape
    from rich.table import Table

    from omnical.recording.baginfo import summarize_bag
    from omnical.recording.topics import TOPICS

    # Counts and times from the bag's index; only /odom and /ground_truth are decoded.
    summary = summarize_bag(run)
    starts = [c.first_ns for c in summary.connections if c.first_ns is not None]
    t0 = min(starts) if starts else summary.start_ns
    table = Table(title=escape(str(run)), box=box.SIMPLE_HEAD)
    table.add_column("topic", no_wrap=True)
    table.add_column("type", overflow="fold")
    table.add_column("messages", justify="right")
    table.add_column("rate (Hz)", justify="right")
    table.add_column("span (s)", justify="right")
    table.add_column("read")
    rows = len(summary.connections) or len(summary.topics)
    for c in summary.connections:
        span = "-"
        if c.first_ns is not None and c.last_ns is not None and t0 is not None:
            span = f"{(c.first_ns - t0) / _NS_PER_S:.2f}–{(c.last_ns - t0) / _NS_PER_S:.2f}"
        rate = f"{c.rate_hz:.1f}" if c.rate_hz else "-"
        if c.reads_as is None:
            reads = "[dim]no[/dim]"
        else:
            reads = "yes" if c.reads_as == c.topic else f"as {escape(c.reads_as)}"
        msgtype = escape(c.msgtype.replace("/msg/", "/"))
        table.add_row(escape(c.topic), msgtype, str(c.count), rate, span, reads)
    if not summary.connections:  # a summary without the bag's own list (not expected)
        for t in summary.topics:
            rate = f"{t.rate_hz:.1f}" if t.rate_hz else "-"
            table.add_row(escape(t.name), "", str(t.count), rate, "-", "yes")
    out = console()
    out.print(table)
    if not rows:
        out.print("the bag holds no topics")
    elif summary.understood_nothing:
        out.print(
            "omnical understands none of these topics (it reads "
            + ", ".join(TOPICS)
            + ", and Marvelmind messages under any name)",
            markup=False,
        )
    if summary.start_ns is not None:
        out.print(f"duration: {summary.duration_s:.2f} s (of the topics omnical reads)")
    if summary.distance_odom_m is not None:
        out.print(f"distance travelled (odometry): {summary.distance_odom_m:.3f} m")
    if summary.distance_ground_truth_m is not None:
        out.print(f"distance travelled (ground truth): {summary.distance_ground_truth_m:.3f} m")
    for note in summary.notes:
        typer.echo(f"omnical: warning: {note}", err=True)
