"""Odometry from wheel encoder JointStates through the kinematics, and the odometry sources."""

from __future__ import annotations

import math
from dataclasses import replace
from importlib import resources

import numpy as np
import pytest
import yaml

from omnical.errors import ConfigError, RecordingError
from omnical.estimation.odometry_sources import (
    OdometrySource,
    corrected_odometry,
    seed003_odometry_of,
    with_odometry,
)
from omnical.estimation.seed003_estimator import seed003_samples_of, seed003_track
from omnical.estimation.wheel_odometry import (
    repair_counter_jumps,
    wheel_angles_of,
    wheel_odometry,
    with_wheel_odometry,
)
from omnical.experiment.library import builtin_script_data
from omnical.experiment.script import parse_script
from omnical.kinematics.correction import CorrectionFactors, counter_compensate_twist
from omnical.kinematics.jacobian import inverse_jacobian
from omnical.recording.recording import Recording, RecordingBuilder
from omnical.robot.description import RobotDescription, WheelEncoders
from omnical.robot.loader import load_robot, parse_robot
from omnical.twin.params import default_twin
from omnical.twin.session import simulate_run

MECANUM = load_robot("rosy-mecanum")
CPR = 42 * 18.5


def _preset(name: str) -> dict[str, object]:
    text = resources.files("omnical.data.robots").joinpath(f"{name}.yaml").read_text("utf-8")
    data: dict[str, object] = yaml.safe_load(text)
    return data


def _with_encoders(section: dict[str, object]) -> RobotDescription:
    return parse_robot({**_preset("rosy-mecanum"), "wheel_encoders": section}, "test robot")


def _twists(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 20.0, n)
    return np.column_stack(
        [0.3 * np.sin(0.4 * t), 0.25 * np.cos(0.3 * t), 0.5 * np.sin(0.2 * t + 1.0)]
    ) + rng.normal(0.0, 0.01, (n, 3))


