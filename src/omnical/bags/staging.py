"""Every output is written in a hidden staging directory beside its place, then swapped in whole.

A final name never holds half an output (a stopped one is kept as ``.partial``); what a killed
writer left is found again by its name, ``.NAME.omnical-KIND-PID-RANDOM``.
"""

from __future__ import annotations

import errno
import os
import re
import secrets
import shutil
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Final, Literal

from omnical.errors import OutputError, RecordingError

__all__ = [
    "STOP_SIGNALS",
    "Staging",
    "StagingKind",
    "find_staging",
    "free_name",
    "held_stops",
    "inside_open_staging",
    "keep_beside",
    "make_parents",
    "make_staging",
    "missing_parents",
    "open_staging",
    "output_in_place",
    "process_alive",
    "remove_created_empty",
    "remove_empty",
    "renamed_in_message",
    "swap_into_place",
    "sweep_staging",
]

StagingKind = Literal["write", "rec", "out", "old"]
"""``write``: :func:`~omnical.bags.bag.write_bag` (a whole recording at once); ``rec``: a
:class:`~omnical.bags.recorder.BagRecorder` (flushed as it goes); ``out``: a directory
output or a group of files (a report, a campaign, a map); ``old``: the earlier output, moved
aside for the instant of a swap."""


STOP_SIGNALS: Final = frozenset({signal.SIGINT, signal.SIGTERM})
"""The signals that stop omnical (Ctrl-C and SIGTERM, the same way)."""

_PATTERN: Final = re.compile(
    r"^\.(?P<name>.+)\.omnical-(?P<kind>write|rec|out|old)-(?P<pid>\d+)-[^/]+$"
)

_OPEN: set[Path] = set()
"""The staging directories this process is writing: what goes inside one is already staged."""
_OPEN_LOCK = threading.Lock()

_CREATED: list[Path] = []
"""Directories this command created for its outputs, outermost first (see :func:`make_parents`)."""


def make_parents(directory: Path) -> None:
    """``mkdir -p directory``, remembering what it created: a command that fails removes those
    that stayed empty (:func:`remove_created_empty`), so nothing of it is left behind."""
    missing = []
    place = directory
    while not place.exists() and place != place.parent:
        missing.append(place)
        place = place.parent
    directory.mkdir(parents=True, exist_ok=True)
    _CREATED.extend(reversed(missing))


def remove_created_empty(*, forget_only: bool = False) -> None:
    """Remove the directories :func:`make_parents` created that are still empty (innermost
    first), and forget them; ``forget_only``: just forget (a command starts)."""
    created = list(_CREATED)
    _CREATED.clear()
    for directory in [] if forget_only else reversed(created):
        with suppress(OSError):
            directory.rmdir()


@dataclass(frozen=True)
class Staging:
    """One staging directory: where it is, for which output name, its kind and owner."""

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


def missing_parents(target: Path) -> list[Path]:
    """The parent directories of ``target`` that do not exist yet, deepest first."""
    missing = []
    parent = target.parent
    while not parent.exists() and not parent.is_symlink() and parent != parent.parent:
        missing.append(parent)
        parent = parent.parent
    return missing


def remove_empty(directories: list[Path]) -> None:
    """Remove those of ``directories`` (deepest first) that are empty; leave the others."""
    for directory in directories:
        try:
            directory.rmdir()
        except OSError:
            return


def make_staging(target: Path, kind: StagingKind) -> Path:
    """Create a staging directory for ``target`` beside it (its parents are created).

    Made with the user's umask (an ``out`` staging becomes the output itself).

    Raises:
        RecordingError: (OutputError for ``out``) the place cannot be written (read-only,
            missing permission, full).
    """
    try:
        make_parents(target.parent)
        for _ in range(100):
            path = (
                target.parent
                / f".{target.name}.omnical-{kind}-{os.getpid()}-{secrets.token_hex(4)}"
            )
            try:
                path.mkdir()
            except FileExistsError:
                continue
            return path
        raise FileExistsError(errno.EEXIST, "no free staging name")
    except OSError as err:
        if kind == "out":
            raise OutputError(f"{target}: cannot write: {err.strerror or err}") from None
        raise RecordingError(f"{target}: cannot create bag: {err.strerror or err}") from None


@contextmanager
def open_staging(staging: Path) -> Iterator[Path]:
    """Mark ``staging`` as being written by this process while the block runs
    (:func:`inside_open_staging`: an output written inside it is not staged again)."""
    key = staging.absolute()
    with _OPEN_LOCK:
        _OPEN.add(key)
    try:
        yield staging
    finally:
        with _OPEN_LOCK:
            _OPEN.discard(key)


def inside_open_staging(path: Path) -> bool:
    """Whether ``path`` is, or lies inside, a staging directory this process is writing."""
    absolute = path.absolute()
    with _OPEN_LOCK:
        return any(absolute == s or s in absolute.parents for s in _OPEN)


def find_staging(target: Path) -> list[Staging]:
    """The staging directories of the output ``target`` (any kind, any owner), oldest first."""
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
            if entry.is_symlink() or not (entry.is_dir() or match["kind"] == "old"):
                continue
            mtime = entry.lstat().st_mtime
        except OSError:
            continue
        kind: StagingKind = match["kind"]  # type: ignore[assignment]  # the pattern's four
        found.append((mtime, Staging(entry, target.name, kind, int(match["pid"]))))
    return [s for _, s in sorted(found, key=lambda item: item[0])]


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with suppress(FileNotFoundError):
            path.unlink()


