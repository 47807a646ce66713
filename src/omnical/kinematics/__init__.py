"""Kinematics: Jacobians from wheel geometry and the seven-factor correction model."""

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
