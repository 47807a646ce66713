"""Outputs, checked before the work and written whole: nothing is destroyed by surprise.

Replaced only where omnical's marker says so, never through a link or a device; staged beside
their place (:mod:`omnical.bags.staging`), swapped in at the end or kept as ``.partial``.
"""

from __future__ import annotations

import os
import shutil
import stat
import struct
import tempfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Final

from omnical.bags.staging import (
    held_stops,
    inside_open_staging,
    keep_beside,
    make_parents,
    make_staging,
    missing_parents,
    open_staging,
    remove_empty,
    renamed_in_message,
    swap_into_place,
    sweep_staging,
)
from omnical.errors import MACHINE_ERRNOS, OmnicalError, OutputError

__all__ = [
    "FIGURE_SOFTWARE",
    "MANIFEST",
    "MARKER",
    "DirectoryOutput",
    "FileOutputs",
    "Notify",
    "claim_directory",
    "claim_files",
    "csv_with_header",
    "is_figure",
    "is_marked",
    "side_file",
    "stage_files",
]

MARKER: Final = ".omnical-output"
"""File that marks a directory as written by omnical (its content: ``written by omnical ...``)."""

MANIFEST: Final = ".omnical-files"
"""File beside single outputs (``factors.yaml``, a map) listing those omnical wrote: one line
``MTIME_NS SIZE NAME`` each; a file is omnical's while it is as omnical left it."""

FIGURE_SOFTWARE: Final = "omnical"
"""The PNG ``Software`` text record of omnical's figures (:func:`is_figure`)."""

Notify = Callable[[str], None]
"""Receives one line saying what was kept where (the CLI prints it on stderr)."""

_MARKER_TEXT: Final = b"written by omnical"
_SNIFF_BYTES: Final = 4096
_MANIFEST_MAX_BYTES: Final = 1 << 20
_PNG_SIGNATURE: Final = b"\x89PNG\r\n\x1a\n"


def _fail(path: Path, reason: str) -> OutputError:
    return OutputError(f"{path}: {reason}")


def _lstat(path: Path) -> os.stat_result | None:
    """``path``'s own status (a link's, not its target's), None if nothing is there."""
    try:
        return path.lstat()
    except FileNotFoundError:
        return None
    except OSError as err:
        raise _fail(path, f"cannot check it: {err.strerror or err}") from None


def _head(path: Path, limit: int) -> bytes | None:
    """The first ``limit`` bytes of a regular file; None for anything else (a link, a device,
    a pipe: never read, /dev/zero has no end) or an unreadable file."""
    try:
        fd = os.open(
            path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
        )
    except OSError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        return os.read(fd, limit)
    except OSError:
        return None
    finally:
        os.close(fd)


def is_marked(directory: Path) -> bool:
    """Whether ``directory`` holds omnical's :data:`MARKER` (a regular file saying so)."""
    head = _head(directory / MARKER, _SNIFF_BYTES)
    return head is not None and head.startswith(_MARKER_TEXT)


def is_figure(path: Path) -> bool:
    """A PNG omnical's figure writers made: its ``Software`` text record is omnical's."""
    head = _head(path, _SNIFF_BYTES)
    if head is None or not head.startswith(_PNG_SIGNATURE):
        return False
    pos = len(_PNG_SIGNATURE)
    while pos + 8 <= len(head):
        (length,) = struct.unpack_from(">I", head, pos)
        kind = head[pos + 4 : pos + 8]
        if kind in {b"IDAT", b"IEND"}:
            return False
        body = head[pos + 8 : pos + 8 + length]
        if kind == b"tEXt" and body.partition(b"\0")[::2] == (
            b"Software",
            FIGURE_SOFTWARE.encode(),
        ):
            return True
        pos += 12 + length
    return False


def csv_with_header(header: str) -> Callable[[Path], bool]:
    """A recogniser of the CSV files omnical writes with this exact first line."""
    expected = header.encode("utf-8")

    def recognise(path: Path) -> bool:
        head = _head(path, len(expected) + 2)
        return head is not None and head.splitlines()[:1] == [expected]

    return recognise


