"""Where the commands print: one rich console on stdout, built on first use; notes on stderr.

rich's console is slow to import, so it is not imported until a command prints.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.console import Console

    from omnical.services.voice import Voice
    from omnical.web.tee import MonitorLink

__all__ = ["also_told", "console", "say", "tell", "voice", "warn"]


@cache
def console() -> Console:
    """The console of every command's output.

    No syntax highlighting of numbers or paths, and no wrapping of plain lines (a ``wrote PATH``
    line stays one line for scripts); tables still fit the terminal.
    """
    from rich.console import Console

    return Console(highlight=False, soft_wrap=True)


def say(line: str) -> None:
    """Print one plain line as it is: no markup, so that a path like ``run[2].mcap`` survives."""
    console().print(line, markup=False)


def tell(line: str) -> None:
    """One line on stderr, ``omnical: LINE``: what became of an output (kept as ``.partial``)."""
    import typer

    typer.echo(f"omnical: {line}", err=True)


def warn(note: str) -> None:
    """One warning line on stderr (what reading or computing cleaned or repaired)."""
    import typer

    typer.echo(f"omnical: warning: {note}", err=True)


def voice() -> Voice:
    """The commands' :class:`~omnical.services.voice.Voice`: :func:`say`, :func:`warn` and the
    console's spinner."""
    from omnical.services.voice import Voice

    return Voice(say=say, warn=warn, status=console().status)


def also_told(
    out: Callable[[str], None], link: MonitorLink | None, prefix: str = ""
) -> Callable[[str], None]:
    """``out`` a line and, with ``--monitor``, put it in the monitor's event log as it happens
    (after ``prefix``)."""
    if link is None:
        return out

    def both(line: str) -> None:
        out(line)
        link.event(prefix + line)

    return both
