"""Closed-loop Ziegler–Nichols against plants whose ultimate gain and period are known.

The known-answer plants are continuous transfer functions discretised here (zero-order hold,
dead time as a shift register); the wheel-speed plant omnical tunes in production is the twin's
(:mod:`omnical.twin.motor`, tested in tests/twin/test_motor.py).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import pytest
from scipy import signal
from scipy.optimize import brentq

from omnical.control.pid import PidParams
from omnical.control.ziegler_nichols import (
    ZnRule,
    analyse_oscillation,
    find_ultimate_gain,
    ziegler_nichols_gains,
)
from omnical.errors import CalibrationError, ConfigError


@dataclass(frozen=True, eq=False)
class _Plant:
    """x+ = A x + B u, y = C x, sampled every dt_s."""

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    dt_s: float


def discretize_plant(
    num: list[float], den: np.ndarray | list[float], dt_s: float, *, dead_time_s: float = 0.0
) -> _Plant:
    """ZOH discretisation of num(s)/den(s) e^(−sL), L a whole number of periods."""
    numd, dend, _ = signal.cont2discrete((num, den), dt_s, method="zoh")
    a, b, c, _ = signal.tf2ss(np.ravel(numd)[1:], np.ravel(dend))
    n, delay = a.shape[0], round(dead_time_s / dt_s)
    big_a = np.zeros((n + delay, n + delay))
    big_a[:n, :n] = a
    big_b = np.concatenate([np.ravel(b), np.zeros(delay)])
    big_c = np.zeros(n + delay)
    if delay == 0:
        big_c[:n] = np.ravel(c)
    else:
        big_a[n, :n] = np.ravel(c)
        for i in range(1, delay):
            big_a[n + i, n + i - 1] = 1.0
        big_c[-1] = 1.0
    return _Plant(big_a, big_b, big_c, dt_s)


def simulate_p_loop(
    plant: _Plant, kp: float, duration_s: float, *, setpoint: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Step response of u = kp (r − y) from rest: the Ziegler–Nichols experiment."""
    steps = max(2, math.ceil(duration_s / plant.dt_s - 1e-9) + 1)
    x, y = np.zeros(plant.a.shape[0]), np.empty(steps)
    for k in range(steps):
        y[k] = plant.c @ x
        x = plant.a @ x + plant.b * (kp * (setpoint - y[k]))
    return np.arange(steps, dtype=np.float64) * plant.dt_s, y


def test_known_answer_plants_are_discretised_exactly() -> None:
    # first order under P control: the ZOH recursion y+ = a y + K (1 − a) kp (r − y)
    plant = discretize_plant([3.0], [0.5, 1.0], 0.01)
    t, y = simulate_p_loop(plant, 1.0, 1.0, setpoint=2.0)
    a = math.exp(-0.01 / 0.5)
    expected = [0.0]
    for _ in range(t.size - 1):
        expected.append(a * expected[-1] + 3.0 * (1.0 - a) * (2.0 - expected[-1]))
    np.testing.assert_allclose(y, expected, rtol=1e-12, atol=1e-12)
    # a dead time of five periods shifts the open-loop step response by five samples
    fast = discretize_plant([1.0], [0.2, 1.0], 0.01)
    slow = discretize_plant([1.0], [0.2, 1.0], 0.01, dead_time_s=0.05)
    x_fast, x_slow, y_fast, y_slow = np.zeros(1), np.zeros(6), np.zeros(50), np.zeros(50)
    for k in range(50):
        y_fast[k], y_slow[k] = fast.c @ x_fast, slow.c @ x_slow
        x_fast, x_slow = fast.a @ x_fast + fast.b, slow.a @ x_slow + slow.b
    np.testing.assert_allclose(y_slow[5:], y_fast[:-5], atol=1e-15)
    np.testing.assert_array_equal(y_slow[:6], 0.0)


def test_oscillation_of_known_signals() -> None:
    t = np.linspace(0.0, 10.0, 10_001)
    decaying = analyse_oscillation(t, 1.0 - np.exp(-0.2 * t) * np.cos(2.0 * math.pi * t))
    assert decaying.period_s == pytest.approx(1.0, rel=1e-3)
    assert decaying.growth_per_period == pytest.approx(math.exp(-0.2), rel=1e-2)
    assert not decaying.growing
    growing = analyse_oscillation(t, np.exp(0.1 * t) * np.sin(2.0 * math.pi * 0.5 * t))
    assert growing.period_s == pytest.approx(2.0, rel=1e-3)
    assert growing.growth_per_period == pytest.approx(math.exp(0.2), rel=1e-2)
    assert growing.growing
    flat = analyse_oscillation(t, 1.0 - np.exp(-t))
    assert flat.growth_per_period == 0.0
    assert math.isnan(flat.period_s)
    assert analyse_oscillation(t[:3], [0.0, math.inf, 1.0]).growing


def test_third_order_lag_ultimate_point() -> None:
    # K/(τs+1)³: phase −π at ω = √3/τ, |G| = K/8 there, so Ku = 8/K and Pu = 2πτ/√3
    K, tau = 2.0, 0.1
    den = np.polymul(np.polymul([tau, 1.0], [tau, 1.0]), [tau, 1.0])
    plant = discretize_plant([K], den, tau / 200)
    point = find_ultimate_gain(functools.partial(simulate_p_loop, plant), 20 * 0.363)
    assert point.ku == pytest.approx(8.0 / K, rel=0.02)
    assert point.pu_s == pytest.approx(2.0 * math.pi * tau / math.sqrt(3.0), rel=0.01)
    assert point.experiments < 25


