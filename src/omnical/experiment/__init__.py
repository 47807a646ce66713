"""Experiments: the Robot/Clock ports, motion scripts and the Runner."""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
    from omnical.experiment.ports import (
        Clock,
        Robot,
        RobotState,
        WallClock,
    )
    from omnical.experiment.runner import (
        RunLog,
        run_script,
    )
    from omnical.experiment.script import (
        MotionScript,
        Step,
        load_script,
        parse_script,
    )

_EXPORTS: dict[str, str] = {
    "Clock": "omnical.experiment.ports",
    "MotionScript": "omnical.experiment.script",
    "Robot": "omnical.experiment.ports",
    "RobotState": "omnical.experiment.ports",
    "RunLog": "omnical.experiment.runner",
    "Step": "omnical.experiment.script",
    "WallClock": "omnical.experiment.ports",
    "load_script": "omnical.experiment.script",
    "parse_script": "omnical.experiment.script",
    "run_script": "omnical.experiment.runner",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

__all__ = [
    "Clock",
    "MotionScript",
    "Robot",
    "RobotState",
    "RunLog",
    "Step",
    "WallClock",
    "load_script",
    "parse_script",
    "run_script",
]


__getattr__ = lazy_getattr(__name__, _EXPORTS)
