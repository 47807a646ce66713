"""One wheel of the twin's drive train in closed loop: for tuning its speed controller.

The same motor and encoder model as :class:`~omnical.twin.simulator.DigitalTwin` — the wheel
motor of :mod:`omnical.twin.wheel_motor` (by default the firmware's nominal first-order lag,
``motor_time_constant_s``; or a twin's true motor with gain and lag errors and friction,
:meth:`~omnical.twin.params.TwinParams.wheel_motors`), a quadrature encoder
(``counts_per_wheel_rev``) read at the vehicle controller's rate, speed = counts per control
period — driven here by a PID (:func:`omnical.control.pid.pid_step`) instead of the firmware's
PI with feed-forward. This is the plant seed 003 tunes with Ziegler–Nichols (the one wheel-loop
plant of omnical): the P-only loop oscillates because the speed is measured over one control
period and acted on one period later.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.control.pid import PidParams, PidState, pid_step
from omnical.control.ziegler_nichols import (
    UltimatePoint,
    ZnRule,
    find_ultimate_gain,
    ziegler_nichols_gains,
)
from omnical.robot.description import DriveTrain
from omnical.twin.wheel_motor import WheelMotor, motor_decay, motor_speed_step

__all__ = [
    "RPM_PER_RADPS",
    "tune_wheel_speed_pid",
    "wheel_speed_loop",
    "wheel_speed_tracking",
]

RPM_PER_RADPS = 60.0 / (2.0 * math.pi)


def wheel_speed_loop(
    drive_train: DriveTrain,
    params: PidParams,
    setpoint_radps: float,
    duration_s: float,
    *,
    step_hz: float = 1000.0,
    quantize: bool = True,
    motor: WheelMotor | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Step response of one wheel's speed loop from rest.

    Args:
        drive_train: nominal motor lag, encoder and control rate of the robot.
        params: the speed controller (output: drive command in rad/s of steady-state speed).
        setpoint_radps: wheel speed set point.
        duration_s: simulated time.
        step_hz: plant integration rate (≥ 10× the control rate).
        quantize: measure speed from whole encoder counts (False: the exact mean speed over the
            period, for a noise-free tuning experiment).
        motor: the true motor; None = the drive train's nominal model.

    Returns:
        Control times (K,) s and the measured wheel speed (K,) rad/s at each control tick.
    """
    sub = max(1, round(step_hz / drive_train.control_rate_hz))
    dt_c = 1.0 / drive_train.control_rate_hz
    dt = dt_c / sub
    plant = WheelMotor.nominal(drive_train) if motor is None else motor
    decay = motor_decay(plant, dt)
    cpr = drive_train.counts_per_wheel_rev
    n = round(duration_s / dt_c)
    t = np.arange(n, dtype=np.float64) * dt_c
    meas_log = np.empty(n)
    state = PidState()
    omega = theta = theta_prev = u = 0.0
    counts_prev = 0
    for k in range(n):
        if quantize:
            counts = math.floor(theta * cpr / (2.0 * math.pi))
            meas = (counts - counts_prev) * 2.0 * math.pi / cpr / dt_c
            counts_prev = counts
        else:
            meas = (theta - theta_prev) / dt_c
            theta_prev = theta
        meas_log[k] = meas
        u, state = pid_step(params, state, setpoint_radps, meas, dt_c)
        for _ in range(sub):
            omega = motor_speed_step(omega, u, plant, decay)
            theta += omega * dt
    return t, meas_log


def tune_wheel_speed_pid(
    drive_train: DriveTrain,
    *,
    setpoint_radps: float = 100.0 / RPM_PER_RADPS,
    rule: ZnRule = ZnRule.PID,
    duration_s: float = 3.0,
    motor: WheelMotor | None = None,
) -> tuple[UltimatePoint, PidParams]:
    """Ziegler–Nichols (closed-loop, ultimate gain) tuning of the twin's wheel-speed loop.

    As seed 003 does it on one motor at 100 rpm: raise Kp of a P-only loop until the speed
    oscillates steadily (Ku), measure the period (Pu), derive Kp, Ti, Td by the classic rules.
    ``motor`` is the motor tuned on (None = the drive train's nominal model).
    """

    def experiment(kp: float, duration: float) -> tuple[ArrayLike, ArrayLike]:
        t, y = wheel_speed_loop(
            drive_train, PidParams(kp=kp), setpoint_radps, duration, quantize=False, motor=motor
        )
        return t, np.round(y, 9)  # float round-off in the settled tail is not an oscillation

    ultimate = find_ultimate_gain(experiment, duration_s, kp_start=0.5)
    return ultimate, ziegler_nichols_gains(ultimate.ku, ultimate.pu_s, rule)


def wheel_speed_tracking(
    drive_train: DriveTrain,
    params: PidParams,
    setpoints_rpm: ArrayLike = tuple(range(110, 201, 10)),
    *,
    settle_s: float = 2.0,
    average_s: float = 2.0,
    motor: WheelMotor | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Seed 003 Table II on the twin: mean measured speed (rpm) at each set point (rpm).

    The loop runs with the quantised encoder on ``motor`` (None = the nominal model); the mean
    is taken over ``average_s`` after ``settle_s``.
    """
    sp = np.asarray(setpoints_rpm, dtype=np.float64)
    means = np.empty_like(sp)
    for i, rpm in enumerate(sp):
        t, y = wheel_speed_loop(
            drive_train, params, rpm / RPM_PER_RADPS, settle_s + average_s, motor=motor
        )
        means[i] = float(np.mean(y[t >= settle_s])) * RPM_PER_RADPS
    return sp, means
