"""Robot descriptions: wheels, limits, drive train, IMU, hedgehog mounting; presets and YAML loading."""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
    from omnical.robot.description import (
        DeadWheel,
        DriveTrain,
        ImuNoise,
        LidarMount,
        Limits,
        RobotDescription,
        RobotFootprint,
        Wheel,
        WheelEncoders,
    )
    from omnical.robot.loader import (
        available_presets,
        load_robot,
        parse_robot,
    )

_EXPORTS: dict[str, str] = {
    "DeadWheel": "omnical.robot.description",
    "DriveTrain": "omnical.robot.description",
    "ImuNoise": "omnical.robot.description",
    "LidarMount": "omnical.robot.description",
    "Limits": "omnical.robot.description",
    "RobotDescription": "omnical.robot.description",
    "RobotFootprint": "omnical.robot.description",
    "Wheel": "omnical.robot.description",
    "WheelEncoders": "omnical.robot.description",
    "available_presets": "omnical.robot.loader",
    "load_robot": "omnical.robot.loader",
    "parse_robot": "omnical.robot.loader",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

__all__ = [
    "DeadWheel",
    "DriveTrain",
    "ImuNoise",
    "LidarMount",
    "Limits",
    "RobotDescription",
    "RobotFootprint",
    "Wheel",
    "WheelEncoders",
    "available_presets",
    "load_robot",
    "parse_robot",
]


__getattr__ = lazy_getattr(__name__, _EXPORTS)
