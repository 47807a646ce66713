"""How the CLI reports failures: one line, exit 2 for bad input, never a traceback for a user mistake."""

from __future__ import annotations

import sys
from collections.abc import Callable

import click
from rich.console import Console

from omnical.errors import OmnicalError

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILED", "run_cli"]

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1

_stderr = Console(stderr=True, highlight=False, soft_wrap=True)


def run_cli(app: Callable[..., object], argv: list[str] | None = None) -> int:
    """Run a typer/click app and map errors to exit codes.

    * :class:`OmnicalError` (bad file, bad recording, impossible request): one line, exit 2;
    * click usage errors: click's own message, exit 2;
    * Ctrl-C: exit 130 (what was already written stays written);
    * anything else is a bug and keeps its traceback.
    """
    try:
        result = app(args=argv, standalone_mode=False)
    except OmnicalError as err:
        _stderr.print(f"omnical: error: {err}", markup=False)
        return EXIT_BAD_INPUT
    except click.ClickException as err:
        err.show()
        return err.exit_code
    except (click.exceptions.Abort, KeyboardInterrupt):
        _stderr.print("omnical: interrupted", markup=False)
        return 130
    except click.exceptions.Exit as err:
        return int(err.exit_code)
    return result if isinstance(result, int) else 0


def main_exit(app: Callable[..., object]) -> None:
    """Entry point helper: run and exit with the mapped status."""
    sys.exit(run_cli(app))
