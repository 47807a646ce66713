"""``omnical recover``: bring back what a killed recorder flushed, as a complete bag.

PATH: a killed recording's name (its staging directory is salvaged, then removed) or a bag without
index; the result goes to ``--out``, by default a free ``RUN.recovered`` beside it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.options import Overwrite
from omnical.cli.output import say

__all__ = ["recover"]


def recover(
    path: Annotated[
        Path,
        typer.Argument(
            metavar="BAG",
            help="An unfinished bag, or the name a killed recording was going to have.",
        ),
    ],
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="Bag to write: RUN.mcap (ROS 2) or RUN.bag (ROS 1); default RUN.recovered.",
        ),
    ] = None,
    overwrite: Overwrite = False,
) -> None:
    """Recover every flushed message of a recording that was cut short (kill -9, crash)."""
    with handled_errors():
        _recover(path, out, overwrite)


def _recover(path: Path, out: Path | None, overwrite: bool) -> None:
    import shutil

    from omnical.bags.bag import (
        bag_location,
        check_bag_output,
        partial_location,
        write_bag,
    )
    from omnical.bags.recover import bag_is_complete, recover_bag, storage_file
    from omnical.bags.staging import Staging, find_staging
    from omnical.errors import RecordingError

    # a killed run first: its staging, which a complete earlier bag at PATH must not hide
    killed = [
        s
        for s in find_staging(bag_location(path))
        if s.kind in {"rec", "write"} and not s.alive() and storage_file(s.bag) is not None
    ]
    staging: Staging | None = killed[-1] if killed else None  # the newest
    if staging is not None:
        source = staging.bag
        what = "recorder" if staging.kind == "rec" else "writer"
        say(
            f"found the unfinished recording of {bag_location(path)} in {staging.path} "
            f"(its {what}, process {staging.pid}, was killed)"
            + (f"; {len(killed) - 1} older ones left there" if len(killed) > 1 else "")
        )
    elif path.exists() or path.is_symlink():
        source = path
    elif bag_location(path).exists():
        source = bag_location(path)
    else:
        msg = f"{path}: no such bag, and no unfinished recording of it to recover"
        raise RecordingError(msg)
    if staging is None and out is None and bag_is_complete(source):
        say(f"{source} is complete (closed with its index): nothing to recover, read it as it is")
        return
    named = bag_location(path)
    target = (
        partial_location(named, "recovered")
        if out is None
        else check_bag_output(out, overwrite=overwrite)
    )
    recording = recover_bag(source)
    for note in recording.notes:
        typer.echo(f"omnical: warning: {note}", err=True)
    if recording.message_count == 0:
        skipped = ", ".join(recording.skipped_topics)
        msg = f"{source}: nothing to recover: no complete chunk holds a message omnical reads"
        raise RecordingError(msg + (f" (topics: {skipped})" if skipped else ""))
    written = write_bag(recording, target, overwrite=overwrite)
    say(
        f"recovered {recording.message_count} messages ({recording.duration_s:.1f} s) "
        f"from {source} into {written}"
    )
    if staging is not None:
        shutil.rmtree(staging.path, ignore_errors=True)
        say(f"removed the unfinished recording {staging.path}")
