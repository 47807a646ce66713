"""Ziegler–Nichols on the twin's wheel-speed loop (seed 003 §IV.A, Table II)."""

from __future__ import annotations

import numpy as np
import pytest

from omnical.control.pid import PidParams
from omnical.robot import load_robot
from omnical.twin.motor import (
    RPM_PER_RADPS,
    tune_wheel_speed_pid,
    wheel_speed_loop,
    wheel_speed_tracking,
)


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
    setpoints, means = wheel_speed_tracking(dt, pid)
    np.testing.assert_array_equal(setpoints, np.arange(110, 201, 10))
    assert np.all(np.abs(means - setpoints) / setpoints < 0.01)


def test_p_only_loop_has_a_steady_state_offset() -> None:
    dt = load_robot("rosy-mecanum").drive_train
    t, y = wheel_speed_loop(dt, PidParams(kp=2.0), 150 / RPM_PER_RADPS, 2.0)
    # unit steady-state plant gain: y = Kp / (1 + Kp) r
    assert y[t > 1.5].mean() * RPM_PER_RADPS == pytest.approx(150 * 2 / 3, rel=0.01)