def _manifest(directory: Path) -> dict[str, tuple[int, int]]:
    """The files omnical wrote in ``directory`` (:data:`MANIFEST`): name → (mtime ns, size)."""
    head = _head(directory / MANIFEST, _MANIFEST_MAX_BYTES)
    entries: dict[str, tuple[int, int]] = {}
    for line in (head or b"").decode("utf-8", "replace").splitlines():
        mtime, _, rest = line.partition(" ")
        size, _, name = rest.partition(" ")
        if mtime.isdigit() and size.isdigit() and name:
            entries[name] = (int(mtime), int(size))
    return entries


def _in_manifest(path: Path) -> bool:
    """Whether ``path`` is a file omnical wrote, as it left it (:data:`MANIFEST`)."""
    entry = _manifest(path.parent).get(path.name)
    status = _lstat(path)
    return (
        entry is not None
        and status is not None
        and stat.S_ISREG(status.st_mode)
        and entry == (status.st_mtime_ns, status.st_size)
    )


def _record(directory: Path, names: Sequence[str]) -> None:
    """Add ``names`` (files just put in ``directory``) to its :data:`MANIFEST`; entries of files
    that are gone or changed are dropped. Written whole (a temporary file renamed)."""
    entries = _manifest(directory)
    for name in [*entries, *names]:
        status = _lstat(directory / name)
        if status is None or not stat.S_ISREG(status.st_mode) or "\n" in name:
            entries.pop(name, None)
        elif name in names:
            entries[name] = (status.st_mtime_ns, status.st_size)
        elif entries[name] != (status.st_mtime_ns, status.st_size):
            entries.pop(name)
    text = "".join(f"{m} {s} {n}\n" for n, (m, s) in sorted(entries.items()))
    fd, temporary = tempfile.mkstemp(prefix=f".{MANIFEST}.", dir=directory)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as stream:
            stream.write(text)
        Path(temporary).replace(directory / MANIFEST)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def _default_recognise(path: Path) -> bool:
    return _in_manifest(path) or (path.suffix.lower() == ".png" and is_figure(path))


def _probe(directory: Path, *, create: bool) -> None:
    """Prove ``directory`` writable (a read-only file system stops root too): created first
    when ``create``, else the nearest existing ancestor is tried (nothing left behind)."""
    place = directory
    try:
        if create:
            make_parents(directory)
        else:
            while not place.exists() and place != place.parent:
                place = place.parent
            if not place.is_dir():
                raise _fail(directory, f"cannot write: {place} is not a directory")
        Path(tempfile.mkdtemp(prefix=".omnical-probe-", dir=place)).rmdir()
    except OSError as err:
        if isinstance(err, OmnicalError):
            raise
        raise _fail(directory, f"cannot write: {err.strerror or err}") from None


def _holds_output(staging: Path) -> bool:
    """Whether a staging directory holds a file besides the marker (worth keeping)."""
    try:
        return any(
            not p.is_dir() and p != staging / MARKER and p.name != MANIFEST
            for p in staging.rglob("*")
        )
    except OSError:
        return True  # when in doubt, keep


def _check_directory(out: Path, *, overwrite: bool) -> None:
    """Refuse ``out`` unless absent, empty, or an earlier omnical output (with ``overwrite``)."""
    if out.name in {"", ".", ".."}:
        raise _fail(out, "give the output directory by name (it is replaced whole)")
    status = _lstat(out)
    if status is None:
        return
    if stat.S_ISLNK(status.st_mode):
        raise _fail(
            out,
            "is a symbolic link; omnical does not write through links — give the directory itself",
        )
    if not stat.S_ISDIR(status.st_mode):
        raise _fail(out, "exists and is not a directory; choose a directory name")
    try:
        entries = [e.name for e in out.iterdir()]
    except OSError as err:
        raise _fail(out, f"cannot list: {err.strerror or err}") from None
    if not entries:
        return
    if not is_marked(out):
        raise _fail(
            out,
            "is not empty and was not written by omnical; nothing there is replaced — "
            "choose a new or empty directory",
        )
    # A directory holding nothing but the marker is a claim whose command stopped before
    # writing anything (an older omnical): as good as empty, no --overwrite needed.
    if entries != [MARKER] and not overwrite:
        raise _fail(out, "holds an earlier omnical output; add --overwrite to replace it")


