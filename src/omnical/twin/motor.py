"""One wheel of the twin's drive train in closed loop: for tuning its speed controller.

The twin's motor and encoder model driven by a PID (:func:`omnical.control.pid.pid_step`): the
plant seed 003 tunes with Ziegler–Nichols. Design: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.control.pid import AntiWindup, PidParams, PidState, pid_step
from omnical.control.ziegler_nichols import (
    StepMetrics,
    UltimatePoint,
    ZnRule,
    find_ultimate_gain,
    step_response_metrics,
    ziegler_nichols_gains,
)
from omnical.robot.description import DriveTrain
from omnical.twin.params import TwinParams
from omnical.twin.wheel_motor import WheelMotor, motor_decay, motor_speed_step

__all__ = [
    "RPM_PER_RADPS",
    "LoopDisturbance",
    "MotorTuning",
    "RuleComparison",
    "compare_rules",
    "seed003_motor_tuning",
    "seed003_table2",
    "tune_wheel_speed_pid",
    "wheel_speed_loop",
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
    disturbance: LoopDisturbance | None = None,
    seed: int = 0,
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
        disturbance: speed-reading noise and load ripple (None = none).
        seed: seed of the reading noise.

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
    dist = disturbance or LoopDisturbance()
    noise = (
        np.random.default_rng([seed, 0x5EED003]).standard_normal(n) * dist.speed_jitter
        if dist.speed_jitter > 0.0
        else np.zeros(n)
    )
    ripple, cycles = dist.load_ripple, dist.ripple_per_rev
    for k in range(n):
        if quantize:
            counts = math.floor(theta * cpr / (2.0 * math.pi))
            meas = (counts - counts_prev) * 2.0 * math.pi / cpr / dt_c
            counts_prev = counts
        else:
            meas = (theta - theta_prev) / dt_c
            theta_prev = theta
        meas *= 1.0 + float(noise[k])
        meas_log[k] = meas
        u, state = pid_step(params, state, setpoint_radps, meas, dt_c)
        for _ in range(sub):
            drive = u * (1.0 - ripple * math.sin(cycles * theta)) if ripple else u
            omega = motor_speed_step(omega, drive, plant, decay)
            theta += omega * dt
    return t, meas_log


@dataclass(frozen=True)
class LoopDisturbance:
    """What a real wheel loop sees beyond the motor model (seed 003's Table II scatter).

    Attributes:
        speed_jitter: relative σ of white noise on each wheel-speed reading.
        load_ripple: load torque ripple as a fraction of the drive (command × (1 − a sin kθ)).
        ripple_per_rev: k, ripple cycles per wheel revolution.
    """

    speed_jitter: float = 0.0
    load_ripple: float = 0.0
    ripple_per_rev: float = 1.0

    @classmethod
    def of_twin(cls, params: TwinParams) -> LoopDisturbance:
        """The reading noise and load ripple of a twin."""
        return cls(params.wheel_speed_jitter, params.load_ripple, params.load_ripple_per_rev)


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


@dataclass(frozen=True, eq=False)
class RuleComparison:
    """One tuning rule's controller and its 100 rpm step response on the twin's motor.

    Attributes:
        rule: the rule.
        pid: its controller (with the firmware's output limit and anti-windup of ``template``).
        metrics: overshoot, settling and rise time of the noise-free response (exact mean
            speed per control period) without output limit: the small-signal behaviour.
        metrics_limited: the same with the firmware's output limit (the drive saturates).
        t_s, speed_rpm: the response as the firmware measures it (quantised encoder, reading
            noise, load ripple), for the figure.
    """

    rule: ZnRule
    pid: PidParams
    metrics: StepMetrics
    metrics_limited: StepMetrics
    t_s: NDArray[np.float64]
    speed_rpm: NDArray[np.float64]


def compare_rules(
    drive_train: DriveTrain,
    ultimate: UltimatePoint,
    rules: tuple[ZnRule, ...] = (
        ZnRule.PID,
        ZnRule.PID_SOME_OVERSHOOT,
        ZnRule.TYREUS_LUYBEN,
        ZnRule.PID_NO_OVERSHOOT,
    ),
    *,
    setpoint_rpm: float = 100.0,
    duration_s: float = 1.0,
    motor: WheelMotor | None = None,
    disturbance: LoopDisturbance | None = None,
    seed: int = 0,
    template: PidParams | None = None,
) -> tuple[RuleComparison, ...]:
    """The 100 rpm step response (seed 003 Fig. 5) of each rule's gains from one (Ku, Pu).

    ``template`` carries the output limits and anti-windup of the firmware (gains replaced).
    """
    out = []
    r = setpoint_rpm / RPM_PER_RADPS
    for rule in rules:
        pid = ziegler_nichols_gains(ultimate.ku, ultimate.pu_s, rule, template=template)
        linear = ziegler_nichols_gains(ultimate.ku, ultimate.pu_s, rule)
        t, clean = wheel_speed_loop(drive_train, linear, r, duration_s, quantize=False, motor=motor)
        t, limited = wheel_speed_loop(drive_train, pid, r, duration_s, quantize=False, motor=motor)
        t, seen = wheel_speed_loop(
            drive_train, pid, r, duration_s, motor=motor, disturbance=disturbance, seed=seed
        )
        out.append(
            RuleComparison(
                rule,
                pid,
                step_response_metrics(t, clean, r),
                step_response_metrics(t, limited, r),
                t,
                seen * RPM_PER_RADPS,
            )
        )
    return tuple(out)


def seed003_table2(
    drive_train: DriveTrain,
    params: PidParams,
    motors: tuple[WheelMotor, ...],
    *,
    setpoints_rpm: ArrayLike = tuple(range(110, 201, 10)),
    samples: int = 100,
    repeats: int = 10,
    settle_s: float = 1.0,
    disturbance: LoopDisturbance | None = None,
    seed: int = 0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Seed 003 Table II as the paper measured it, on each motor.

    For every motor and set point: run the loop from rest ``repeats`` times (fresh reading
    noise each time), average ``samples`` speed readings after ``settle_s``, and average the
    repeats ("the average of a hundred data from each motors and then mean it from 10x testing").

    Returns:
        Set points (S,) rpm and the mean speeds (S, M) rpm of the M motors.
    """
    sp = np.asarray(setpoints_rpm, dtype=np.float64)
    means = np.empty((sp.size, len(motors)))
    dt_c = 1.0 / drive_train.control_rate_hz
    duration = settle_s + samples * dt_c
    for j, motor in enumerate(motors):
        for i, rpm in enumerate(sp):
            runs = []
            for rep in range(repeats):
                t, y = wheel_speed_loop(
                    drive_train,
                    params,
                    rpm / RPM_PER_RADPS,
                    duration,
                    motor=motor,
                    disturbance=disturbance,
                    seed=seed + 1000 * j + 100 * i + rep,
                )
                runs.append(float(np.mean(y[t >= settle_s - 1e-12][:samples])))
            means[i, j] = float(np.mean(runs)) * RPM_PER_RADPS
    return sp, means


@dataclass(frozen=True, eq=False)
class MotorTuning:
    """Seed 003 §IV.A on a twin's motor: the procedure, the rules compared, the choice.

    Attributes:
        ultimate: Ku and Pu of the P-only loop at the set point.
        comparisons: each rule's gains and 100 rpm step response (the classic PID row first).
        chosen: the comparison whose gains are installed: the classic row, or the first
            refinement within ``max_overshoot`` when the classic row overshoots more.
        max_overshoot: the overshoot accepted without refinement.
    """

    ultimate: UltimatePoint
    comparisons: tuple[RuleComparison, ...]
    chosen: RuleComparison
    max_overshoot: float

    @property
    def classic(self) -> RuleComparison:
        """The classic Ziegler–Nichols PID row (seed 003's "Ziegler–Nichols 2")."""
        return self.comparisons[0]

    @property
    def refined(self) -> bool:
        """True when the installed gains are a refinement, not the classic row."""
        return self.chosen.rule != ZnRule.PID


def seed003_motor_tuning(
    drive_train: DriveTrain,
    motor: WheelMotor,
    *,
    output_limit_radps: float = math.inf,
    disturbance: LoopDisturbance | None = None,
    setpoint_rpm: float = 100.0,
    max_overshoot: float = 0.25,
    seed: int = 0,
) -> MotorTuning:
    """Seed 003's tuning on one motor: Ziegler–Nichols 2 at ``setpoint_rpm``, refined if needed.

    The ultimate gain and period come from the gain bisection on the noise-free P-only loop
    (:func:`tune_wheel_speed_pid`); each rule's PID, with the firmware's output limit and
    conditional anti-windup, is stepped to the set point; the classic row is kept unless its
    overshoot exceeds ``max_overshoot``, then the first refinement (some-overshoot,
    Tyreus–Luyben, no-overshoot) within it is chosen (the least overshoot if none is).
    """
    ultimate, _ = tune_wheel_speed_pid(
        drive_train, setpoint_radps=setpoint_rpm / RPM_PER_RADPS, motor=motor
    )
    template = PidParams(
        kp=1.0,
        output_min=-output_limit_radps,
        output_max=output_limit_radps,
        anti_windup=AntiWindup.CONDITIONAL,
    )
    comparisons = compare_rules(
        drive_train,
        ultimate,
        setpoint_rpm=setpoint_rpm,
        motor=motor,
        disturbance=disturbance,
        seed=seed,
        template=template,
    )
    chosen = comparisons[0]
    if chosen.metrics.overshoot > max_overshoot:
        within = [c for c in comparisons[1:] if c.metrics.overshoot <= max_overshoot]
        chosen = within[0] if within else min(comparisons, key=lambda c: c.metrics.overshoot)
    return MotorTuning(ultimate, comparisons, chosen, max_overshoot)
