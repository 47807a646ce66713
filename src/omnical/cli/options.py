"""Options shared by several commands, so that they read the same everywhere."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated, TypeAlias

import typer

__all__ = ["Beacons", "Robot", "Seed", "choice_metavar"]

Robot: TypeAlias = Annotated[
    str, typer.Option(help="Robot preset (rosy-mecanum, omni-x) or robot YAML.")
]
Seed: TypeAlias = Annotated[
    int, typer.Option(min=0, max=2**63 - 1, help="Random seed ≥ 0 (same seed, same run).")
]
Beacons: TypeAlias = Annotated[
    Path | None, typer.Option(help="Beacon map YAML (default: seed 000 Table 3).")
]


def choice_metavar(enum_type: type[StrEnum]) -> str:
    """``METHOD`` for ``LocateMethod``: the metavar of an option taking one of ``enum_type``'s
    values, the last word of the enum's name in capitals, short enough to leave the help text
    room at 80 columns. The help text names the values.

    The option itself is a plain ``str`` validated by :func:`omnical.choices.parse_choice`
    in the command, so that a wrong value gets omnical's one-line message and exit status 2.
    """
    import re

    words = re.findall(r"[A-Z][a-z0-9]*", enum_type.__name__)
    return (words[-1] if words else enum_type.__name__).upper()


Overwrite = Annotated[
    bool,
    typer.Option(
        "--overwrite",
        help="Replace an earlier omnical output there (never files omnical did not write).",
    ),
]
