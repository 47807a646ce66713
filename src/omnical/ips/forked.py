"""Work in a forked process (Linux, ``os.fork``), its result sent back pickled, with the open
files it holds: what the second core of ``omnical locate`` runs (the bag read while this
process loads the compiled solver; half the hedgehogs' noise models learnt).

The child has everything this process had at the fork. Its result comes back over a Unix
socket; objects of the ``shared`` types in it (:class:`Shared`: a file on disk, such as
:class:`omnical.ips.windowed.Spill`) travel as their open file (``SCM_RIGHTS``), adopted here,
so a temporary file the child made outlives it. The child writes nothing to the terminal, takes
Ctrl-C and SIGTERM in their default action (it ends at once, silently: this process reports the
interrupt and reaps it), dies with its parent (``PR_SET_PDEATHSIG``) and leaves by
``os._exit`` whatever happens. A child that fails hands back None: the caller does the work
itself. A short-lived caller may freeze its objects out of garbage collection first
(``gc.freeze``, as ``omnical locate`` does): a collection in either process would otherwise
copy the pages of every object it scans.
"""

from __future__ import annotations

import contextlib
import io
import os
import pickle
import signal
import socket
import struct
import sys
import warnings
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any, NoReturn, Protocol, cast

__all__ = ["Child", "Shared", "collect", "fork", "reap"]

_STOPS = {signal.SIGINT, signal.SIGTERM}
_HEADER = struct.Struct("<QQ")  # bytes of the pickle, files sent
_MAX_FILES = 16


class Shared(Protocol):
    """An object whose state is an open file and a few picklable values."""

    def fileno(self) -> int:
        """The file's descriptor."""
        ...

    def handover(self) -> object:
        """The rest of the state, picklable."""
        ...

    @classmethod
    def adopt(cls, fd: int, state: Any) -> Shared:
        """The object again, from its file (now owned) and :meth:`handover`'s state."""
        ...


@dataclass
class Child:
    """A forked process at work (:func:`fork`)."""

    pid: int
    """0 once reaped."""
    channel: socket.socket
    """This end of the socket its result comes through."""


class _Pickler(pickle.Pickler):
    def __init__(self, file: io.BytesIO, shared: tuple[type, ...]) -> None:
        super().__init__(file, protocol=pickle.HIGHEST_PROTOCOL)
        self.shared = shared
        self.files: list[int] = []
        self._index: dict[int, int] = {}  # id → index: an object met twice is sent once

    def persistent_id(self, obj: Any) -> Any:
        if self.shared and isinstance(obj, self.shared):
            handed = cast("Shared", obj)
            if id(obj) not in self._index:
                self._index[id(obj)] = len(self.files)
                self.files.append(handed.fileno())
            return (self._index[id(obj)], type(obj), handed.handover())
        return None


class _Unpickler(pickle.Unpickler):
    def __init__(self, file: io.BytesIO, files: list[int]) -> None:
        super().__init__(file)
        self.files = files
        self.adopted: dict[int, object] = {}

    def persistent_load(self, pid: Any) -> Any:
        index, kind, state = pid
        if index not in self.adopted:
            self.adopted[index] = kind.adopt(self.files[index], state)
        return self.adopted[index]


def fork(work: Callable[[], object], *, shared: tuple[type, ...] = ()) -> Child:
    """Run ``work`` in a forked process; its result comes back with :func:`collect`, the
    ``shared`` objects in it (:class:`Shared`) as their open files."""
    ours, theirs = socket.socketpair()
    parent = os.getpid()
    held = signal.pthread_sigmask(signal.SIG_BLOCK, _STOPS)
    try:
        pid = os.fork()
    except BaseException:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
        ours.close()
        theirs.close()
        raise
    if pid == 0:  # pragma: no cover - the child (coverage does not follow it)
        _child(work, shared, ours, theirs, held, parent)
    child = Child(pid, ours)
    try:
        theirs.close()
        # a Ctrl-C held during the fork arrives here: the child is ended, not left behind
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
    except BaseException:
        reap(child)
        raise
    return child


def _child(
    work: Callable[[], object],
    shared: tuple[type, ...],
    ours: socket.socket,
    theirs: socket.socket,
    held: Collection[int],
    parent: int,
) -> NoReturn:  # pragma: no cover - the child
    status = 1
    try:
        ours.close()
        # nothing written to the terminal: a print or warning would take the console's lock,
        # which a thread of the parent (the CLI's spinner) may have held at the fork
        sys.stdout = sys.stderr = open(os.devnull, "w")  # noqa: SIM115, PTH123 - until os._exit
        warnings.simplefilter("ignore")
        for stop in _STOPS:
            signal.signal(stop, signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
        _die_with_parent()
        if os.getppid() != parent:  # the parent ended before the request took effect
            os._exit(1)
        buffer = io.BytesIO()
        pickler = _Pickler(buffer, shared)
        result = work()  # held until sent: a shared object freed would close its file
        pickler.dump(result)
        data = buffer.getvalue()
        if len(pickler.files) > _MAX_FILES:
            os._exit(1)
        header = _HEADER.pack(len(data), len(pickler.files))
        socket.send_fds(theirs, [header], pickler.files)
        theirs.sendall(data)
        status = 0
    except BaseException:
        pass
    finally:
        os._exit(status)


def _die_with_parent() -> None:  # pragma: no cover - the child
    """Ask Linux to end this process when its parent ends (PR_SET_PDEATHSIG)."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _receive(channel: socket.socket) -> tuple[bytes, list[int]]:
    """The child's pickled result and the files that came with it, not inherited by what
    this process runs (b"" if none came whole; the files are closed if interrupted)."""
    header, files, _, _ = socket.recv_fds(channel, _HEADER.size, _MAX_FILES)
    try:
        for fd in files:
            os.set_inheritable(fd, False)
        while header and len(header) < _HEADER.size:
            more = channel.recv(_HEADER.size - len(header))
            if not more:
                return b"", files
            header += more
        if not header:
            return b"", files
        size, count = _HEADER.unpack(header)
        if count != len(files):  # the kernel dropped some (MSG_CTRUNC): not usable
            return b"", files
        data = bytearray()
        while len(data) < size:
            chunk = channel.recv(min(size - len(data), 1 << 20))
            if not chunk:
                return b"", files
            data += chunk
    except BaseException:
        for fd in files:
            os.close(fd)
        raise
    return bytes(data), files


def collect(child: Child) -> Any:
    """The child's result (None if it failed); the child has ended then."""
    data, files = _receive(child.channel)  # interrupted: reap() ends the child
    _, status = os.waitpid(child.pid, 0)
    child.pid = 0
    unpickler = _Unpickler(io.BytesIO(data), files)
    try:
        if status != 0 or not data:
            return None
        try:
            return unpickler.load()
        except Exception:  # a result that does not rebuild: as if the child had failed
            for adopted in unpickler.adopted.values():
                close = getattr(adopted, "close", None)
                if callable(close):
                    close()
            return None
    finally:
        for index, fd in enumerate(files):
            if index not in unpickler.adopted:
                os.close(fd)


def reap(child: Child) -> None:
    """End the child if it still runs (interrupted) and close the socket."""
    if child.pid:
        with contextlib.suppress(ProcessLookupError):
            os.kill(child.pid, signal.SIGKILL)
        with contextlib.suppress(ChildProcessError):
            os.waitpid(child.pid, 0)
        child.pid = 0
    child.channel.close()
