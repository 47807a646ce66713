"""Discrete plants, the motor model and seed 003 Table II on simulated motors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from omnical.control import (
    PidParams,
    discretize_plant,
    motor_speed_plant,
    simulate_p_loop,
    simulate_pid_loop,
    speed_tracking_table,
)
from omnical.errors import ConfigError


def test_first_order_step_response_is_exact() -> None:
    plant = discretize_plant([3.0], [0.5, 1.0], 0.01)
    assert plant.dc_gain == pytest.approx(3.0)
    # P loop with kp = 1 around K/(τs+1): the ZOH recursion y+ = a y + K (1 − a)(r − y)
    t, y = simulate_p_loop(plant, 1.0, 1.0, setpoint=2.0)
    a = math.exp(-0.01 / 0.5)
    expected = [0.0]
    for _ in range(t.size - 1):
        expected.append(a * expected[-1] + 3.0 * (1.0 - a) * (2.0 - expected[-1]))
    np.testing.assert_allclose(y, expected, rtol=1e-12, atol=1e-12)


def test_dead_time_shifts_the_response() -> None:
    num, den = [1.0], [0.2, 1.0]
    fast = discretize_plant(num, den, 0.01)
    slow = discretize_plant(num, den, 0.01, dead_time_s=0.05)
    assert slow.a.shape == (6, 6)
    u = np.ones(50)
    y_fast, y_slow = np.zeros(50), np.zeros(50)
    x_fast, x_slow = np.zeros(1), np.zeros(6)
    for k in range(50):
        y_fast[k], y_slow[k] = fast.c @ x_fast, slow.c @ x_slow
        x_fast, x_slow = fast.a @ x_fast + fast.b * u[k], slow.a @ x_slow + slow.b * u[k]
    np.testing.assert_allclose(y_slow[5:], y_fast[:-5], atol=1e-15)
    np.testing.assert_array_equal(y_slow[:6], 0.0)


def test_discretisation_matches_scipy_step() -> None:
    den = np.polymul([0.12, 1.0], [0.01, 1.0])
    plant = discretize_plant([0.64], den, 0.01)
    _, (ref,) = signal.dstep(signal.cont2discrete(signal.tf2ss([0.64], den), 0.01), n=40)
    x, y = np.zeros(plant.a.shape[0]), []
    for _ in range(40):
        y.append(plant.c @ x)
        x = plant.a @ x + plant.b
    np.testing.assert_allclose(y, ref[:, 0], atol=1e-12)


def test_motor_reaches_seed003_speeds() -> None:
    motor = motor_speed_plant()
    assert motor.dc_gain == pytest.approx(0.64)
    assert motor.input_max * motor.dc_gain > 200.0  # 200 rpm is within the PWM range
    assert motor.dt_s == 0.01


def test_speed_tracking_table_like_seed003_table2() -> None:
    pid = PidParams(kp=5.0, ti_s=0.079, td_s=0.02, output_min=-1023.0, output_max=1023.0)
    motors = [
        motor_speed_plant(),
        motor_speed_plant(gain_rpm_per_count=0.60, mechanical_time_constant_s=0.13),
        motor_speed_plant(gain_rpm_per_count=0.67, mechanical_time_constant_s=0.11),
        motor_speed_plant(gain_rpm_per_count=0.62),
    ]
    table = speed_tracking_table(motors, pid, repeats=10, noise_rpm=1.0, rng=np.random.default_rng(3))
    np.testing.assert_array_equal(table.setpoint_rpm, np.arange(110.0, 201.0, 10.0))
    assert table.mean_rpm.shape == (10, 4)
    # seed 003 Table II: every motor within 0.5 % of each set point
    assert np.abs(table.error_pct).max() < 0.5
    assert np.abs(table.error_pct).max() > 0.0  # noise makes it imperfect
    rows = table.rows()
    assert rows[0][0] == 110.0
    assert rows[-1][1:] == pytest.approx([200.0] * 4, abs=1.0)


def test_noise_needs_a_generator() -> None:
    with pytest.raises(ConfigError, match="rng"):
        simulate_pid_loop(motor_speed_plant(), PidParams(kp=1.0), [100.0], 1.0, noise_std=1.0)


@pytest.mark.parametrize(
    ("num", "den", "kwargs", "match"),
    [
        ([1.0, 0.0], [1.0, 1.0], {}, "strictly proper"),
        ([1.0], [1.0, 1.0], {"dead_time_s": 0.015}, "multiple"),
        ([1.0], [1.0, 1.0], {"dead_time_s": -0.01}, "dead time"),
    ],
)
def test_discretize_rejects(num: list[float], den: list[float], kwargs: dict[str, float], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        discretize_plant(num, den, 0.01, **kwargs)


def test_motor_rejects_non_positive_constants() -> None:
    with pytest.raises(ConfigError, match="mechanical_time_constant_s"):
        motor_speed_plant(mechanical_time_constant_s=0.0)
