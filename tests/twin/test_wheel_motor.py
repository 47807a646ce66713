"""The true wheel motor: a first-order lag with gain and lag errors, Coulomb and viscous friction."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest

from omnical.errors import ConfigError
from omnical.robot.loader import load_robot
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.simulator import DigitalTwin
from omnical.twin.wheel_motor import WheelMotor, motor_decay, motor_speed_step

ROSY = load_robot("rosy-mecanum")


def _run(
    motor: WheelMotor, commands: list[float], dt_s: float = 0.001, omega: float = 0.0
) -> list[float]:
    decay = motor_decay(motor, dt_s)
    out = []
    for u in commands:
        omega = motor_speed_step(omega, u, motor, decay)
        out.append(omega)
    return out


def test_nominal_motor_is_the_firmwares_first_order_lag() -> None:
    motor = WheelMotor.nominal(ROSY.drive_train)
    assert motor.is_nominal_form
    assert motor.time_constant_s == ROSY.drive_train.motor_time_constant_s
    y = _run(motor, [3.0] * 200)
    t = np.arange(1, 201) * 0.001
    np.testing.assert_allclose(y, 3.0 * (1.0 - np.exp(-t / 0.05)), rtol=0.0, atol=1e-12)


def test_friction_and_gain_set_the_steady_state() -> None:
    motor = WheelMotor(0.05, gain=0.96, coulomb_friction_radps=1.5, viscous_droop=0.04)
    assert not motor.is_nominal_form
    for u in (10.0, -10.0):
        final = _run(motor, [u] * 2000)[-1]
        assert final == pytest.approx(math.copysign((0.96 * 10.0 - 1.5) / 1.04, u), rel=1e-9)


def test_static_friction_holds_the_wheel_and_never_reverses_it() -> None:
    motor = WheelMotor(0.05, coulomb_friction_radps=1.0)
    assert _run(motor, [0.99] * 100) == [0.0] * 100  # below break-away: stays put
    assert _run(motor, [1.01] * 100)[-1] > 0.0
    # command removed while turning: the wheel coasts down to rest and stays there
    coast = _run(motor, [0.0] * 1000, omega=5.0)
    assert min(coast) == 0.0
    assert all(b <= a for a, b in itertools.pairwise(coast))
    assert coast[-1] == 0.0


@pytest.mark.parametrize(
    "changes",
    [
        {"time_constant_s": 0.0},
        {"gain": -1.0},
        {"coulomb_friction_radps": -0.1},
        {"viscous_droop": math.nan},
    ],
)
def test_out_of_range_motor_is_rejected(changes: dict[str, float]) -> None:
    with pytest.raises(ConfigError, match=next(iter(changes))):
        replace(WheelMotor(0.05), **changes)


def test_ideal_twin_motors_are_nominal_and_default_twin_motors_differ() -> None:
    dt = ROSY.drive_train
    assert all(m == WheelMotor.nominal(dt) for m in TwinParams.ideal_twin().wheel_motors(dt, 4))
    true = default_twin(ROSY).wheel_motors(dt, 4)
    assert len({m.gain for m in true}) == 4
    assert all(0.9 < m.gain < 1.0 and m.time_constant_s > dt.motor_time_constant_s for m in true)
    with pytest.raises(ConfigError, match="motor_gain_errors"):
        TwinParams(motor_gain_errors=(0.0, 0.0)).wheel_motors(dt, 4)


def _drive_1m(params: TwinParams) -> tuple[float, list[float]]:
    twin = DigitalTwin(ROSY, replace(params, start_pose_map=(0.0, 0.0, 0.0)), seed=2)
    twin.send_twist(0.2, 0.0, 0.0)
    twin.advance_to(5.0)  # 0.2 m/s for 5 s, ramps in and out symmetric: 1 m
    wheels = list(twin.read_state().wheel_speeds_radps)
    twin.stop()
    twin.advance_to(8.0)
    return twin.read_state().odom_pose[0], wheels


def test_odometry_lags_the_commanded_motion_by_millimetres_on_the_default_twin() -> None:
    ideal_x, _ = _drive_1m(TwinParams.ideal_twin())
    assert ideal_x == pytest.approx(1.0, abs=1e-4)
    real_x, wheels = _drive_1m(default_twin(ROSY))
    # the PI loop brings each wheel to its reference (to the encoder resolution) ...
    step = 2 * math.pi / ROSY.drive_train.counts_per_wheel_rev / 0.01
    np.testing.assert_allclose(np.abs(wheels), 0.2 / 0.0762, atol=1.5 * step)
    # ... but its integrator holds the Coulomb friction with the wheels a few mrad behind
    assert 0.003 < 1.0 - real_x < 0.012
