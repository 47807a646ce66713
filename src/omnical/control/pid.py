"""A discrete PID controller in the (Kp, Ti, Td) form of seed 003, as a pure step function.

u = Kp (e + ∫e dt / Ti + Td de/dt), derivative filtered on the measurement, anti-windup;
:func:`pid_step` on floats (the twin's motor loop and the pose controllers).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

from omnical.errors import ConfigError

__all__ = [
    "SEED003_MOTOR_PID",
    "AntiWindup",
    "PidParams",
    "PidState",
    "pid_step",
]


class AntiWindup(StrEnum):
    """How the integral is kept from winding up while the output saturates."""

    NONE = "none"
    CONDITIONAL = "conditional"
    BACK_CALCULATION = "back_calculation"


@dataclass(frozen=True)
class PidParams:
    """Gains and limits of a PID controller (seed 003 form).

    Attributes:
        kp: proportional gain Kp (output units per measurement unit).
        ti_s: integral time Ti; ``math.inf`` turns the integral off.
        td_s: derivative time Td; 0 turns the derivative off.
        derivative_filter_n: N, the derivative filter time constant is Td/N.
        output_min, output_max: output saturation.
        anti_windup: the anti-windup scheme.
        tracking_time_s: Tt of back-calculation; None → √(Ti Td), or Ti when Td = 0.

    Raises:
        ConfigError: on construction, for a non-finite Kp, Ti ≤ 0, Td < 0, N ≤ 0, an empty output
            range or Tt ≤ 0.
    """

    kp: float
    ti_s: float = math.inf
    td_s: float = 0.0
    derivative_filter_n: float = 10.0
    output_min: float = -math.inf
    output_max: float = math.inf
    anti_windup: AntiWindup = AntiWindup.BACK_CALCULATION
    tracking_time_s: float | None = None

    def __post_init__(self) -> None:
        checks = (
            (math.isfinite(self.kp), f"kp must be finite, got {self.kp}"),
            (self.ti_s > 0.0, f"ti_s must be > 0 (math.inf for no integral), got {self.ti_s}"),
            (
                math.isfinite(self.td_s) and self.td_s >= 0.0,
                f"td_s must be finite and >= 0, got {self.td_s}",
            ),
            (
                math.isfinite(self.derivative_filter_n) and self.derivative_filter_n > 0.0,
                f"derivative_filter_n must be finite and > 0, got {self.derivative_filter_n}",
            ),
            (
                self.output_min < self.output_max,
                f"output range [{self.output_min}, {self.output_max}] is empty",
            ),
            (
                self.tracking_time_s is None
                or (math.isfinite(self.tracking_time_s) and self.tracking_time_s > 0.0),
                f"tracking_time_s must be finite and > 0, got {self.tracking_time_s}",
            ),
        )
        for ok, msg in checks:
            if not ok:
                raise ConfigError(msg)
        try:
            AntiWindup(self.anti_windup)
        except ValueError as err:
            msg = f"unknown anti_windup {self.anti_windup!r}; use one of {[m.value for m in AntiWindup]}"
            raise ConfigError(msg) from err

    @property
    def ki(self) -> float:
        """Integral gain Kp/Ti of the parallel form."""
        return self.kp / self.ti_s

    @property
    def kd(self) -> float:
        """Derivative gain Kp Td of the parallel form."""
        return self.kp * self.td_s

    @property
    def tracking_s(self) -> float:
        """Tracking time Tt used by back-calculation."""
        if self.tracking_time_s is not None:
            return self.tracking_time_s
        return math.sqrt(self.ti_s * self.td_s) if self.td_s > 0.0 else self.ti_s


#: Seed 003 §IV.A: the DC-motor speed PID tuned by Ziegler–Nichols and trial and error
#: (Kp = 5, Ti = 2.8, Td = 0.6). The paper gives neither the output unit nor the time unit.
SEED003_MOTOR_PID = PidParams(kp=5.0, ti_s=2.8, td_s=0.6)


@dataclass(frozen=True)
class PidState:
    """What a PID remembers between steps.

    Attributes:
        integral: integral term I, output units (set it to the current output for a bumpless start).
        derivative: filtered derivative term D, output units.
        last_measurement: previous measurement; None before the first step (no derivative then).
    """

    integral: float = 0.0
    derivative: float = 0.0
    last_measurement: float | None = None


def _check_dt(dt_s: float) -> None:
    if not (math.isfinite(dt_s) and dt_s > 0.0):
        msg = f"PID time step must be finite and > 0, got {dt_s}"
        raise ConfigError(msg)


def pid_step(
    params: PidParams, state: PidState, setpoint: float, measurement: float, dt_s: float
) -> tuple[float, PidState]:
    """One PID update.

    Args:
        params: gains and limits.
        state: state after the previous step (``PidState()`` to start, or to reset).
        setpoint: r.
        measurement: y.
        dt_s: time since the previous step.

    Returns:
        ``(output, new_state)``: the saturated output u and the state for the next step.

    Raises:
        ConfigError: a non-positive time step.
    """
    _check_dt(dt_s)
    error = setpoint - measurement
    derivative = 0.0
    if params.td_s > 0.0 and state.last_measurement is not None:
        tf = params.td_s / params.derivative_filter_n
        dy = measurement - state.last_measurement
        derivative = (tf * state.derivative - params.kp * params.td_s * dy) / (tf + dt_s)
    raw = params.kp * error + state.integral + derivative
    output = min(max(raw, params.output_min), params.output_max)
    integral = state.integral
    if math.isfinite(params.ti_s):
        increment = params.kp * dt_s / params.ti_s * error
        if params.anti_windup == AntiWindup.BACK_CALCULATION:
            integral += increment + min(dt_s / params.tracking_s, 1.0) * (output - raw)
        elif params.anti_windup == AntiWindup.CONDITIONAL:
            if output == raw or increment * (raw - output) < 0.0:
                integral += increment
        else:
            integral += increment
    return output, PidState(integral, derivative, measurement)
