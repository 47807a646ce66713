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
itself.
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
_HEADER = struct.Struct("<Q")
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

    def persistent_id(self, obj: Any) -> Any:
        if self.shared and isinstance(obj, self.shared):
            handed = cast("Shared", obj)
            self.files.append(handed.fileno())
            return (len(self.files) - 1, type(obj), handed.handover())
        return None


class _Unpickler(pickle.Unpickler):
    def __init__(self, file: io.BytesIO, files: list[int]) -> None:
        super().__init__(file)
        self.files = files
        self.adopted: set[int] = set()

    def persistent_load(self, pid: Any) -> Any:
        index, kind, state = pid
        self.adopted.add(index)
        return kind.adopt(self.files[index], state)


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
    signal.pthread_sigmask(signal.SIG_SETMASK, held)
    theirs.close()
    return Child(pid, ours)


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
        pickler.dump(work())
        data = buffer.getvalue()
        socket.send_fds(theirs, [_HEADER.pack(len(data))], pickler.files)
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
    """The child's pickled result and the files that came with it (b"" if none came)."""
    header, files, _, _ = socket.recv_fds(channel, _HEADER.size, _MAX_FILES)
    while header and len(header) < _HEADER.size:
        more = channel.recv(_HEADER.size - len(header))
        if not more:
            return b"", files
        header += more
    if not header:
        return b"", files
    (size,) = _HEADER.unpack(header)
    data = bytearray()
    while len(data) < size:
        chunk = channel.recv(min(size - len(data), 1 << 20))
        if not chunk:
            return b"", files
        data += chunk
    return bytes(data), files


def collect(child: Child) -> Any:
    """The child's result (None if it failed); the child has ended then."""
    data, files = _receive(child.channel)  # interrupted: reap() ends the child
    _, status = os.waitpid(child.pid, 0)
    child.pid = 0
    adopted: set[int] = set()
    try:
        if status != 0 or not data:
            return None
        unpickler = _Unpickler(io.BytesIO(data), files)
        try:
            return unpickler.load()
        finally:
            adopted = unpickler.adopted
    finally:
        for index, fd in enumerate(files):
            if index not in adopted:
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