def _truth_and_angles(n: int = 1001) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times, poses composed from body increments, and the wheel angles making them."""
    t = np.linspace(0.0, 20.0, n)
    body = _twists(n - 1) * np.diff(t)[:, None]
    yaw = np.concatenate([[0.0], np.cumsum(body[:, 2])])
    c, s = np.cos(yaw[:-1] + 0.5 * body[:, 2]), np.sin(yaw[:-1] + 0.5 * body[:, 2])
    step = np.column_stack([c * body[:, 0] - s * body[:, 1], s * body[:, 0] + c * body[:, 1]])
    xy = np.vstack([np.zeros((1, 2)), np.cumsum(step, axis=0)])
    angles = np.vstack(
        [np.zeros((1, 4)), np.cumsum(body @ inverse_jacobian(MECANUM.wheels).T, axis=0)]
    )
    return t, np.column_stack([xy, yaw]), angles


def test_forward_kinematics_of_wheel_angles_composes_the_body_increments() -> None:
    t, truth, angles = _truth_and_angles()
    poses, twist, repaired = wheel_odometry(t, angles, MECANUM.wheels)
    assert repaired == 0
    np.testing.assert_allclose(poses, truth, atol=1e-9)
    assert np.all(twist[0] == 0.0)
    # the twist is the increment over its step
    np.testing.assert_allclose(twist[1:, 2] * np.diff(t), np.diff(truth[:, 2]), atol=1e-12)


def test_ticks_under_driver_names_order_and_signs() -> None:
    _, _, angles = _truth_and_angles(50)
    enc = _with_encoders(
        {
            "counts_per_rev": CPR,
            "joints": {
                "front_left": "fl",
                "front_right": "fr",
                "rear_left": "rl",
                "rear_right": "rr",
            },
            "reversed": ["front_right", "rear_right"],
        }
    ).encoders
    assert enc.counts_per_rev == 777.0 and enc.joints == ("rl", "fl", "fr", "rr")
    published = ["fr", "rr", "fl", "rl"]  # the driver's own order
    index = [enc.joints.index(j) for j in published]
    sign = np.array([-1.0, -1.0, 1.0, 1.0])
    ticks = angles[:, index] * sign * CPR / (2 * math.pi)
    names = np.array([published] * ticks.shape[0], dtype=object)
    rows, back = wheel_angles_of(names, ticks, enc, "/wheels")
    assert rows.tolist() == list(range(ticks.shape[0]))
    np.testing.assert_allclose(back, angles, atol=1e-12)


def test_wheel_encoder_fields_are_checked() -> None:
    with pytest.raises(ConfigError, match="unknown wheel"):
        _with_encoders({"joints": {"front_middle": "x"}})
    with pytest.raises(ConfigError, match="counts_per_rev"):
        _with_encoders({"counts_per_rev": -42.0})
    with pytest.raises(ConfigError, match="unique"):
        _with_encoders({"joints": {"front_left": "a", "rear_left": "a"}})
    assert MECANUM.wheel_encoders is None
    assert MECANUM.encoders == WheelEncoders(tuple(w.name for w in MECANUM.wheels))


def _joint_recording(
    t_ns: np.ndarray, positions: np.ndarray, names: list[str], topic: str = "/wheel_states"
) -> Recording:
    n = t_ns.shape[0]
    b = RecordingBuilder()
    b.add_many(
        topic,
        t_ns,
        name=np.array([names] * n, dtype=object),
        position_rad=positions,
        velocity_radps=np.zeros((n, 0)),
        effort_nm=np.zeros((n, 0)),
    )
    return b.build()


def _names() -> list[str]:
    return [w.name for w in MECANUM.wheels]


def test_a_missing_joint_names_the_joints_found() -> None:
    t, _, angles = _truth_and_angles(20)
    rec = _joint_recording((t * 1e9).astype(np.int64), angles, ["a", "b", "c", "d"])
    with pytest.raises(ConfigError, match=r"no joint named 'rear_left' \(joints: a, b, c, d\)"):
        with_wheel_odometry(rec, "/wheel_states", MECANUM)


@pytest.mark.parametrize("fault", ["nan", "backwards", "repeated"])
def test_bad_samples_are_refused_in_one_line(fault: str) -> None:
    t, _, angles = _truth_and_angles(20)
    if fault == "nan":
        angles[5, 1] = np.nan
        with pytest.raises(RecordingError, match="finite"):
            wheel_odometry(t, angles, MECANUM.wheels)
    elif fault == "backwards":
        t[7] = t[5]
        with pytest.raises(RecordingError, match="times must increase: sample 7 "):
            wheel_odometry(t, angles, MECANUM.wheels)
    else:  # through a recording: same bag time, different positions
        t_ns = (t * 1e9).astype(np.int64)
        t_ns[8] = t_ns[7]
        rec = _joint_recording(t_ns, angles, _names())
        with pytest.raises(RecordingError, match="same bag time") as err:
            with_wheel_odometry(rec, "/wheel_states", MECANUM)
        assert "\n" not in str(err.value)


def test_a_counter_reset_is_bridged_and_counted() -> None:
    t, truth, angles = _truth_and_angles()
    reset = angles.copy()
    reset[600:] -= reset[600]  # the driver restarts: every counter back to zero
    rec = _joint_recording((t * 1e9).astype(np.int64), reset, _names())
    out, odo = with_wheel_odometry(rec, "/wheel_states", MECANUM)
    assert any("counter resets" in n for n in odo.notes)
    err = np.hypot(*(odo.poses[:, :2] - truth[:, :2]).T)
    assert err.max() < 0.01  # one 20 ms step bridged from its neighbours
    plain, _, _ = wheel_odometry(t, reset, MECANUM.wheels)  # unrepaired: a jump of metres
    assert np.hypot(*(plain[-1, :2] - truth[-1, :2])) > 1.0
    assert len(out.topic("/odom")) == t.size


def test_repair_leaves_plausible_steps_alone() -> None:
    t = np.arange(5, dtype=float)
    inc, count = repair_counter_jumps(t, np.arange(5.0)[:, None] * 2.0, 10.0)
    assert count == 0 and np.all(inc == 2.0)


def test_messages_without_the_wheel_joints_are_left_out() -> None:
    t, truth, angles = _truth_and_angles(40)
    names = np.array([_names()] * 40, dtype=object)
    names[10] = ["arm_1", "arm_2", "arm_3", "arm_4"]  # another publisher on the same topic
    b = RecordingBuilder()
    b.add_many(
        "/joint_states",
        (t * 1e9).astype(np.int64),
        name=names,
        position_rad=np.where(np.arange(40)[:, None] == 10, 99.0, angles),
        velocity_radps=np.zeros((40, 0)),
        effort_nm=np.zeros((40, 0)),
    )
    _, odo = with_wheel_odometry(b.build(), "/joint_states", MECANUM)
    assert odo.t_ns.size == 39 and "1 message(s) without every wheel joint" in odo.notes[0]
    np.testing.assert_allclose(odo.poses[-1], truth[-1], atol=2e-3)  # one step twice as long


def test_odometry_sources_replace_odom() -> None:
    t, truth, angles = _truth_and_angles(30)
    rec = _joint_recording((t * 1e9).astype(np.int64), angles, _names())
    with pytest.raises(RecordingError, match="--wheel-topic"):
        with_odometry(rec, OdometrySource.ODOM, MECANUM)
    with pytest.raises(ConfigError, match="--wheel-topic"):
        with_odometry(rec, OdometrySource.WHEELS, MECANUM)
    with pytest.raises(ConfigError, match="no dead wheels"):
        with_odometry(rec, OdometrySource.SEED003, MECANUM)
    out, used = with_odometry(rec, OdometrySource.WHEELS, MECANUM, wheel_topic="/wheel_states")
    odom = out.topic("/odom")
    np.testing.assert_allclose(odom["x_m"], truth[:, 0], atol=1e-9)
    assert used.samples == 30 and "/wheel_states" in used.describe()


def test_corrected_odometry_applies_the_factors_to_each_increment() -> None:
    t, truth, angles = _truth_and_angles(200)
    rec, _ = with_wheel_odometry(
        _joint_recording((t * 1e9).astype(np.int64), angles, _names()), "/wheel_states", MECANUM
    )
    same = corrected_odometry(rec, CorrectionFactors())
    np.testing.assert_allclose(same.topic("/odom")["x_m"], truth[:, 0], atol=1e-9)
    f = CorrectionFactors(1.02, 1.13, 1.0236, 0.0072, -0.00009, 0.0389, -0.0277)
    got = corrected_odometry(rec, f).topic("/odom")
    odom = rec.topic("/odom")
    inc = (
        np.column_stack([odom["vx_mps"], odom["vy_mps"], odom["wz_radps"]])[1:]
        * np.diff(t)[:, None]
    )
    yaw = np.concatenate([[0.0], np.cumsum(counter_compensate_twist(inc, f)[:, 2])])
    np.testing.assert_allclose(np.unwrap(got["yaw_rad"]), yaw, atol=1e-9)
    # undoing installed factors first: corrected with what was installed is the raw odometry
    assert not np.allclose(got["x_m"], odom["x_m"])
    back = corrected_odometry(corrected_odometry(rec, f), CorrectionFactors(), installed=f)
    np.testing.assert_allclose(back.topic("/odom")["x_m"], odom["x_m"], atol=1e-9)


def test_seed003_odometry_is_the_estimator_of_evaluate() -> None:
    robot = load_robot("omni-x")
    script = parse_script(builtin_script_data("straight-10m"), robot.limits)
    rec = simulate_run(script, robot, replace(default_twin(robot)), seed=2)
    out = seed003_odometry_of(rec, robot)
    track = seed003_track(seed003_samples_of(rec, robot.dead_wheels), robot.dead_wheels)
    odom = out.topic("/odom")
    assert len(odom) == track.shape[0]
    np.testing.assert_allclose(odom["x_m"], track[:, 1], atol=1e-12)
    np.testing.assert_allclose(odom.t_s(rec.start_ns), track[:, 0], atol=1e-9)
    assert not np.allclose(odom["x_m"], rec.topic("/odom")["x_m"][: len(odom)])
