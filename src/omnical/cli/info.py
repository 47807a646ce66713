"""``omnical info``: what a recording holds, every topic of it, understood by omnical or not."""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.output import console

if TYPE_CHECKING:
    from rich.console import Console
    from rich.table import Table

    from omnical.recording.summary import RecordingSummary

__all__ = ["info"]

_NS_PER_S = 1_000_000_000


@cache
def _commands_by_topic() -> dict[str, str]:
    """Which commands read a canonical topic (every one is exported and recovered)."""
    from omnical.recording import topics as t

    return {
        t.CMD_VEL: "evaluate calibrate",
        t.ODOM: "evaluate calibrate map",
        t.GROUND_TRUTH: "evaluate map (truth)",
        t.IMU: "evaluate calibrate",
        t.HEDGE_POS_ANG: "locate evaluate calibrate",
        t.BEACON_RAW_DISTANCE: "locate evaluate calibrate",
        t.BEACONS_POS_A: "locate evaluate calibrate",
        t.HEDGE_QUALITY: "export",
        t.EVENTS: "calibrate",
        t.SCAN: "map navigate",
        t.IMU_MAG: "evaluate calibrate (seed 003)",
        t.DEAD_WHEELS: "evaluate calibrate (seed 003)",
    }


_BY_TYPE = {
    "sensor_msgs/msg/JointState": "--wheel-topic",
    "geometry_msgs/msg/PoseStamped": "--reference-topic",
    "geometry_msgs/msg/PoseWithCovarianceStamped": "--reference-topic",
    "nav_msgs/msg/Odometry": "--reference-topic",
    "geometry_msgs/msg/TransformStamped": "--reference-topic",
    "tf2_msgs/msg/TFMessage": "--reference-topic",
}
"""Topics omnical reads when named on the command line, by type."""


def info(
    run: Annotated[
        Path,
        typer.Argument(metavar="BAG", help="Recording (ROS 2 bag directory or .mcap, ROS 1 .bag)."),
    ],
) -> None:
    """Every topic of a recording (type, messages, rate, time span, whether omnical reads it),
    its duration and the distance travelled."""
    with handled_errors():
        _print_summary(run)


def _print_summary(run: Path) -> None:
    from rich.console import Console
    from rich.markup import escape

    from omnical.bags.baginfo import summarize_bag
    from omnical.recording.topics import TOPICS

    # Counts and times from the bag's index; only /odom and /ground_truth are decoded.
    summary = summarize_bag(run)
    rows = len(summary.connections) or len(summary.topics)
    out = console()
    # a log or a file: lines as long as they need, not folded to 80 columns
    shown = out if out.is_terminal else Console(highlight=False, width=160)
    shown.print(_topic_table(summary, escape(str(run)), shown))
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


def _topic_table(summary: RecordingSummary, title: str, out: Console) -> Table:
    """Every topic of the bag, one row each, with its type whole in a column of its own, or
    under the topic's name where that fits ``out`` (80–110 columns: Marvelmind's type names are
    long) or takes fewer lines. No type name is cut or folded."""
    from rich.markup import escape
    from rich.text import Text

    starts = [c.first_ns for c in summary.connections if c.first_ns is not None]
    t0 = min(starts) if starts else summary.start_ns
    rows: list[tuple[str, str, str, str, str, str]] = []
    for c in summary.connections:
        span = "-"
        if c.first_ns is not None and c.last_ns is not None and t0 is not None:
            span = f"{(c.first_ns - t0) / _NS_PER_S:.2f}–{(c.last_ns - t0) / _NS_PER_S:.2f}"
        rate = f"{c.rate_hz:.1f}" if c.rate_hz else "-"
        reads = _used_by(c.topic, c.msgtype, c.reads_as)
        rows.append((c.topic, _short_type(c.msgtype), str(c.count), rate, span, reads))
    if not summary.connections:  # a summary without the bag's own list (not expected)
        for t in summary.topics:
            rate = f"{t.rate_hz:.1f}" if t.rate_hz else "-"
            rows.append((t.name, "", str(t.count), rate, "-", "yes"))

    def table(stacked: bool) -> Table:
        from rich import box
        from rich.table import Table

        grid = Table(
            title=title, box=box.SIMPLE_HEAD, pad_edge=False, show_edge=False, collapse_padding=True
        )
        grid.add_column("topic\n  type" if stacked else "topic", no_wrap=True)
        if not stacked:
            grid.add_column("type", no_wrap=True)
        grid.add_column("messages", justify="right")
        grid.add_column("rate (Hz)", justify="right")
        grid.add_column("span (s)", justify="right", no_wrap=True)
        grid.add_column("used by")
        for topic, msgtype, *figures, reads in rows:
            if stacked:
                name = Text(topic)
                if msgtype:
                    name.append(f"\n  {msgtype}", style="dim")
                grid.add_row(name, *figures, reads)
            else:
                grid.add_row(escape(topic), escape(msgtype), *figures, reads)
        return grid

    wide, stacked = table(stacked=False), table(stacked=True)
    unbounded = out.options.update_width(1_000_000)  # the widths it needs, not the ones it has
    if out.measure(wide, options=unbounded).minimum > out.width:
        return stacked
    return min((wide, stacked), key=lambda t: len(out.render_lines(t, out.options)))


def _short_type(msgtype: str) -> str:
    """``nav_msgs/Odometry``; Marvelmind's long package names shortened to ``marvelmind/``."""
    package, _, name = msgtype.replace("/msg/", "/").rpartition("/")
    if package.startswith("marvelmind"):
        package = "marvelmind"
    return f"{package}/{name}" if package else name


def _used_by(topic: str, msgtype: str, reads_as: str | None) -> str:
    """The commands that read a topic, as the table shows them (markup escaped)."""
    from rich.markup import escape

    if reads_as is None:
        option = _BY_TYPE.get(msgtype)
        return f"with {option}" if option else "[dim]no[/dim]"
    used = _commands_by_topic().get(reads_as, "evaluate calibrate --wheel-topic")
    return used if reads_as == topic else f"{used} (as {escape(reads_as)})"
