"""The true motor of one wheel, shared by the twin and the wheel-loop tuning of twin.motor.

:class:`WheelMotor`: a first-order lag with gain and time-constant errors, Coulomb friction and
a viscous load; :meth:`WheelMotor.nominal` is the firmware's model. Equation: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from omnical.errors import ConfigError
from omnical.robot.description import DriveTrain

__all__ = ["WheelMotor", "motor_decay", "motor_speed_step"]


@dataclass(frozen=True)
class WheelMotor:
    """The real dynamics of one wheel's motor under load.

    Attributes:
        time_constant_s: τ, mechanical time constant of the loaded motor.
        gain: K, steady-state wheel speed per unit of drive command, without friction
            (1 = the firmware's nominal model).
        coulomb_friction_radps: ω_c ≥ 0, Coulomb friction as the steady-state speed it costs.
        viscous_droop: b ≥ 0, viscous friction and load as a fraction of the speed
            (steady state ω = (K u − ω_c) / (1 + b) for u > 0).
    """

    time_constant_s: float
    gain: float = 1.0
    coulomb_friction_radps: float = 0.0
    viscous_droop: float = 0.0

    def __post_init__(self) -> None:
        for name, value, ok in (
            ("time_constant_s", self.time_constant_s, self.time_constant_s > 0.0),
            ("gain", self.gain, self.gain > 0.0),
            (
                "coulomb_friction_radps",
                self.coulomb_friction_radps,
                self.coulomb_friction_radps >= 0.0,
            ),
            ("viscous_droop", self.viscous_droop, self.viscous_droop >= 0.0),
        ):
            if not (math.isfinite(value) and ok):
                msg = f"wheel motor: {name} = {value} is out of range"
                raise ConfigError(msg)

    @classmethod
    def nominal(cls, drive_train: DriveTrain) -> WheelMotor:
        """The firmware's model of the motor: unit gain, the described lag, no friction."""
        return cls(drive_train.motor_time_constant_s)

    @property
    def is_nominal_form(self) -> bool:
        """True without friction and with unit gain (a pure first-order lag)."""
        return self.gain == 1.0 and self.coulomb_friction_radps == 0.0 and self.viscous_droop == 0.0


def motor_decay(motor: WheelMotor, dt_s: float) -> float:
    """exp(−(1 + b) dt / τ): the factor by which the speed's distance to its target shrinks."""
    return math.exp(-(1.0 + motor.viscous_droop) * dt_s / motor.time_constant_s)


def motor_speed_step(
    omega_radps: float, command_radps: float, motor: WheelMotor, decay: float
) -> float:
    """Wheel speed after one step of ``dt_s`` with the command held (``decay`` of that step).

    Args:
        omega_radps: wheel speed at the start of the step.
        command_radps: drive command u, in rad/s of nominal steady-state speed.
        motor: the true motor.
        decay: :func:`motor_decay` of the motor and the step.

    Returns:
        The wheel speed at the end of the step, rad/s.
    """
    drive = motor.gain * command_radps
    coulomb = motor.coulomb_friction_radps
    if coulomb > 0.0:
        if omega_radps == 0.0:
            if abs(drive) <= coulomb:  # static friction holds the wheel
                return 0.0
            drive -= math.copysign(coulomb, drive)
        else:
            drive -= math.copysign(coulomb, omega_radps)
    target = drive / (1.0 + motor.viscous_droop)
    new = target + (omega_radps - target) * decay
    if coulomb > 0.0 and new * omega_radps < 0.0:  # friction stops the wheel, never reverses it
        return 0.0
    return new
