"""How the CLI reports failures: one line, exit 2 for bad input, never a traceback for a user mistake."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import typer
from rich.console import Console

from omnical.errors import OmnicalError

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILED", "user_errors"]

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1

_stderr = Console(stderr=True, highlight=False, soft_wrap=True)


@contextmanager
def user_errors() -> Iterator[None]:
    """Turn an :class:`OmnicalError` into ``omnical: error: <message>`` and exit status 2.

    Anything else is a bug and keeps its traceback; usage errors are typer's (exit 2 too).
    """
    try:
        yield
    except OmnicalError as err:
        _stderr.print(f"omnical: error: {err}", markup=False)
        raise typer.Exit(EXIT_BAD_INPUT) from None