def sweep_staging(target: Path) -> list[Staging]:
    """Tidy what killed writers of ``target`` left; return what they wrote that is worth keeping.

    A dead process's ``old`` is put back if ``target`` is missing, else removed; its ``write``,
    ``rec`` or ``out`` staging is left and returned (for ``omnical recover`` or ``.partial``).
    A staging of a live process is a concurrent writer and is left alone.
    """
    unfinished: list[Staging] = []
    for staging in find_staging(target):
        if staging.pid == os.getpid() or staging.alive():
            continue
        if staging.kind in {"write", "rec", "out"}:
            unfinished.append(staging)
        elif not target.exists() and not target.is_symlink():  # an "old" moved aside
            with suppress(OSError):
                staging.path.rename(target)
        else:
            _remove(staging.path)
    return unfinished


def free_name(target: Path, label: str = "partial", suffix: str = "") -> Path:
    """A free name beside ``target`` saying ``label``: ``RUN.partial``, ``RUN.partial-2``, ...

    ``suffix`` stays last (``RUN.bag`` with ``.bag`` → ``RUN.partial.bag``).

    Raises:
        OutputError: 10,000 such names are taken.
    """
    stem = target.name.removesuffix(suffix) if suffix else target.name
    for k in range(1, 10_000):
        candidate = target.with_name(f"{stem}.{label}{'' if k == 1 else f'-{k}'}{suffix}")
        if not candidate.exists() and not candidate.is_symlink():
            return candidate
    msg = f"{target}: no free name for a {label} output (10,000 taken)"
    raise OutputError(msg)


def keep_beside(staged: Path, target: Path, label: str = "partial", suffix: str = "") -> Path:
    """Move ``staged`` to a free ``label`` name beside ``target`` (:func:`free_name`)."""
    kept = free_name(target, label, suffix)
    staged.rename(kept)
    return kept


_HELD: list[list[int]] = []
"""The stop signals noted by the :func:`held_stops` block in force (at most one: nested blocks
share it)."""


_IN_PLACE: list[bool] = []


def output_in_place(*, forget: bool = False) -> bool:
    """Whether a :func:`held_stops` block has put a finished output in place (since the last
    ``forget``: the CLI forgets at the start of every command)."""
    placed = bool(_IN_PLACE)
    if forget:
        _IN_PLACE.clear()
    return placed


@contextmanager
def held_stops() -> Iterator[Callable[[], bool]]:
    """Hold SIGINT and SIGTERM while the block runs; yield "has a stop signal come meanwhile?".

    A stop is noted, then handled by the previous handler when the block ends, so a swap is
    never cut in two. A stop after the block asked and went on is said on stderr, not raised.
    Nested blocks hold until the outermost ends; outside the main thread nothing is held.
    """
    if _HELD:
        came = _HELD[-1]
        yield lambda: bool(came)
        return
    if threading.current_thread() is not threading.main_thread():
        yield lambda: False
        return
    came = []
    went_on = [False]  # the block asked, no stop had come: it puts the new output in place

    def note(signum: int, frame: FrameType | None) -> None:
        came.append(signum)

    def stopped() -> bool:
        went_on[0] = went_on[0] or not came
        return bool(came)

    previous = {
        int(stop): signal.signal(stop, note)
        for stop in STOP_SIGNALS
        if signal.getsignal(stop) != signal.SIG_IGN  # an ignored signal stops nothing
    }
    _HELD.append(came)
    try:
        yield stopped
        if went_on[0]:
            _IN_PLACE.append(True)  # a finished output is in place: later stops come too late
    finally:
        _HELD.pop()
        for stop, handler in previous.items():
            signal.signal(stop, signal.SIG_DFL if handler is None else handler)
        if came and went_on[0]:  # it came after the block went on: too late to keep the old
            sys.stderr.write(
                "omnical: the stop came while the finished output was put in place: it is "
                "complete and kept; nothing left to stop\n"
            )
            came.clear()
        for first in came[:1]:  # the first decides, as it would have
            handler = previous[first]
            if callable(handler):
                handler(first, None)
            elif handler in {signal.SIG_DFL, None}:
                os.kill(os.getpid(), first)


def swap_into_place(new: Path, target: Path) -> None:
    """Put the complete output ``new`` at ``target``, replacing what was there.

    The earlier output is renamed to an ``old`` staging name first (put back by
    :func:`sweep_staging` if the process dies in between), then removed. Call inside
    :func:`held_stops`.

    Raises:
        OSError: A rename failed; ``target`` is then as it was.
    """
    aside = None
    if target.exists() or target.is_symlink():
        aside = target.with_name(f".{target.name}.omnical-old-{os.getpid()}-{secrets.token_hex(4)}")
        target.rename(aside)
    try:
        new.rename(target)
    except OSError:
        if aside is not None:
            aside.rename(target)
        raise
    if aside is not None:
        _remove(aside)


def renamed_in_message(err: BaseException, staged: Path, final: Path) -> BaseException:
    """``err`` with the staging path ``staged`` in its message (or file name) said as ``final``.

    A writer inside a staging directory names the hidden path; the user knows the final one.
    Only a message of one string and an ``OSError``'s file names are changed, in place.
    """
    hidden, shown = str(staged), str(final)
    if isinstance(err, OSError):
        for attr in ("filename", "filename2"):
            name = getattr(err, attr, None)
            if isinstance(name, str) and hidden in name:
                setattr(err, attr, name.replace(hidden, shown))
    if len(err.args) == 1 and isinstance(err.args[0], str) and hidden in err.args[0]:
        err.args = (err.args[0].replace(hidden, shown),)
    return err
