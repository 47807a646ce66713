"""Kinematics: Jacobians from wheel geometry and the seven-factor correction model."""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
    from omnical.kinematics.correction import (
        CorrectionFactors,
        compensate_twist,
        counter_compensate_twist,
        crosstalk_yaw_rate,
    )
    from omnical.kinematics.jacobian import (
        body_twist_from_wheel_speeds,
        forward_jacobian,
        inverse_jacobian,
        wheel_speeds_from_body_twist,
    )

_EXPORTS: dict[str, str] = {
    "CorrectionFactors": "omnical.kinematics.correction",
    "body_twist_from_wheel_speeds": "omnical.kinematics.jacobian",
    "compensate_twist": "omnical.kinematics.correction",
    "counter_compensate_twist": "omnical.kinematics.correction",
    "crosstalk_yaw_rate": "omnical.kinematics.correction",
    "forward_jacobian": "omnical.kinematics.jacobian",
    "inverse_jacobian": "omnical.kinematics.jacobian",
    "wheel_speeds_from_body_twist": "omnical.kinematics.jacobian",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

__all__ = [
    "CorrectionFactors",
    "body_twist_from_wheel_speeds",
    "compensate_twist",
    "counter_compensate_twist",
    "crosstalk_yaw_rate",
    "forward_jacobian",
    "inverse_jacobian",
    "wheel_speeds_from_body_twist",
]


__getattr__ = lazy_getattr(__name__, _EXPORTS)
