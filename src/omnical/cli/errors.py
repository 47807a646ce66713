"""How the CLI reports failures: one line for a user's mistake, a traceback for a bug.

Exit status 2 for an :class:`~omnical.errors.OmnicalError` or a refused read or write, 4 for a
safety stop, 130 / 143 for Ctrl-C / SIGTERM, 1 and the traceback for anything else.
"""

from __future__ import annotations

import _thread
import errno
import signal
import sys
import threading
import time
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Final, NoReturn, TypeVar

import typer
from typer.exceptions import TyperException

from omnical.errors import MACHINE_ERRNOS, OmnicalError, SafetyStopError

__all__ = [
    "BUG_MESSAGE",
    "ENVIRONMENT_ERRNOS",
    "EXIT_BAD_INPUT",
    "EXIT_BUG",
    "EXIT_INTERRUPTED",
    "EXIT_NO_RESULT",
    "EXIT_SAFETY_STOP",
    "EXIT_TERMINATED",
    "Terminated",
    "environment_message",
    "handled_errors",
    "install_signal_handlers",
]

EXIT_BUG: Final = 1
EXIT_BAD_INPUT: Final = 2
EXIT_NO_RESULT: Final = 3
"""The command ran on good input but its result is not usable, and says why: fewer than half the
fixes usable (``locate``), no path (``plan``), a goal not reached (``navigate``), the footprint
against a wall (``simulate --world``). What was produced is kept."""
EXIT_SAFETY_STOP: Final = 4
"""A device the experiment needs went silent or sent garbage while the robot moved: the robot
was stopped at once and the run ended early (:class:`~omnical.errors.SafetyStopError`)."""
EXIT_INTERRUPTED: Final = 130
ENVIRONMENT_ERRNOS: Final = MACHINE_ERRNOS
EXIT_TERMINATED: Final = 143


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived: stop as on Ctrl-C (close and keep what was recorded), exit 143."""


_E = TypeVar("_E", bound=BaseException)


class _StoppedOutsideBody(SystemExit):
    """A stop before or after a command body: the process exits with the shell's status."""


_IN_BODY: list[bool] = []
"""Non-empty while a command body runs inside :func:`handled_errors`."""


def stop_behind(err: BaseException) -> SystemExit | None:
    """The stop outside a command body that ``err`` wraps (Python 3.11 wraps an exception
    raised in a class's ``__set_name__``, as while a module is imported, in a RuntimeError),
    or None."""
    return _in_chain(err, _StoppedOutsideBody)


_LOST_STOP_HOOK_RETURNED = threading.Event()
_LOST_STOP_HOOK_RETURNED.set()
_RESEND: list[signal.Signals] = []
"""The stops :func:`_deliver_lost_stop` sends again once it has returned (SIGTERM first)."""


def _resend_stop() -> None:
    """From a thread: once the hook has returned, send the main thread the stop again."""
    _LOST_STOP_HOOK_RETURNED.wait()
    time.sleep(0.005)  # past the hook's last bytecodes
    signum = max(_RESEND, default=signal.SIGINT)  # SIGTERM (15) over SIGINT (2)
    _RESEND.clear()
    _thread.interrupt_main(signum)


def _on_stop(signum: int, frame: FrameType | None) -> None:
    """SIGINT / SIGTERM: inside a command body, an exception every ``finally`` and recorder
    closes on; before it (typer parsing the command line, a command's imports) the command
    has done nothing yet: one line and the shell's status, without click's "Aborted"."""
    if not _LOST_STOP_HOOK_RETURNED.is_set():  # raised in there, it would be lost too
        _RESEND.append(signal.Signals(signum))
        return
    # not imported here: the stop may have come in the middle of importing it
    staging = sys.modules.get("omnical.bags.staging")
    in_place = getattr(staging, "output_in_place", None)
    if (
        _IN_BODY and in_place is not None and in_place()
    ):  # the command's output is in place: nothing to stop
        typer.echo(
            "omnical: the stop came after the output was in place: it is complete and kept",
            err=True,
        )
        return
    if not _IN_BODY:
        word = "terminated" if signum == signal.SIGTERM else "interrupted"
        typer.echo(f"omnical: {word}", err=True)
        raise _StoppedOutsideBody(128 + signum)
    if signum == signal.SIGTERM:
        raise Terminated
    raise KeyboardInterrupt


def _deliver_lost_stop(unraisable: sys.UnraisableHookArgs) -> None:
    """``sys.unraisablehook``: a stop CPython could not raise (the signal came while a garbage
    collector's callback or a finaliser ran: it prints "Exception ignored" and drops it) is
    delivered again, not printed; anything else goes to the default hook."""
    import signal as signals

    kind = unraisable.exc_type
    if kind is not None and issubclass(kind, KeyboardInterrupt | _StoppedOutsideBody):
        terminated = issubclass(kind, Terminated) or (
            issubclass(kind, _StoppedOutsideBody)
            and getattr(unraisable.exc_value, "code", None) == 128 + signals.SIGTERM
        )
        # delivered again, from a thread once this hook has returned (raised in here, it would
        # be lost too): it reaches the code that stops the robot and keeps what was recorded
        # (starting that thread takes a while on a loaded machine: a stop that comes while
        # this hook runs is sent again with it, see _on_stop)
        _LOST_STOP_HOOK_RETURNED.clear()
        try:
            _RESEND.append(signals.SIGTERM if terminated else signals.SIGINT)
            threading.Thread(target=_resend_stop, daemon=True).start()
        finally:
            _LOST_STOP_HOOK_RETURNED.set()
        return
    sys.__unraisablehook__(unraisable)