def test_first_order_plus_dead_time_ultimate_point() -> None:
    # K e^(−Ls)/(Ts+1): atan(ωT) + ωL = π, Ku = √(1 + ω²T²)/K, Pu = 2π/ω
    K, T, L = 2.0, 1.0, 0.2
    w = brentq(lambda w: math.atan(w * T) + w * L - math.pi, 1e-3, math.pi / L)
    plant = discretize_plant([K], [T, 1.0], 0.002, dead_time_s=L)
    point = find_ultimate_gain(functools.partial(simulate_p_loop, plant), 15.0)
    assert point.ku == pytest.approx(math.sqrt(1.0 + (w * T) ** 2) / K, rel=0.02)
    assert point.pu_s == pytest.approx(2.0 * math.pi / w, rel=0.02)


def test_sampled_first_order_lag_oscillates_at_the_nyquist_rate() -> None:
    # y+ = a y + K (1 − a) kp (r − y): the pole a − K (1 − a) kp leaves the unit circle at −1,
    # so Ku = (1 + a) / (K (1 − a)) and Pu = 2 Δt (sampling alone adds the lag)
    K, tau, dt = 1.0, 0.1, 0.01
    a = math.exp(-dt / tau)
    plant = discretize_plant([K], [tau, 1.0], dt)
    point = find_ultimate_gain(functools.partial(simulate_p_loop, plant), 2.0)
    assert point.ku == pytest.approx((1.0 + a) / (K * (1.0 - a)), rel=2e-3)
    assert point.pu_s == pytest.approx(2.0 * dt)


def test_continuous_first_order_lag_never_oscillates() -> None:
    def simulate(kp: float, duration_s: float) -> tuple[np.ndarray, np.ndarray]:
        t = np.linspace(0.0, duration_s, 2001)  # exact closed loop of 1/(0.1 s + 1), kp
        return t, kp / (1.0 + kp) * (1.0 - np.exp(-(1.0 + kp) * t / 0.1))

    with pytest.raises(CalibrationError, match="no sustained oscillation"):
        find_ultimate_gain(simulate, 2.0, max_doublings=30)


def test_classic_rules() -> None:
    pid = ziegler_nichols_gains(10.0, 4.0)
    assert (pid.kp, pid.ti_s, pid.td_s) == (6.0, 2.0, 0.5)
    pi = ziegler_nichols_gains(10.0, 4.0, ZnRule.PI)
    assert (pi.kp, pi.ti_s, pi.td_s) == pytest.approx((4.5, 4.0 / 1.2, 0.0))
    p = ziegler_nichols_gains(10.0, 4.0, ZnRule.P)
    assert (p.kp, p.ti_s, p.td_s) == (5.0, math.inf, 0.0)
    kept = ziegler_nichols_gains(10.0, 4.0, template=PidParams(kp=1.0, output_max=255.0))
    assert (kept.kp, kept.output_max) == (6.0, 255.0)
    # seed 003's Kp = 5, Ti = 2.8 invert to Ku = 8.33, Pu = 5.6, for which the rule gives Td = 0.7
    seed = ziegler_nichols_gains(5.0 / 0.6, 5.6)
    assert (seed.kp, seed.ti_s, seed.td_s) == pytest.approx((5.0, 2.8, 0.7))
    with pytest.raises(ConfigError, match="Ku and Pu"):
        ziegler_nichols_gains(0.0, 1.0)
    with pytest.raises(ConfigError, match="rule"):
        ziegler_nichols_gains(1.0, 1.0, "PD")  # type: ignore[arg-type]


def test_search_rejects_bad_settings() -> None:
    plant = discretize_plant([1.0], [0.1, 1.0], 0.01)
    with pytest.raises(ConfigError, match="kp_start"):
        find_ultimate_gain(functools.partial(simulate_p_loop, plant), 1.0, kp_start=0.0)


def test_refined_rules_and_step_metrics() -> None:
    from omnical.control.ziegler_nichols import step_response_metrics

    tl = ziegler_nichols_gains(2.2, 1.0, ZnRule.TYREUS_LUYBEN)
    assert (tl.kp, tl.ti_s, tl.td_s) == pytest.approx((1.0, 2.2, 1 / 6.3))
    some = ziegler_nichols_gains(3.0, 2.0, ZnRule.PID_SOME_OVERSHOOT)
    assert (some.kp, some.ti_s, some.td_s) == pytest.approx((1.0, 1.0, 2 / 3))
    t = np.linspace(0.0, 10.0, 1001)
    y = 1.0 - np.exp(-t) * np.cos(3.0 * t)
    m = step_response_metrics(t, y, 1.0)
    peak = 1.0 + np.max(-np.exp(-t) * np.cos(3.0 * t))
    assert m.overshoot == pytest.approx(peak - 1.0, rel=1e-9)
    assert 3.0 < m.settling_time_s < 4.5
    assert step_response_metrics(t, np.ones_like(t), 1.0).overshoot == 0.0
