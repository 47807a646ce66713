"""The live correction of ``omnical ros2 correct``, one sample at a time, against the offline one
(``corrected_odometry``, ``wheel_odometry``) and its covariance against finite differences."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from omnical.estimation.odometry_sources import corrected_odometry
from omnical.estimation.wheel_odometry import wheel_odometry
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.jacobian import forward_jacobian, inverse_jacobian
from omnical.recording.recording import RecordingBuilder
from omnical.recording.topics import ODOM
from omnical.robot.loader import load_robot
from omnical.ros2.correct import (
    CorrectedOdometry,
    correct_pose_step,
    correct_wheel_step,
    factor_sigmas,
    start_corrected,
)

FACTORS = CorrectionFactors.seed000_table2()


def raw_odometry() -> np.ndarray:
    """(N, 4) t_s, x, y, yaw of a drive with turns, sideways and backwards legs."""
    t = np.arange(0.0, 12.0, 0.02)
    vx = np.where(t < 4, 0.3, np.where(t < 8, 0.0, -0.2))
    vy = np.where((t >= 4) & (t < 8), 0.25, 0.0)
    wz = 0.4 * np.sin(0.7 * t)
    yaw = np.concatenate([[0.3], 0.3 + np.cumsum(wz[1:] * 0.02)])
    c, s = np.cos(yaw), np.sin(yaw)
    x = 1.0 + np.concatenate([[0.0], np.cumsum((c * vx - s * vy)[1:] * 0.02)])
    y = -2.0 + np.concatenate([[0.0], np.cumsum((s * vx + c * vy)[1:] * 0.02)])
    return np.column_stack([t, x, y, yaw])


def run_live(raw: np.ndarray, factors: CorrectionFactors) -> CorrectedOdometry:
    t_ns = np.round(raw[:, 0] * 1e9).astype(np.int64)
    state = start_corrected(int(t_ns[0]), raw[0, 1:], raw[0, 1:])
    for k in range(1, len(raw)):
        state = correct_pose_step(state, int(t_ns[k]), raw[k, 1:], factors)
    return state


def test_identity_factors_give_back_the_raw_odometry() -> None:
    raw = raw_odometry()
    state = run_live(raw, CorrectionFactors.identity())
    assert state.pose == pytest.approx(tuple(raw[-1, 1:]), abs=1e-12)


def test_live_equals_the_offline_correction() -> None:
    raw = raw_odometry()
    builder = RecordingBuilder()
    zeros = np.zeros(len(raw))
    builder.add_many(
        ODOM,
        np.round(raw[:, 0] * 1e9).astype(np.int64),
        x_m=raw[:, 1],
        y_m=raw[:, 2],
        yaw_rad=raw[:, 3],
        vx_mps=zeros,
        vy_mps=zeros,
        wz_radps=zeros,
    )
    offline = corrected_odometry(builder.build(), FACTORS).topic(ODOM)
    state = run_live(raw, FACTORS)
    assert state.pose[0] == pytest.approx(offline["x_m"][-1], abs=1e-9)
    assert state.pose[1] == pytest.approx(offline["y_m"][-1], abs=1e-9)
    assert state.pose[2] == pytest.approx(offline["yaw_rad"][-1], abs=1e-9)
    assert state.twist[0] == pytest.approx(offline["vx_mps"][-1], abs=1e-9)


def test_pose_covariance_is_the_linearised_effect_of_the_factors() -> None:
    raw = raw_odometry()
    base = run_live(raw, FACTORS)
    names = ("scale_longitudinal", "scale_lateral", "crosstalk_left_rad_per_m")
    for j, name in enumerate(names):
        column = [
            "scale_longitudinal",
            "scale_lateral",
            "scale_rotational",
            "crosstalk_forward_rad_per_m",
            "crosstalk_reverse_rad_per_m",
            "crosstalk_left_rad_per_m",
            "crosstalk_right_rad_per_m",
        ].index(name)
        h = 1e-4
        moved = run_live(raw, replace(FACTORS, **{name: getattr(FACTORS, name) + h}))
        change = (np.array(moved.pose) - np.array(base.pose)) / h
        assert change == pytest.approx(base.pose_sensitivity[:, column], rel=2e-3, abs=1e-6), j
    sigma = CorrectionFactors(0.01, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    cov = base.pose_covariance(factor_sigmas(sigma))
    g = base.pose_sensitivity[:, 0]
    assert cov == pytest.approx(np.outer(g, g) * 1e-4)
    assert np.all(factor_sigmas(None) == 0.0)


def test_wheel_angles_integrate_as_the_offline_wheel_odometry() -> None:
    robot = load_robot("rosy-mecanum")
    J = inverse_jacobian(robot.wheels)
    t = np.arange(0.0, 4.0, 0.02)
    twist = np.column_stack([0.3 * np.ones_like(t), 0.1 * np.sin(t), 0.5 * np.cos(t)])
    rates = twist @ J.T
    angles = np.vstack([np.zeros(J.shape[0]), np.cumsum(rates[1:] * 0.02, axis=0)])
    poses, _, _ = wheel_odometry(t, angles, robot.wheels)
    J_plus = forward_jacobian(J)
    t_ns = np.round(t * 1e9).astype(np.int64)
    state = start_corrected(int(t_ns[0]), angles[0])
    for k in range(1, len(t)):
        state = correct_wheel_step(
            state, int(t_ns[k]), angles[k], J_plus, CorrectionFactors.identity()
        )
    assert state.pose == pytest.approx(tuple(poses[-1]), abs=1e-9)


def test_a_sample_not_after_the_last_changes_nothing() -> None:
    state = start_corrected(100, (0.0, 0.0, 0.0))
    assert correct_pose_step(state, 100, (1.0, 0.0, 0.0), FACTORS) is state


def test_unstamped_odometry_is_timed_by_its_receipt() -> None:
    """Stamp 0 on every message (a driver that does not stamp): the receipt times go on, so
    the correction does (it froze at the first sample)."""
    from omnical.ros2.publishers import OdometryCorrector

    raw = raw_odometry()
    corrector = OdometryCorrector(FACTORS)
    for k in range(len(raw)):
        state = corrector.step_pose(0, raw[k, 1:], rx_ns=1_000_000_000 + round(raw[k, 0] * 1e9))
    assert state.pose == pytest.approx(run_live(raw, FACTORS).pose, abs=1e-9)
    assert state.twist != (0.0, 0.0, 0.0)


def test_a_clock_that_jumps_back_restarts_the_increments_with_a_warning() -> None:
    """Halfway the stamps start again from 0.5 s (a simulator restarted, its clock reset) and
    the raw pose continues: the corrected pose goes on as without the jump."""
    from omnical.ros2.publishers import OdometryCorrector

    raw = raw_odometry()
    half = len(raw) // 2
    said: list[str] = []
    corrector = OdometryCorrector(FACTORS, warn=said.append)
    for k in range(len(raw)):
        t_s = 1.0 + raw[k, 0] if k < half else 0.5 + raw[k, 0] - raw[half, 0]
        state = corrector.step_pose(round(t_s * 1e9), raw[k, 1:])
    assert corrector.jumps == 1 and len(said) == 1 and "went back" in said[0]
    # the one increment across the jump is lost (rebased there); the rest is corrected
    assert state.pose == pytest.approx(run_live(raw, FACTORS).pose, abs=0.02)
    assert state.t_ns == round((0.5 + raw[-1, 0] - raw[half, 0]) * 1e9)


def test_tf_goes_to_a_frame_of_its_own() -> None:
    from types import SimpleNamespace

    from omnical.ros2.publishers import tf_child

    assert tf_child(SimpleNamespace(child_frame_id="base_link")) == "base_link_calibrated"
    assert tf_child(SimpleNamespace(child_frame_id="")) == "base_link_calibrated"
