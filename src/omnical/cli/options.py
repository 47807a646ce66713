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
    """``[robust|lsq|grid]``: the metavar of an option taking one of ``enum_type``'s values.

    The option itself is a plain ``str`` validated by :func:`omnical.choices.parse_choice`
    in the command, so that a wrong value gets omnical's one-line message and exit status 2.
    """
    return "[" + "|".join(member.value for member in enum_type) + "]"


Overwrite = Annotated[
    bool,
    typer.Option(
        "--overwrite",
        help="Replace an earlier omnical output there (never files omnical did not write).",
    ),
]
