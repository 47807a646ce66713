"""The discrete PID: each term on known inputs, saturation, anti-windup."""

from __future__ import annotations

import math

import pytest

from omnical.control.pid import (
    SEED003_MOTOR_PID,
    AntiWindup,
    PidParams,
    PidState,
    pid_step,
)
from omnical.errors import ConfigError


def test_proportional_only() -> None:
    out, state = pid_step(PidParams(kp=5.0), PidState(), 100.0, 90.0, 0.01)
    assert out == 50.0
    assert state.integral == 0.0
    assert state.last_measurement == 90.0


def test_integral_accumulates_kp_over_ti() -> None:
    params = PidParams(kp=2.0, ti_s=0.5)
    state = PidState()
    outputs = []
    for _ in range(10):
        out, state = pid_step(params, state, 1.0, 0.0, 0.1)
        outputs.append(out)
    # I after k steps = k · Kp Δt/Ti · e = 0.4 k; output k uses the integral before it
    assert outputs == pytest.approx([2.0 + 0.4 * k for k in range(10)])
    assert state.integral == pytest.approx(4.0)
    assert params.ki == 4.0


def test_derivative_acts_on_measurement_only() -> None:
    params = PidParams(kp=2.0, td_s=0.5, derivative_filter_n=10.0)
    _, state = pid_step(params, PidState(), 0.0, 0.0, 0.01)
    # a set-point step gives no derivative kick
    out, state = pid_step(params, state, 10.0, 0.0, 0.01)
    assert out == 20.0
    assert state.derivative == 0.0
    # a measurement ramp of slope 1/s: D settles at −Kp Td · 1 with time constant Td/N = 0.05 s
    y, dt = 0.0, 0.01
    for _ in range(200):
        y += dt
        out, state = pid_step(params, state, 10.0, y, dt)
    assert state.derivative == pytest.approx(-params.kd, rel=1e-6)
    assert out == pytest.approx(2.0 * (10.0 - y) - 1.0, rel=1e-6)
    # first backward-difference step from rest: −Kp Td Δy / (Tf + Δt)
    _, fresh = pid_step(params, PidState(0.0, 0.0, 0.0), 0.0, 0.01, 0.01)
    assert fresh.derivative == pytest.approx(-1.0 * 0.01 / (0.05 + 0.01))


def test_first_step_has_no_derivative() -> None:
    out, state = pid_step(PidParams(kp=1.0, td_s=1.0), PidState(), 0.0, 5.0, 0.01)
    assert out == -5.0
    assert state.derivative == 0.0


def test_output_saturates() -> None:
    params = PidParams(kp=10.0, output_min=-1.0, output_max=2.0)
    assert pid_step(params, PidState(), 1.0, 0.0, 0.01)[0] == 2.0
    assert pid_step(params, PidState(), -1.0, 0.0, 0.01)[0] == -1.0


def _saturate_then_release(mode: AntiWindup) -> tuple[float, int]:
    """Drive into saturation for 5 s, then reverse the error; return I and steps to unsaturate."""
    params = PidParams(kp=1.0, ti_s=0.5, output_min=-1.0, output_max=1.0, anti_windup=mode)
    state = PidState()
    for _ in range(500):
        _, state = pid_step(params, state, 10.0, 0.0, 0.01)
    windup = state.integral
    for k in range(1, 20_000):
        out, state = pid_step(params, state, -0.5, 0.0, 0.01)
        if out < 1.0:
            return windup, k
    return windup, 20_000


def test_anti_windup_keeps_the_integral_bounded() -> None:
    none_i, none_steps = _saturate_then_release(AntiWindup.NONE)
    cond_i, cond_steps = _saturate_then_release(AntiWindup.CONDITIONAL)
    back_i, back_steps = _saturate_then_release(AntiWindup.BACK_CALCULATION)
    assert none_i == pytest.approx(100.0)  # 5 s · Kp/Ti · e = 5 · 2 · 10
    assert cond_i == pytest.approx(0.0)  # P alone saturates from the first step
    assert back_i == pytest.approx(1.0, abs=1e-3)  # Kp/Ti · e = (Δt/Tt)/Δt · (v − u): I = 1
    # without anti-windup, I must unwind from 100 to 1.5 at Kp Δt/Ti · 0.5 = 0.01 per step
    assert none_steps == pytest.approx(9852, abs=1)
    assert cond_steps == 1
    assert back_steps == 1


def test_back_calculation_tracking_time() -> None:
    assert PidParams(kp=1.0, ti_s=2.0, td_s=0.5).tracking_s == 1.0
    assert PidParams(kp=1.0, ti_s=2.0).tracking_s == 2.0
    assert PidParams(kp=1.0, ti_s=2.0, tracking_time_s=0.3).tracking_s == 0.3


def test_seed003_gains() -> None:
    assert (SEED003_MOTOR_PID.kp, SEED003_MOTOR_PID.ti_s, SEED003_MOTOR_PID.td_s) == (5.0, 2.8, 0.6)
    assert SEED003_MOTOR_PID.kd == pytest.approx(3.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"kp": math.nan}, "kp"),
        ({"kp": 1.0, "ti_s": 0.0}, "ti_s"),
        ({"kp": 1.0, "td_s": -1.0}, "td_s"),
        ({"kp": 1.0, "derivative_filter_n": 0.0}, "derivative_filter_n"),
        ({"kp": 1.0, "output_min": 1.0, "output_max": 1.0}, "empty"),
        ({"kp": 1.0, "tracking_time_s": 0.0}, "tracking_time_s"),
        ({"kp": 1.0, "anti_windup": "clamp"}, "anti_windup"),
    ],
)
def test_params_are_validated(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        PidParams(**kwargs)  # type: ignore[arg-type]


def test_bad_time_step() -> None:
    with pytest.raises(ConfigError, match="time step"):
        pid_step(PidParams(kp=1.0), PidState(), 0.0, 0.0, 0.0)