def _keep_killed(named: Path, partial_of: Path, notify: Notify | None) -> None:
    """Keep what killed omnical commands were writing as ``named`` under a ``.partial`` name
    of ``partial_of`` (removed if it holds nothing)."""
    for staging in sweep_staging(named):
        if staging.kind != "out":
            continue
        if not _holds_output(staging.path):
            shutil.rmtree(staging.path, ignore_errors=True)
            continue
        kept = keep_beside(staging.path, partial_of)
        if notify is not None:
            notify(f"an omnical command writing {named} was killed; what it wrote is in {kept}")


def _kept_line(kept: Path, earlier: str) -> str:
    return f"kept the unfinished output in {kept}; {earlier}"


def _failed(
    exc: BaseException,
    staging: Path,
    final: Path,
    kept: Path | None,
    earlier: str,
    notify: Notify | None,
) -> BaseException | None:
    """What to raise for ``exc`` raised while writing in ``staging`` (None: ``exc`` itself).

    The hidden staging path is said as the ``final`` one. A file system refusing the write
    (:data:`~omnical.errors.MACHINE_ERRNOS`) becomes an :class:`OutputError` naming
    the file (or the output); an omnical error says where the rest is kept, in its one line;
    anything else (an interruption, a bug) is raised as it is, after a line saying so.
    """
    renamed_in_message(exc, staging, final)
    where = "" if kept is None else f"; what was written is kept in {kept}, {earlier}"
    if isinstance(exc, OSError) and not isinstance(exc, OmnicalError):
        if exc.errno in MACHINE_ERRNOS:
            name = exc.filename if isinstance(exc.filename, str) else str(final)
            return OutputError(f"{name}: cannot write: {exc.strerror or exc}{where}")
    elif isinstance(exc, OmnicalError) and len(exc.args) == 1 and isinstance(exc.args[0], str):
        exc.args = (exc.args[0] + where,)
        return None
    if kept is not None and notify is not None:
        notify(_kept_line(kept, earlier))
    return None


def _earlier(target: Path) -> str:
    """What became of the earlier output at ``target`` when the new one is kept aside."""
    if target.exists() or target.is_symlink():
        return f"the earlier {target} was not touched"
    return f"nothing was written at {target}"


class DirectoryOutput:
    """An output directory checked before the work (:func:`claim_directory`), written whole.

    :meth:`staged` yields the staging directory to write in; at its end the directory is
    swapped in whole (the earlier one removed), or — on any exception, or a stop signal that
    came while it was written — kept as ``OUT.partial`` (removed if it holds nothing), the
    earlier output untouched. Inside an output already being staged it is written in place.
    """

    def __init__(self, path: Path, *, overwrite: bool, writer: str, nested: bool) -> None:
        self.path = path
        self.overwrite = overwrite
        self.writer = writer
        self.nested = nested
        self.staging: Path | None = None
        self.kept_at: Path | None = None
        """Where an unfinished output went (``OUT.partial``), if it was kept."""

    def final(self, path: Path) -> Path:
        """Where ``path`` (written in the staging directory) is once swapped in."""
        if self.staging is not None and (path == self.staging or self.staging in path.parents):
            return self.path / path.relative_to(self.staging)
        return path

    @contextmanager
    def staged(self, notify: Notify | None = None, *, keep: bool = False) -> Iterator[Path]:
        """Write the output in the block, into the yielded directory (see the class).

        ``keep``: keep it as ``.partial`` at the end too (what a stopped command had made).

        Raises:
            OutputError: The place cannot be written, was taken meanwhile (the new output is
                then kept as ``.partial``), or the disk refused a write (naming the file).
        """
        if self.nested:
            try:
                self.path.mkdir(parents=True, exist_ok=True)
                if not is_marked(self.path):
                    (self.path / MARKER).write_text(f"written by {self.writer}\n", encoding="utf-8")
            except OSError as err:
                raise _fail(self.path, f"cannot write: {err.strerror or err}") from None
            yield self.path
            return
        created = missing_parents(self.path)
        staging = make_staging(self.path, "out")
        self.staging = staging
        try:
            with open_staging(staging):
                (staging / MARKER).write_text(f"written by {self.writer}\n", encoding="utf-8")
                yield staging
        except BaseException as exc:
            kept = None
            if _holds_output(staging):
                kept = self.kept_at = keep_beside(staging, self.path)
            else:
                shutil.rmtree(staging, ignore_errors=True)
                remove_empty(created)
            earlier = _earlier(self.path)
            raise (_failed(exc, staging, self.path, kept, earlier, notify) or exc) from None
        if keep:
            self.kept_at = keep_beside(staging, self.path)
            return
        self._commit(staging, notify)

    def _commit(self, staging: Path, notify: Notify | None) -> None:
        with held_stops() as stopped:
            try:
                _check_directory(self.path, overwrite=self.overwrite)  # changed meanwhile?
            except OutputError as err:
                self.kept_at = keep_beside(staging, self.path)
                raise OutputError(f"{err}; the new output is kept in {self.kept_at}") from None
            if stopped():  # a stop signal came while the output was written: keep the earlier
                self.kept_at = keep_beside(staging, self.path)
                if notify is not None:
                    notify(_kept_line(self.kept_at, _earlier(self.path)))
                return
            try:
                swap_into_place(staging, self.path)
            except OSError as err:
                self.kept_at = keep_beside(staging, self.path)
                msg = f"{self.path}: cannot put the new output in place ({err.strerror or err}); "
                raise OutputError(msg + f"it is kept in {self.kept_at}") from None


