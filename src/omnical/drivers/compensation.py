"""The seven correction factors applied host-side, for stock vehicle-controller firmware.

Stock Wheeltec firmware runs the nominal inverse kinematics and integrates nothing itself, so
the factors cannot be installed in it without reflashing. :class:`CompensatingRobot` wraps any
:class:`~omnical.experiment.ports.Robot` and does on the host what the compensating firmware does
(seed 000 §3.2.3, :mod:`omnical.kinematics.correction`):

* outgoing: the desired twist → :func:`~omnical.kinematics.correction.compensate_twist_scalar`
  (cross-talk yaw injected, then scaled) → the base;
* incoming: the base's forward-kinematics twist →
  :func:`~omnical.kinematics.correction.counter_compensate_twist_scalar` → the odometry.

With a base that integrates its own odometry from the twist (:class:`WheeltecRobot` offers
``set_odometry_correction``) the counter-compensation is applied to every status frame before
integration, so pose and twist are both compensated. Any other robot gets its reported twist
counter-compensated, and its pose passed through unchanged (said in ``pose_compensated``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from omnical.experiment.ports import Robot, RobotState
from omnical.kinematics.correction import (
    CorrectionFactors,
    compensate_twist_scalar,
    counter_compensate_twist_scalar,
)

__all__ = ["CompensatingRobot"]


class CompensatingRobot:
    """A :class:`Robot` that compensates with ``factors`` on the host.

    Args:
        inner: the base (e.g. :class:`~omnical.drivers.wheeltec_serial.WheeltecRobot`).
        factors: the correction factors to apply.
    """

    def __init__(self, inner: Robot, factors: CorrectionFactors) -> None:
        self.inner = inner
        self.factors = factors
        setter: Any = getattr(inner, "set_odometry_correction", None)
        self.pose_compensated = callable(setter)
        if callable(setter):
            setter(factors)

    def send_twist(self, vx_mps: float, vy_mps: float, wz_radps: float) -> None:
        """Send the compensated twist (what the nominal inverse kinematics must be fed)."""
        self.inner.send_twist(*compensate_twist_scalar(vx_mps, vy_mps, wz_radps, self.factors))

    def read_state(self) -> RobotState:
        """The base's state with counter-compensated odometry."""
        state = self.inner.read_state()
        if self.pose_compensated:
            return state
        twist = counter_compensate_twist_scalar(*state.odom_twist, self.factors)
        return replace(state, odom_twist=twist)

    def stop(self) -> None:
        """Zero twist (compensation of zero is zero)."""
        self.inner.stop()

    def release(self) -> None:
        """Stop counter-compensating the inner base's odometry."""
        setter: Any = getattr(self.inner, "set_odometry_correction", None)
        if callable(setter):
            setter(None)
