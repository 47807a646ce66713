"""What omnical ships to run by name: motion scripts and closed-loop controller tasks.

Scripts (``data/scripts/*.yaml``): :func:`builtin_script_names`, :func:`builtin_script_data`;
tasks (seed 003's four tests, as data): :data:`BUILTIN_TASKS`, :func:`builtin_task`.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from typing import Any

from omnical.userfiles import parse_yaml

__all__ = [
    "BUILTIN_TASKS",
    "BuiltinTask",
    "builtin_script_data",
    "builtin_script_names",
    "builtin_task",
    "builtin_task_names",
]

_PACKAGE = "omnical.data.scripts"

Point = tuple[float, float]


def builtin_script_names() -> list[str]:
    """Names usable in place of a script path."""
    root = resources.files(_PACKAGE)
    return sorted(p.name.removesuffix(".yaml") for p in root.iterdir() if p.name.endswith(".yaml"))


def builtin_script_data(name: str) -> Any:
    """The parsed YAML of a built-in script."""
    text = resources.files(_PACKAGE).joinpath(f"{name}.yaml").read_text(encoding="utf-8")
    return parse_yaml(text, f"built-in script {name}", "motion script")


@dataclass(frozen=True)
class BuiltinTask:
    """A closed-loop controller task shipped with omnical.

    Attributes:
        name: what the user types (``omnical run seed003-square``).
        slug: the test's key in :data:`omnical.paper.SEED003_PAPER_TEST_ERRORS`.
        title: human-readable name with the paper's figure.
        mode: how each goal is approached (a :class:`omnical.control.centred.CentredMode` value:
            ``centred_turning``, ``driving_forward`` or ``translate``).
        goals_m: (x, y) goals in the path frame (the robot's start pose), in order.
        reference_m: the reference path drawn and measured against, start point first.
    """

    name: str
    slug: str
    title: str
    mode: str
    goals_m: tuple[Point, ...]
    reference_m: tuple[Point, ...]


_SQUARE: tuple[Point, ...] = ((0.0, 0.0), (1.2, 0.0), (1.2, -1.2), (0.0, -1.2), (0.0, 0.0))
_TRIANGLE: tuple[Point, ...] = ((0.0, 0.0), (1.2, 0.0), (0.6, 0.6), (0.0, 0.0))

#: Seed 003's four positioning tests (§IV.B), in the paper's order.
BUILTIN_TASKS: tuple[BuiltinTask, ...] = (
    BuiltinTask(
        "seed003-centred-turning",
        "centred-turning",
        "centred turning to (100, 100) cm (Fig. 6)",
        "centred_turning",
        ((1.0, 1.0),),
        ((0.0, 0.0), (1.0, 1.0)),
    ),
    BuiltinTask(
        "seed003-driving-forward",
        "driving-forward",
        "driving forward to (125, 100) cm (Fig. 7)",
        "driving_forward",
        ((1.25, 1.0),),
        ((0.0, 0.0), (1.25, 0.0), (1.25, 1.0)),
    ),
    BuiltinTask(
        "seed003-square",
        "square",
        "square trajectory (Fig. 8)",
        "translate",
        _SQUARE[1:],
        _SQUARE,
    ),
    BuiltinTask(
        "seed003-triangle",
        "triangle",
        "triangle trajectory (Fig. 9)",
        "translate",
        _TRIANGLE[1:],
        _TRIANGLE,
    ),
)


def builtin_task_names() -> list[str]:
    """Names of the built-in controller tasks, usable in place of a script path."""
    return [t.name for t in BUILTIN_TASKS]


def builtin_task(name: str) -> BuiltinTask | None:
    """The built-in controller task called ``name``, or None."""
    return next((t for t in BUILTIN_TASKS if t.name == name), None)
