"""Where the commands print: one rich console on stdout, built on first use; notes on stderr.

rich's console takes ~40 ms to import, so it is not imported until a command prints.
"""

from __future__ import annotations

from functools import cache
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.console import Console

__all__ = ["console", "say", "tell"]


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
