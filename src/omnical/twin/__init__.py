"""The digital twin: plant with imperfections, vehicle-controller firmware, sensors, simulated IPS."""

from omnical.twin.clock import TwinClock
from omnical.twin.noise import NoiseChannel, NoiseStream
from omnical.twin.params import TwinParams, default_twin, load_twin, parse_twin
from omnical.twin.simulator import (
    DigitalTwin,
    ImuColumn,
    MagnetometerColumn,
    StateColumn,
    TwinLog,
)
from omnical.twin.wheel_motor import WheelMotor, motor_decay, motor_speed_step

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
