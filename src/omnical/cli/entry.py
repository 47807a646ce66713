"""The ``omnical`` console script: stop signals handled from the first instant, then the app.

Importing typer and the commands takes a tenth of a second or more; a Ctrl-C or SIGTERM then
ends with one line and the shell's status (130 / 143) instead of a traceback.
"""

from __future__ import annotations

import signal
import sys
from itertools import pairwise
from pathlib import Path
from types import FrameType

__all__ = ["main"]


_SAID: list[int] = []
"""The stop signal already said (a stop lost in a callback is delivered again, said once)."""


_IMPORTING: list[bool] = [True]
"""While the app is imported a stop is only noted (raised in an import's weak-reference
callback, CPython would drop it), and acted on once the import is done."""


def _stop_before_start(signum: int, frame: FrameType | None) -> None:
    if not _SAID:
        word = "terminated" if signum == signal.SIGTERM else "interrupted"
        print(f"omnical: {word}", file=sys.stderr)
        _SAID.append(signum)
    if not _IMPORTING:
        raise SystemExit(128 + signum)


def _deliver_lost_stop(unraisable: sys.UnraisableHookArgs) -> None:
    """A stop raised while an import's weak-reference callback ran is printed as "Exception
    ignored" and dropped by CPython: deliver it again, from a thread, once this hook returns."""
    if isinstance(unraisable.exc_value, SystemExit) and _SAID:
        import _thread
        import threading

        later = threading.Timer(0.005, _thread.interrupt_main, args=(_SAID[0],))
        later.daemon = True
        later.start()
        return
    sys.__unraisablehook__(unraisable)


def main() -> None:
    """Console-script entry point."""
    sys.unraisablehook = _deliver_lost_stop
    signal.signal(signal.SIGTERM, _stop_before_start)
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        signal.signal(signal.SIGINT, _stop_before_start)
    # the shell expands ~ in "--out ~/x" but not in "--out=~/x"
    sys.argv[1:] = [_expand_home(arg) for arg in sys.argv[1:]]
    if _on_ros2(sys.argv[1:]) and not {"--help", "-h"} & set(sys.argv):
        _ros2_environment_first()
    from omnical.cli.main import main as run

    _IMPORTING.clear()
    if _SAID:  # a stop came while the app was imported: nothing has been done yet
        raise SystemExit(128 + _SAID[0])
    try:
        run()
    finally:  # the command is over: a stop during the interpreter's teardown has nothing left
        # to stop (Python would die of it, its handlers gone, the output long in place)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def _on_ros2(args: list[str]) -> bool:
    """``omnical ros2 ...`` or a command with ``--robot ros2``."""
    after_robot = (b for a, b in pairwise(args) if a == "--robot")
    return args[:1] == ["ros2"] or "--robot=ros2" in args or "ros2" in after_robot


def _ros2_environment_first() -> None:
    """``omnical ros2 ...`` and ``--robot ros2``: re-execute for the ROS 2 wheels' library path
    before importing the app (the command would, after all its imports and perhaps after its
    first output, e.g. ``--monitor``'s line; docs/ros2.md); its errors are the command's to
    report."""
    import contextlib

    from omnical.errors import OmnicalError
    from omnical.ros2.runtime import ensure_ros_environment

    with contextlib.suppress(OmnicalError):  # said by the command, in one line
        ensure_ros_environment()


def _expand_home(arg: str) -> str:
    """``--opt=~/x`` → ``--opt=/home/me/x`` and ``-o~/x`` → ``-o/home/me/x``, as the shell
    does for a separate word; a quoted ``'~/x'`` too (a directory named ``~`` is never meant)."""
    if arg == "~" or arg.startswith("~/"):
        return str(Path(arg).expanduser())
    option, equals, value = arg.partition("=")
    if option.startswith("--") and equals and value.startswith("~"):
        return f"{option}={Path(value).expanduser()}"
    if len(arg) > 2 and arg[0] == "-" and arg[1] != "-" and arg[2] == "~":
        return f"{arg[:2]}{Path(arg[2:]).expanduser()}"
    return arg
