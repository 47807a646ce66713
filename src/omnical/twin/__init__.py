"""The digital twin: plant with imperfections, vehicle-controller firmware, sensors, simulated IPS."""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
    from omnical.twin.clock import TwinClock
    from omnical.twin.noise import (
        NoiseChannel,
        NoiseStream,
    )
    from omnical.twin.params import (
        TwinParams,
        default_twin,
        load_twin,
        parse_twin,
    )
    from omnical.twin.simulator import (
        DigitalTwin,
        ImuColumn,
        MagnetometerColumn,
        StateColumn,
        TwinLog,
    )
    from omnical.twin.wheel_motor import (
        WheelMotor,
        motor_decay,
        motor_speed_step,
    )

_EXPORTS: dict[str, str] = {
    "DigitalTwin": "omnical.twin.simulator",
    "ImuColumn": "omnical.twin.simulator",
    "MagnetometerColumn": "omnical.twin.simulator",
    "NoiseChannel": "omnical.twin.noise",
    "NoiseStream": "omnical.twin.noise",
    "StateColumn": "omnical.twin.simulator",
    "TwinClock": "omnical.twin.clock",
    "TwinLog": "omnical.twin.simulator",
    "TwinParams": "omnical.twin.params",
    "WheelMotor": "omnical.twin.wheel_motor",
    "default_twin": "omnical.twin.params",
    "load_twin": "omnical.twin.params",
    "motor_decay": "omnical.twin.wheel_motor",
    "motor_speed_step": "omnical.twin.wheel_motor",
    "parse_twin": "omnical.twin.params",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

__all__ = [
    "DigitalTwin",
    "ImuColumn",
    "MagnetometerColumn",
    "NoiseChannel",
    "NoiseStream",
    "StateColumn",
    "TwinClock",
    "TwinLog",
    "TwinParams",
    "WheelMotor",
    "default_twin",
    "load_twin",
    "motor_decay",
    "motor_speed_step",
    "parse_twin",
]


__getattr__ = lazy_getattr(__name__, _EXPORTS)
