"""Robot descriptions: wheels, limits, drive train, IMU, hedgehog mounting; presets and YAML loading."""

from omnical.robot.description import (
    DeadWheel,
    DriveTrain,
    ImuNoise,
    Limits,
    RobotDescription,
    Wheel,
)
from omnical.robot.loader import available_presets, load_robot, parse_robot

__all__ = [
    "DeadWheel",
    "DriveTrain",
    "ImuNoise",
    "Limits",
    "RobotDescription",
    "Wheel",
    "available_presets",
    "load_robot",
    "parse_robot",
]
