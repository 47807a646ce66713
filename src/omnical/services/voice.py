"""How a single command's work tells what it does (:class:`Voice`): lines, warnings and a
spinner over its long steps; silent for the fleet's jobs, whose rows say what became of them.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass

__all__ = ["SILENT", "Voice"]


def _quiet(line: str) -> None:
    """Say nothing."""


def _still(label: str) -> AbstractContextManager[object]:
    """No spinner."""
    return nullcontext()


@dataclass(frozen=True)
class Voice:
    """Where a command's work speaks (by default nowhere).

    Attributes:
        say: one line of what was read or used.
        warn: one warning line (what reading or computing cleaned or repaired).
        status: a context that shows ``label`` while a long step runs (a spinner).
    """

    say: Callable[[str], None] = _quiet
    warn: Callable[[str], None] = _quiet
    status: Callable[[str], AbstractContextManager[object]] = _still


SILENT = Voice()
"""The fleet's jobs' voice: nothing said."""
