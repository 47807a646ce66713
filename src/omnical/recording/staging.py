"""Where bags are written before they are complete, and what is left when a writer is killed.

Every bag is first written into a hidden *staging* directory beside its final place and moved
there only when complete, so a final name never holds half a bag and an earlier bag is
replaced only by a finished one. A staging directory is named after the bag, its kind and the
process that owns it::

    .RUN.omnical-write-<pid>-<random>/     write_bag: the whole recording at once
    .RUN.omnical-rec-<pid>-<random>/       BagRecorder: a long run, flushed as it goes

A process killed while writing (``kill -9``, power loss) leaves its staging behind.
:func:`sweep_staging`, run before every write to the same place, removes what can be removed
safely: a ``write`` staging of a dead process (its recording died with it in memory), or of
any process when older than :data:`STALE_AFTER_S` (no bag takes a day to write at once). A
``rec`` staging of a dead process still holds every flushed message: it is *never* deleted by
the sweep, only reported (``omnical recover RUN`` brings it back, then removes it). A staging
of a live process is a concurrent writer and is left alone.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Literal

from omnical.errors import RecordingError

__all__ = [
    "STALE_AFTER_S",
    "Staging",
    "StagingKind",
    "find_staging",
    "make_staging",
    "process_alive",
    "sweep_staging",
]

StagingKind = Literal["write", "rec"]

STALE_AFTER_S: Final = 24 * 3600.0
"""Age after which a ``write`` staging is removed even if its process id is alive (reused)."""

_PATTERN: Final = re.compile(r"^\.(?P<name>.+)\.omnical-(?P<kind>write|rec)-(?P<pid>\d+)-[^/]+$")


@dataclass(frozen=True)
class Staging:
    """One staging directory: where it is, for which bag name, its kind and owner."""

    path: Path
    name: str
    kind: StagingKind
    pid: int

    @property
    def bag(self) -> Path:
        """The bag inside (``staging/RUN``: a ROS 2 directory or a ROS 1 file)."""
        return self.path / self.name

    def alive(self) -> bool:
        """Whether its writer is still running."""
        return process_alive(self.pid)


def process_alive(pid: int) -> bool:
    """Whether a process with id ``pid`` runs on this machine (ours counts as alive)."""
    if pid <= 0:
        return False
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process
    except OSError:
        return False
    return True


def make_staging(target: Path, kind: StagingKind) -> Path:
    """Create a staging directory for ``target`` beside it (its parents are created).

    Raises:
        RecordingError: The place cannot be written (read-only, missing permission, full).
    """
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        prefix = f".{target.name}.omnical-{kind}-{os.getpid()}-"
        return Path(tempfile.mkdtemp(prefix=prefix, dir=target.parent))
    except OSError as err:
        msg = f"{target}: cannot create bag: {err.strerror or err}"
        raise RecordingError(msg) from None


def find_staging(target: Path) -> list[Staging]:
    """The staging directories of the bag ``target`` (any kind, any owner), oldest first."""
    parent = target.parent
    found: list[tuple[float, Staging]] = []
    try:
        entries = list(parent.iterdir())
    except OSError:
        return []
    for entry in entries:
        match = _PATTERN.match(entry.name)
        if match is None or match["name"] != target.name:
            continue
        try:
            if not entry.is_dir() or entry.is_symlink():
                continue
            mtime = entry.stat().st_mtime
        except OSError:
            continue
        kind: StagingKind = "rec" if match["kind"] == "rec" else "write"
        found.append((mtime, Staging(entry, target.name, kind, int(match["pid"]))))
    return [s for _, s in sorted(found, key=lambda item: item[0])]


def _age_s(path: Path) -> float:
    newest = 0.0
    try:
        for entry in [path, *path.rglob("*")]:
            newest = max(newest, entry.stat().st_mtime)
    except OSError:
        return 0.0
    return time.time() - newest


def sweep_staging(target: Path) -> list[Staging]:
    """Remove the stale ``write`` stagings of ``target``; return unfinished recordings.

    Returns:
        The ``rec`` stagings of dead processes: recordings cut short, which
        ``omnical recover`` (:func:`omnical.recording.recover.recover_bag`) brings back.
    """
    unfinished: list[Staging] = []
    for staging in find_staging(target):
        if staging.kind == "rec":
            if not staging.alive():
                unfinished.append(staging)
            continue
        if staging.pid == os.getpid():
            continue  # a write of this very process (another thread), never stale
        if not staging.alive() or _age_s(staging.path) > STALE_AFTER_S:
            shutil.rmtree(staging.path, ignore_errors=True)
    return unfinished
