"""``omnical``: the typer app. One module per command; this one only assembles them.

Start-up is part of the interface: this module and the command modules import typer, the
standard library and :mod:`omnical.choices` only. numpy, scipy, matplotlib, rosbags, rich's
widgets and the omnical library are imported inside the command bodies, so ``omnical --help``
costs about what a bare typer app does (``bench/bench_startup.py`` measures it).
"""

from __future__ import annotations

import atexit
import gc
import os
import sys
import threading
from typing import NoReturn

import typer

from omnical.cli import (
    calibrate,
    demo,
    evaluate,
    export,
    info,
    locate,
    map,
    navigate,
    plan,
    recover,
    run,
    seed003,
    simulate,
    twin,
)
from omnical.cli.errors import install_signal_handlers

__all__ = ["app", "leave", "main"]

app = typer.Typer(
    name="omnical",
    help="Kinematics, digital twin, indoor positioning and calibration for omnidirectional robots.",
    no_args_is_help=True,
    rich_markup_mode="markdown",
    pretty_exceptions_enable=False,
    add_completion=False,
)

app.command()(simulate.simulate)
app.command()(info.info)
app.command()(export.export)
app.command()(recover.recover)
app.command()(locate.locate)
app.command()(evaluate.evaluate)
app.command()(plan.plan)
app.command(name="map")(map.map_command)
app.command()(navigate.navigate)
app.add_typer(calibrate.app, name="calibrate")
app.command()(run.run)
app.add_typer(twin.app, name="twin")
app.command()(demo.demo)
app.command()(seed003.seed003)


def main() -> None:
    """Console-script entry point."""
    install_signal_handlers()
    try:
        app()
    except SystemExit as end:
        leave(end.code)


def leave(code: object) -> NoReturn:
    """End the process with ``code`` (as :class:`SystemExit` would) without the
    interpreter's teardown, which only frees memory the system takes back anyway: numba's
    compiled kernels alone took 0.15–0.3 s to tear down, 7 % of ``omnical locate`` on a
    60-minute stress bag (the known skip, as Instagram's servers do with ``os._exit``).

    What the teardown would have done that matters is done first: Python's exit handlers
    (:mod:`atexit`: logging's files, executors, temporary directories), the finalisers of
    objects only cycles hold (``__del__``; but for those a command froze, ``gc.freeze``),
    the standard streams flushed
    (status 120 if that fails, as Python's). While a thread Python would wait for runs (a
    recorder's writer), the usual exit, which waits for it; daemon threads (rich's refresh)
    it does not wait for either.
    """
    main_thread = threading.main_thread()
    if any(not t.daemon and t is not main_thread for t in threading.enumerate()):
        raise SystemExit(code)
    if code is None:
        status = 0
    elif isinstance(code, int):
        status = code
    else:  # SystemExit's rule: anything else is printed, status 1
        print(code, file=sys.stderr)
        status = 1
    atexit._run_exitfuncs()
    gc.collect()
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:  # None: started with the descriptor closed (>&-)
                stream.flush()
        except (OSError, ValueError):  # a closed pipe (| head), a closed stream
            status = status or 120
    os._exit(status)


if __name__ == "__main__":
    main()