def install_signal_handlers() -> None:
    """SIGTERM stops a run the way Ctrl-C does (see :class:`Terminated`); a stop whose
    exception is lost (raised inside a garbage collector's callback) is delivered again."""
    signal.signal(signal.SIGTERM, _on_stop)
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:  # ignored stays ignored
        signal.signal(signal.SIGINT, _on_stop)
    sys.unraisablehook = _deliver_lost_stop


BUG_MESSAGE: Final = (
    "omnical: this is a bug in omnical, please report it with the traceback above "
    "and the command line"
)


@contextmanager
def handled_errors() -> Iterator[None]:
    """Run a command body and turn what it raises into a message and an exit status."""
    from omnical.bags.staging import output_in_place, remove_created_empty

    output_in_place(forget=True)
    remove_created_empty(forget_only=True)
    _IN_BODY.append(True)
    try:
        try:
            try:
                yield
            except BaseException:
                remove_created_empty()  # a failed command leaves no empty directory behind
                raise
        except SafetyStopError as err:
            typer.echo(f"omnical: error: {err}", err=True)
            if _twin_pause_can_explain(err):
                typer.echo(
                    "omnical: note: against `omnical twin serve` on a busy machine the twin "
                    "itself can pause this long (it warns when it does)",
                    err=True,
                )
            raise typer.Exit(EXIT_SAFETY_STOP) from None
        except OmnicalError as err:
            typer.echo(f"omnical: error: {err}", err=True)
            raise typer.Exit(EXIT_BAD_INPUT) from None
        except Terminated:
            typer.echo("omnical: terminated", err=True)
            raise typer.Exit(EXIT_TERMINATED) from None
        except KeyboardInterrupt:
            typer.echo("omnical: interrupted", err=True)
            raise typer.Exit(EXIT_INTERRUPTED) from None
        except (typer.Exit, typer.Abort, TyperException):
            raise  # typer's own control flow and usage errors
        except OSError as err:
            if err.errno not in ENVIRONMENT_ERRNOS:
                _report_bug()
            typer.echo(f"omnical: error: {environment_message(err)}", err=True)
            raise typer.Exit(EXIT_BAD_INPUT) from None
        except Exception as err:
            stop = _stop_in_chain(err)
            if stop is None:
                _report_bug()
            # a stop that came while a C extension was imported or called back into Python:
            # the extension turned it into its own error ("ImportError: initialization failed")
            terminated = isinstance(stop, Terminated)
            typer.echo(f"omnical: {'terminated' if terminated else 'interrupted'}", err=True)
            raise typer.Exit(EXIT_TERMINATED if terminated else EXIT_INTERRUPTED) from None
    finally:
        _IN_BODY.pop()  # a stop after the body: one line and the status (_on_stop)


def _stop_in_chain(err: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C or SIGTERM an exception was raised from or during, if any."""
    return _in_chain(err, KeyboardInterrupt)


def _in_chain(err: BaseException, kind: type[_E]) -> _E | None:
    """The first exception of ``kind`` in ``err``'s chain (itself, then cause or context)."""
    seen: set[int] = set()
    link: BaseException | None = err
    while link is not None and id(link) not in seen:
        if isinstance(link, kind):
            return link
        seen.add(id(link))
        link = link.__cause__ or link.__context__
    return None


def _report_bug() -> NoReturn:
    """The traceback of the exception being handled and the request to report it; exit 1."""
    traceback.print_exc()
    typer.echo(BUG_MESSAGE, err=True)
    raise typer.Exit(EXIT_BUG) from None


def environment_message(err: OSError) -> str:
    """One line for an :data:`ENVIRONMENT_ERRNOS` error: what failed, and where if known."""
    what = err.strerror or errno.errorcode.get(err.errno or 0, "I/O error")
    where = [str(name) for name in (err.filename, err.filename2) if name is not None]
    return f"{' → '.join(where)}: {what}" if where else what


def _twin_pause_can_explain(err: SafetyStopError) -> bool:
    """A silence of a vehicle controller on a pseudo-terminal (``omnical twin serve``, not a
    robot) with nothing or less than one 24-byte status frame received: a pause of the served
    twin's process looks exactly so (garbage, a failed port or a hedgehog do not)."""
    if "/dev/pts/" not in err.device or not err.device.startswith("vehicle controller"):
        return False
    if err.detail == "nothing received":
        return True
    count, _, rest = err.detail.partition(" bytes received, none valid")
    return not rest and count.isdigit() and int(count) < 24
