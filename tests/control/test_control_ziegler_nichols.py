"""Closed-loop Ziegler–Nichols against plants whose ultimate gain and period are known."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from omnical.control import (
    PidParams,
    ZnRule,
    analyse_oscillation,
    discretize_plant,
    find_ultimate_gain,
    motor_speed_plant,
    simulate_p_loop,
    simulate_pid_loop,
    ziegler_nichols_gains,
)
from omnical.errors import CalibrationError, ConfigError


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


def test_tuned_pid_tracks_the_motor_within_1_percent() -> None:
    motor = motor_speed_plant()
    point = find_ultimate_gain(functools.partial(simulate_p_loop, motor, setpoint=100.0), 6.0)
    assert point.ku == pytest.approx(8.3, rel=0.02)  # so that 0.6 Ku is seed 003's Kp = 5
    assert point.pu_s == pytest.approx(0.157, rel=0.03)
    limits = PidParams(kp=1.0, output_min=-1023.0, output_max=1023.0)
    pid = ziegler_nichols_gains(point.ku, point.pu_s, template=limits)
    assert pid.kp == pytest.approx(5.0, rel=0.02)
    t, speed, pwm = simulate_pid_loop(motor, pid, [100.0, 150.0, 200.0], 3.0)
    steady = speed[:, t >= 2.0]
    assert np.abs(steady / np.array([[100.0], [150.0], [200.0]]) - 1.0).max() < 0.01
    assert np.abs(pwm).max() <= 1023.0
    # proportional-only control leaves the classic offset 1/(1 + K Kp) instead
    p_only = ziegler_nichols_gains(point.ku, point.pu_s, ZnRule.P, template=limits)
    _, speed_p, _ = simulate_pid_loop(motor, p_only, [100.0], 3.0)
    offset = 1.0 / (1.0 + motor.dc_gain * p_only.kp)
    assert speed_p[0, -1] == pytest.approx(100.0 * (1.0 - offset), rel=1e-3)


def test_search_rejects_bad_settings() -> None:
    plant = motor_speed_plant()
    with pytest.raises(ConfigError, match="kp_start"):
        find_ultimate_gain(functools.partial(simulate_p_loop, plant), 1.0, kp_start=0.0)
