"""Ziegler–Nichols on the twin's wheel-speed loop (seed 003 §IV.A, Table II)."""

from __future__ import annotations

import numpy as np
import pytest

from omnical.control.pid import PidParams
from omnical.robot.description import DriveTrain
from omnical.robot.loader import load_robot
from omnical.twin.motor import (
    RPM_PER_RADPS,
    seed003_table2,
    tune_wheel_speed_pid,
    wheel_speed_loop,
)
from omnical.twin.params import default_twin
from omnical.twin.wheel_motor import WheelMotor


def _table2(dt: DriveTrain, pid: PidParams, motor: WheelMotor) -> tuple[np.ndarray, np.ndarray]:
    """Table II on one motor: the mean speed over 2 s after 2 s at each set point (rpm)."""
    samples = round(2.0 * dt.control_rate_hz)
    setpoints, means = seed003_table2(dt, pid, (motor,), samples=samples, repeats=1, settle_s=2.0)
    return setpoints, means[:, 0]


def _swing_growth(kp: float, preset: str) -> float:
    dt = load_robot(preset).drive_train
    t, y = wheel_speed_loop(dt, PidParams(kp=kp), 10.0, 3.0, quantize=False)
    err = y - y[-200:].mean()
    early = np.abs(err[(t > 0.2) & (t < 0.6)]).max()
    late = np.abs(err[(t > 2.0) & (t < 2.4)]).max()
    return float(late / early)


@pytest.mark.parametrize("preset", ["rosy-mecanum", "omni-x"])
def test_ultimate_gain_separates_decay_from_growth(preset: str) -> None:
    ultimate, pid = tune_wheel_speed_pid(load_robot(preset).drive_train)
    assert _swing_growth(0.9 * ultimate.ku, preset) < 0.5
    assert _swing_growth(1.1 * ultimate.ku, preset) > 2.0
    # the period is a few control periods: the loop oscillates through its measurement delay
    assert 0.02 < ultimate.pu_s < 0.08
    # classic rules
    assert pid.kp == pytest.approx(0.6 * ultimate.ku)
    assert pid.ti_s == pytest.approx(ultimate.pu_s / 2)
    assert pid.td_s == pytest.approx(ultimate.pu_s / 8)


@pytest.mark.parametrize("preset", ["rosy-mecanum", "omni-x"])
def test_tuned_loop_tracks_seed003_set_points_within_1_percent(preset: str) -> None:
    dt = load_robot(preset).drive_train
    _, pid = tune_wheel_speed_pid(dt)
    setpoints, means = _table2(dt, pid, WheelMotor.nominal(dt))
    np.testing.assert_array_equal(setpoints, np.arange(110, 201, 10))
    assert np.all(np.abs(means - setpoints) / setpoints < 0.01)


def test_p_only_loop_has_a_steady_state_offset() -> None:
    dt = load_robot("rosy-mecanum").drive_train
    t, y = wheel_speed_loop(dt, PidParams(kp=2.0), 150 / RPM_PER_RADPS, 2.0)
    # unit steady-state plant gain: y = Kp / (1 + Kp) r
    assert y[t > 1.5].mean() * RPM_PER_RADPS == pytest.approx(150 * 2 / 3, rel=0.01)


def test_p_only_steady_state_of_the_true_motor_shows_gain_friction_and_droop() -> None:
    robot = load_robot("rosy-mecanum")
    dt = robot.drive_train
    motor = default_twin(robot).wheel_motors(dt, robot.wheel_count)[1]
    assert motor.gain < 1.0
    assert motor.coulomb_friction_radps > 0.0
    assert motor.viscous_droop > 0.0
    kp, r = 2.0, 150 / RPM_PER_RADPS
    t, y = wheel_speed_loop(dt, PidParams(kp=kp), r, 2.0, quantize=False, motor=motor)
    # ω (1 + b) = K kp (r − ω) − ω_c
    k, b, c = motor.gain, motor.viscous_droop, motor.coulomb_friction_radps
    assert y[t > 1.5].mean() == pytest.approx((k * kp * r - c) / (1.0 + b + k * kp), rel=1e-6)


def test_true_motors_tune_to_a_higher_ultimate_gain_at_the_same_period() -> None:
    robot = load_robot("rosy-mecanum")
    dt = robot.drive_train
    nominal, _ = tune_wheel_speed_pid(dt)
    for motor in default_twin(robot).wheel_motors(dt, robot.wheel_count):
        ultimate, _ = tune_wheel_speed_pid(dt, motor=motor)
        # a weaker, slower, loaded motor needs more gain to oscillate; the period is set by
        # the measurement delay of the encoder speed, not by the motor
        assert 1.05 * nominal.ku < ultimate.ku < 1.3 * nominal.ku
        assert ultimate.pu_s == pytest.approx(nominal.pu_s, rel=0.03)


def test_seed003_table2_on_the_four_true_motors_of_the_omni_x_twin() -> None:
    # seed 003 tunes one PID by Ziegler–Nichols and runs it on all four motors (Table II)
    robot = load_robot("omni-x")
    dt = robot.drive_train
    motors = default_twin(robot).wheel_motors(dt, robot.wheel_count)
    _, pid = tune_wheel_speed_pid(dt, motor=motors[0])
    for motor in motors:
        setpoints, means = _table2(dt, pid, motor)
        error = np.abs(means - setpoints) / setpoints
        assert error.max() < 0.005  # every motor within 0.5 % of each set point


def test_omni_x_default_twin_installs_the_procedures_refined_gains() -> None:
    from omnical.control.ziegler_nichols import ZnRule
    from omnical.twin.motor import LoopDisturbance, seed003_motor_tuning
    from omnical.twin.params import OMNI_X_WHEEL_KU, OMNI_X_WHEEL_PID, OMNI_X_WHEEL_PU_S
    from omnical.twin.simulator import wheel_command_limit

    robot = load_robot("omni-x")
    params = default_twin(robot)
    motor = params.wheel_motors(robot.drive_train, robot.wheel_count)[0]
    tuning = seed003_motor_tuning(
        robot.drive_train,
        motor,
        output_limit_radps=wheel_command_limit(robot),
        disturbance=LoopDisturbance.of_twin(params),
    )
    assert (tuning.ultimate.ku, tuning.ultimate.pu_s) == (OMNI_X_WHEEL_KU, OMNI_X_WHEEL_PU_S)
    assert tuning.classic.metrics.overshoot > 0.6  # the classic row rings
    assert tuning.chosen.rule == ZnRule.TYREUS_LUYBEN
    assert tuning.chosen.metrics.overshoot < 0.15
    assert params.wheel_pid == OMNI_X_WHEEL_PID
    for name in ("kp", "ti_s", "td_s"):
        assert getattr(tuning.chosen.pid, name) == getattr(OMNI_X_WHEEL_PID, name)
    # the Mecanum twin keeps its PI with feed-forward
    assert default_twin(load_robot("rosy-mecanum")).wheel_pid is None


def test_installed_pid_drives_the_twin() -> None:
    from dataclasses import replace

    from omnical.twin.simulator import DigitalTwin

    robot = load_robot("omni-x")
    params = default_twin(robot)
    speeds = {}
    for pid in (params.wheel_pid, None):
        twin = DigitalTwin(robot, replace(params, wheel_pid=pid), seed=1)
        twin.send_twist(0.3, 0.0, 0.0)
        twin.advance_to(3.0)
        speeds[pid is None] = twin.read_state().odom_twist[0]
    assert speeds[False] == pytest.approx(0.3, abs=0.01)
    assert speeds[False] != speeds[True]
