"""``omnical export``: a recording as CSV files or TUM trajectories, in a directory written whole."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.choices import ExportFormat, parse_choice
from omnical.cli.errors import handled_errors
from omnical.cli.options import Overwrite, choice_metavar
from omnical.cli.output import say

if TYPE_CHECKING:
    from omnical.bags.reference_topics import PoseTopic

__all__ = ["export"]


def export(
    run: Annotated[Path, typer.Argument(metavar="BAG", help="Recording to export.")],
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
            help="csv (one file per topic omnical reads, pose topics as t_ns,x_m,y_m,yaw_rad) or "
            "tum (odometry, ground truth, IPS and every pose topic: PoseStamped, "
            "PoseWithCovarianceStamped, Odometry, TransformStamped, tf per child frame).",
        ),
    ] = ExportFormat.CSV.value,
    overwrite: Overwrite = False,
) -> None:
    """Export a recording to CSV (one file per topic) or TUM trajectory files.

    Pose topics (motion capture) are written too, named after the topic (/mocap/pose →
    mocap_pose.tum), ready for --reference-file; every topic left out is listed with its type.
    """
    with handled_errors():
        _export(run, out, parse_choice(ExportFormat, fmt, "--format"), overwrite)


def _export(run: Path, out: Path, fmt: ExportFormat, overwrite: bool = False) -> None:
    from omnical.bags.bag import resolve_source
    from omnical.bags.export import (
        export_bag_csv,
        export_bag_tum,
        export_poses_csv,
        export_poses_tum,
    )
    from omnical.bags.reference_topics import pose_topics
    from omnical.cli.output import tell
    from omnical.errors import RecordingError
    from omnical.recording.topics import recognise_topic
    from omnical.reports.outputs import claim_directory

    pose_exporter = {ExportFormat.CSV: export_poses_csv, ExportFormat.TUM: export_poses_tum}[fmt]
    source = resolve_source(run)  # a missing bag is refused before the output directory is made
    claimed = claim_directory(out, overwrite=overwrite, writer="omnical export", notify=tell)
    with claimed.staged(tell) as directory:
        # Topic by topic, part by part: memory does not grow with the recording (CSV: every
        # topic omnical reads; TUM: the trajectories).
        exported = (
            export_bag_csv(source, directory)
            if fmt == ExportFormat.CSV
            else export_bag_tum(source, directory)
        )
        in_bag = exported.bag_topics  # read with the bag: no second index of a ROS 1 bag
        for note in exported.notes:
            typer.echo(f"omnical: warning: {note}", err=True)
        written = list(exported.written)
        poses, pose_skips, skips = _pose_topics(source, pose_topics(in_bag))
        written += pose_exporter(poses, directory)
        pose_names = {p.topic for p in poses}
        for topic, msgtype in in_bag.items():
            hit = recognise_topic(topic, msgtype)
            if topic in pose_names or (hit is not None and hit[0] in exported.topics):
                continue
            reason = pose_skips.get(topic)
            if reason is None:
                reason = _why_not(fmt, hit is not None)
            if reason:
                skips.append(f"skipped {topic} ({msgtype}): {reason}")
        if not written:  # nothing but the marker: the staging is removed, no directory left
            for line in skips:
                say(line)
            wanted = (
                "a topic omnical reads" if fmt == ExportFormat.CSV else "a trajectory or pose topic"
            )
            msg = f"{run}: nothing to export: no message of {wanted}" + (
                f"; the bag holds {', '.join(f'{t} [{m}]' for t, m in in_bag.items())}"
                if in_bag
                else ""
            )
            raise RecordingError(msg)
    for path in written:
        say(f"wrote {claimed.final(path)}")
    for line in skips:
        say(line)


def _why_not(fmt: ExportFormat, recognised: bool) -> str:
    """Why a topic of the bag (recognised by omnical's reader or not) was not exported."""
    if recognised:
        return "no message" if fmt == ExportFormat.CSV else "not a trajectory"
    return "not a topic omnical reads" if fmt == ExportFormat.CSV else "not a pose type"


def _pose_topics(
    source: Path, names: list[str]
) -> tuple[list[PoseTopic], dict[str, str], list[str]]:
    """The pose topics ``names`` of the bag, per child frame; why a topic is left out (topic →
    reason: no usable pose, a type mix, several single poses); and a skip line for each child
    frame of a single pose (a static transform is not a trajectory)."""
    from omnical.bags.reference_topics import read_pose_frames
    from omnical.errors import ConfigError, RecordingError

    poses: list[PoseTopic] = []
    skipped: dict[str, str] = {}
    lines: list[str] = []
    for name in names:
        try:
            frames = read_pose_frames(source, name)
        except (ConfigError, RecordingError) as err:
            skipped[name] = str(err)
            continue
        for frame in frames:
            if len(frame.table) < 2:
                child = f" → {frame.child_frame_id}" if frame.child_frame_id else ""
                lines.append(
                    f"skipped {name}{child} ({frame.msgtype}): a single pose, not a trajectory"
                )
                continue
            for note in frame.notes:
                typer.echo(f"omnical: warning: {note}", err=True)
            poses.append(frame)
        if not any(len(f.table) >= 2 for f in frames):
            skipped[name] = ""  # said per child frame
    return poses, skipped, lines
