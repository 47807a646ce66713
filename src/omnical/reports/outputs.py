"""Output paths, checked before the work starts: nothing is destroyed by surprise.

Rules (the README's "bad input and interruptions"):

* A directory omnical writes into (``calibrate campaign --out``, ``demo --out``, ``evaluate
  --out``) must be absent, empty, or one omnical wrote before — recognised by the marker file
  :data:`MARKER` it leaves there. An earlier omnical output is replaced only with
  ``overwrite`` (a directory holding only the marker, left by a command that stopped before
  writing, counts as empty); a non-empty directory without the marker is never written into.
* A single file (``calibrate estimate --out factors.yaml`` and the side files named from it)
  must be absent, or — with ``overwrite`` — a file omnical wrote (its text names omnical).
* The check happens first, and proves the place writable (the marker is written then), so a
  long run never fails at its end on a read-only or full disk.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Final

from omnical.errors import OutputError

__all__ = [
    "MARKER",
    "claim_directory",
    "claim_files",
    "clear_in_claimed",
    "csv_with_header",
    "is_figure",
    "side_file",
]

MARKER: Final = ".omnical-output"
"""File that marks a directory as written by omnical (its content: what wrote it)."""

_SNIFF_BYTES = 4096


def _fail(path: Path, reason: str) -> OutputError:
    return OutputError(f"{path}: {reason}")


def claim_directory(path: str | Path, *, overwrite: bool, writer: str) -> Path:
    """Make ``path`` ready to receive an omnical output, or refuse before any work.

    Args:
        path: the output directory.
        overwrite: replace an earlier omnical output there.
        writer: what will write it (``omnical demo``), recorded in the marker.

    Returns:
        The directory (created, marked).

    Raises:
        OutputError: a file is in the way, the directory holds someone else's files, an earlier
            output is there without ``overwrite``, or the directory cannot be written.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise _fail(out, "exists and is not a directory; choose a directory name")
    if out.is_dir():
        try:
            entries = [e.name for e in out.iterdir()]
        except OSError as err:
            raise _fail(out, f"cannot list: {err.strerror or err}") from None
        if entries and MARKER not in entries:
            raise _fail(
                out,
                "is not empty and was not written by omnical; nothing there is replaced — "
                "choose a new or empty directory",
            )
        # A directory holding nothing but the marker is a claim whose command stopped before
        # writing anything (a typo in an input): as good as empty, no --overwrite needed.
        if MARKER in entries and entries != [MARKER] and not overwrite:
            raise _fail(out, "holds an earlier omnical output; add --overwrite to replace it")
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / MARKER).write_text(f"written by {writer}\n", encoding="utf-8")
    except OSError as err:
        raise _fail(out, f"cannot write: {err.strerror or err}") from None
    return out


def _probe(directory: Path) -> None:
    """Create ``directory`` and prove it writable (a read-only file system stops root too)."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=".omnical-probe-", dir=directory)
        os.close(fd)
        Path(name).unlink()
    except OSError as err:
        raise _fail(directory, f"cannot write: {err.strerror or err}") from None


def _is_omnical_file(path: Path) -> bool:
    try:
        with path.open("rb") as stream:
            head = stream.read(_SNIFF_BYTES)
    except OSError:
        return False
    return b"omnical" in head.lower()


def is_figure(path: Path) -> bool:
    """A PNG omnical's figure writers made (matplotlib names itself in the PNG's text chunk)."""
    try:
        with path.open("rb") as stream:
            head = stream.read(_SNIFF_BYTES)
    except OSError:
        return False
    return head.startswith(b"\x89PNG") and b"Matplotlib" in head


def csv_with_header(header: str) -> Callable[[Path], bool]:
    """A recogniser of the CSV files omnical writes with this exact first line."""

    def recognise(path: Path) -> bool:
        try:
            with path.open("r", encoding="utf-8", errors="replace") as stream:
                return stream.readline().rstrip("\r\n") == header
        except OSError:
            return False

    return recognise


def claim_files(
    paths: Sequence[str | Path],
    *,
    overwrite: bool,
    recognise: Callable[[Path], bool] | None = None,
) -> list[Path]:
    """Check single output files before the work: absent, or omnical's own with ``overwrite``.

    The parent directories are created and proved writable. A file is omnical's when
    ``recognise`` says so (default: its first 4 KiB name omnical; PNGs: :func:`is_figure`).
    A symbolic link is followed: the file it points to is checked and returned (a writer that
    replaces the file then keeps the link a link).

    Returns:
        The paths to write, links resolved.

    Raises:
        OutputError: a path is a directory, exists without ``overwrite``, exists and was not
            written by omnical, is a link that loops, or its directory cannot be written.
    """
    claimed = []
    for raw in paths:
        path = _followed(Path(raw))
        if path.is_dir():
            raise _fail(path, "is a directory; give a file name")
        if path.exists():
            ours = recognise or (is_figure if path.suffix.lower() == ".png" else _is_omnical_file)
            if not ours(path):
                raise _fail(path, "exists and was not written by omnical; it is not replaced")
            if not overwrite:
                raise _fail(path, "exists; add --overwrite to replace it")
        _probe(path.parent)
        claimed.append(path)
    return claimed


def _followed(path: Path) -> Path:
    """``path``, or the file a symbolic link there points to (which may not exist yet)."""
    if not path.is_symlink():
        return path
    try:
        return path.resolve()
    except (RuntimeError, OSError):  # a loop: RuntimeError before Python 3.13, then OSError
        raise _fail(path, "is a symbolic link that loops; give a file name") from None


def clear_in_claimed(directory: Path, *names: str) -> None:
    """Remove earlier outputs ``names`` inside a directory omnical claimed (:data:`MARKER`).

    A claimed directory is omnical's own, so what an earlier run left there (a bag of an older
    format, a figure) is replaced without asking again; outside one nothing is removed.

    Raises:
        OutputError: ``directory`` is not claimed, or a path cannot be removed.
    """
    if not (directory / MARKER).is_file():
        raise _fail(directory, "was not claimed as an omnical output directory")
    for name in names:
        target = directory / name
        try:
            if target.is_dir() and not target.is_symlink():
                shutil.rmtree(target)
            elif target.exists() or target.is_symlink():
                target.unlink()
        except OSError as err:
            raise _fail(target, f"cannot replace: {err.strerror or err}") from None


def side_file(main: str | Path, suffix: str) -> Path:
    """A file named from the main output: ``calib/rosy.yaml`` + ``.h`` → ``calib/rosy.h``."""
    path = Path(main)
    return path.with_name(path.stem + suffix)