def claim_directory(
    path: str | Path, *, overwrite: bool, writer: str, notify: Notify | None = None
) -> DirectoryOutput:
    """Check, before any work, that ``path`` may receive an omnical output; nothing is created.

    Args:
        path: the output directory.
        overwrite: replace an earlier omnical output there.
        writer: what will write it (``omnical demo``), recorded in its :data:`MARKER`.
        notify: told when what a killed omnical left there is kept as ``.partial``.

    Returns:
        The output, to write with :meth:`DirectoryOutput.staged`.

    Raises:
        OutputError: a file or a link is in the way, the directory holds someone else's files,
            an earlier output is there without ``overwrite``, or the place cannot be written.
    """
    out = Path(path)
    if inside_open_staging(out):
        return DirectoryOutput(out, overwrite=True, writer=writer, nested=True)
    _keep_killed(out, out, notify)
    _check_directory(out, overwrite=overwrite)
    _probe(out, create=False)
    return DirectoryOutput(out, overwrite=overwrite, writer=writer, nested=False)


def _check_file(path: Path, *, overwrite: bool, recognise: Callable[[Path], bool]) -> None:
    status = _lstat(path)
    if status is None:
        return
    if stat.S_ISDIR(status.st_mode):
        raise _fail(path, "is a directory; give a file name")
    if not stat.S_ISREG(status.st_mode):
        raise _fail(path, "is not a regular file (a device, a pipe, a socket); give a file name")
    if not recognise(path):
        raise _fail(path, "exists and was not written by omnical; it is not replaced")
    if not overwrite:
        raise _fail(path, "exists; add --overwrite to replace it")


def _through_link(path: Path) -> Path:
    """``path``, or the new file a symbolic link there points to; an existing one is refused."""
    if not path.is_symlink():
        return path
    try:
        target = path.resolve()
    except (RuntimeError, OSError):  # a loop: RuntimeError before Python 3.13, then OSError
        raise _fail(path, "is a symbolic link that loops; give a file name") from None
    if target.exists() or target.is_symlink():
        raise _fail(
            path,
            f"is a symbolic link to {target}; omnical does not replace a file through a link — "
            "remove the link or give the file itself",
        )
    return target


