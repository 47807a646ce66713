"""What ``--robot`` / ``--hedge`` name: the in-process twin, a serial port, or a robot description.

:func:`parse_robot_target` and :func:`parse_hedge` read them for every command that can drive
either world; :func:`load_said_robot` loads a robot description and says which one is used.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from omnical.errors import ConfigError

if TYPE_CHECKING:
    from omnical.robot.description import RobotDescription

__all__ = [
    "DEFAULT_MODEL",
    "HedgeTarget",
    "RobotTarget",
    "load_said_robot",
    "parse_hedge",
    "parse_robot_target",
]

DEFAULT_MODEL = "rosy-mecanum"
_SERIAL = "serial:"


@dataclass(frozen=True)
class RobotTarget:
    """The robot a command drives.

    Attributes:
        kind: ``twin`` (in process, simulated time) or ``serial`` (a vehicle controller).
        model: the robot description: a preset name or a robot YAML path.
        port: the serial device (``serial`` only, else None).
    """

    kind: Literal["twin", "serial"]
    model: str
    port: str | None = None

    @property
    def is_serial(self) -> bool:
        """True for a vehicle controller on a serial port."""
        return self.kind == "serial"


@dataclass(frozen=True)
class HedgeTarget:
    """The hedgehog: ``twin`` (simulated with the twin), ``serial`` (on ``port``) or ``none``."""

    kind: Literal["twin", "serial", "none"]
    port: str | None = None


def _serial_port(option: str, value: str) -> str | None:
    if not value.startswith(_SERIAL):
        return None
    port = value[len(_SERIAL) :]
    if not port:
        msg = f"{option} {value!r}: give the device after 'serial:', e.g. serial:/dev/ttyUSB0"
        raise ConfigError(msg)
    return port


def parse_robot_target(robot: str, model: str | None = None) -> RobotTarget:
    """Parse ``--robot`` (``twin``, ``serial:PORT``, a preset or a robot YAML) and ``--model``.

    Raises:
        ConfigError: an empty port, or ``--model`` with a ``--robot`` that already names the
            robot description.
    """
    port = _serial_port("--robot", robot)
    if port is not None:
        return RobotTarget("serial", model or DEFAULT_MODEL, port)
    if robot == "twin":
        return RobotTarget("twin", model or DEFAULT_MODEL)
    if model is not None and model != robot:
        msg = (
            f"--robot {robot} already names the robot description; --model {model} applies "
            "only with --robot twin or --robot serial:PORT"
        )
        raise ConfigError(msg)
    return RobotTarget("twin", robot)


def parse_hedge(hedge: str) -> HedgeTarget:
    """Parse ``--hedge``: ``twin``, ``serial:PORT`` or ``none``.

    Raises:
        ConfigError: anything else.
    """
    if hedge in {"twin", "none"}:
        return HedgeTarget("twin" if hedge == "twin" else "none")
    port = _serial_port("--hedge", hedge)
    if port is None:
        msg = f"--hedge {hedge!r}: use 'twin', 'serial:PORT' or 'none'"
        raise ConfigError(msg)
    return HedgeTarget("serial", port)


def load_said_robot(name_or_path: str | Path) -> RobotDescription:
    """The robot description of a preset or YAML file, and one printed line naming it: what
    the command computes with (a wrong or default robot otherwise goes unnoticed)."""
    from omnical.cli.output import say
    from omnical.robot.loader import available_presets, load_robot

    description = load_robot(name_or_path)
    text = str(name_or_path)
    source = "preset" if text in available_presets() else f"file {text}"
    encoders = description.wheel_encoders
    counts = (
        f", wheel encoders {encoders.counts_per_rev:g} counts/rev"
        if encoders is not None and encoders.counts_per_rev is not None
        else ""
    )
    say(f"robot: {description.name} ({source}{counts})")
    return description
