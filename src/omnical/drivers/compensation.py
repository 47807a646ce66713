"""The seven correction factors applied host-side, for stock vehicle-controller firmware.

:class:`CompensatingRobot` wraps any :class:`~omnical.experiment.ports.Robot`: the commanded
twist compensated on its way out, the reported one counter-compensated on its way in.
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