def claim_files(
    paths: Sequence[str | Path],
    *,
    overwrite: bool,
    recognise: Callable[[Path], bool] | None = None,
) -> list[Path]:
    """Check single output files before the work: absent, or omnical's own with ``overwrite``.

    A file is omnical's when ``recognise`` says so (default: :data:`MANIFEST` lists it as it
    is; a PNG: :func:`is_figure`); only the first bytes of a regular file are ever read. A
    symbolic link is written through only to a file that does not exist yet (the link stays a
    link); a link to an existing file, a device, a pipe or a directory is refused. The parent
    directories are created and proved writable.

    Returns:
        The paths to write, links resolved.

    Raises:
        OutputError: one line naming the path and the reason.
    """
    claimed = []
    for raw in paths:
        path = _through_link(Path(raw))
        _check_file(path, overwrite=overwrite, recognise=recognise or _default_recognise)
        _probe(path.parent, create=True)
        claimed.append(path)
    return claimed


class FileOutputs:
    """Single files of one directory (:func:`stage_files`), written whole, side by side."""

    def __init__(
        self, paths: list[Path], *, overwrite: bool, recognise: Callable[[Path], bool]
    ) -> None:
        self.paths = paths
        self.overwrite = overwrite
        self.recognise = recognise
        self.kept_at: Path | None = None
        """Where unfinished files went (a ``STEM.partial`` directory), if they were kept."""

    @contextmanager
    def staged(self, notify: Notify | None = None) -> Iterator[list[Path]]:
        """Write the files in the block, at the yielded paths (in a staging directory).

        At its end each file written replaces its earlier one (one rename each, stop signals
        held) and is listed in :data:`MANIFEST`; on an exception or a stop signal the staging
        directory is kept as ``STEM.partial`` (removed if empty), the earlier files untouched.
        """
        first = self.paths[0]
        staging = make_staging(first, "out")
        staged = [staging / p.name for p in self.paths]
        try:
            with open_staging(staging):
                yield staged
        except BaseException as exc:
            kept = None
            if _holds_output(staging):
                kept = self.kept_at = keep_beside(staging, first.with_suffix(""))
            else:
                shutil.rmtree(staging, ignore_errors=True)
            earlier = self._earlier()
            raise (_failed(exc, staging, first.parent, kept, earlier, notify) or exc) from None
        with held_stops() as stopped:
            try:
                for path in self.paths:  # changed meanwhile?
                    _check_file(path, overwrite=self.overwrite, recognise=self.recognise)
                if stopped():  # a stop signal came while they were written: keep the earlier
                    self.kept_at = keep_beside(staging, first.with_suffix(""))
                    if notify is not None:
                        notify(_kept_line(self.kept_at, self._earlier()))
                    return
                for new, path in zip(staged, self.paths, strict=True):
                    if new.exists():
                        new.replace(path)
                _record(first.parent, [p.name for p in self.paths if p.exists()])
            except OSError as err:
                self.kept_at = keep_beside(staging, first.with_suffix(""))
                reason = str(err) if isinstance(err, OmnicalError) else f"{first}: {err}"
                raise OutputError(f"{reason}; the new files are kept in {self.kept_at}") from None
        shutil.rmtree(staging, ignore_errors=True)

    def _earlier(self) -> str:
        if any(p.exists() for p in self.paths):
            return "the earlier files were not touched"
        return f"nothing was written at {self.paths[0]}"


def stage_files(
    paths: Sequence[str | Path],
    *,
    overwrite: bool,
    recognise: Callable[[Path], bool] | None = None,
    notify: Notify | None = None,
) -> FileOutputs:
    """:func:`claim_files`, for files written together in one directory by :meth:`FileOutputs.
    staged` (a factors file and its side files, a map and its image). ``notify`` is told when
    what a killed omnical left there is kept as ``.partial``."""
    claimed = claim_files(paths, overwrite=overwrite, recognise=recognise)
    for given, path in zip(paths, claimed, strict=True):
        if Path(given).name != path.name or path.parent != claimed[0].parent:
            msg = (
                f"{given}: is a symbolic link; files written together are not written through links"
            )
            raise OutputError(msg)
    _keep_killed(claimed[0], claimed[0].with_suffix(""), notify)
    return FileOutputs(claimed, overwrite=overwrite, recognise=recognise or _default_recognise)


def side_file(main: str | Path, suffix: str) -> Path:
    """A file named from the main output: ``calib/rosy.yaml`` + ``.h`` → ``calib/rosy.h``."""
    path = Path(main)
    return path.with_name(path.stem + suffix)
