"""Every noise channel of the twin has its own random stream: no two channels correlate."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from omnical.robot.loader import load_robot
from omnical.twin.noise import NoiseChannel, NoiseStream
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.simulator import DigitalTwin, TwinLog

OMNI = load_robot("omni-x")
_TWIST = (0.25, 0.2, 0.3)
_SETTLED_S = 3.0


def _minute(params: TwinParams, seed: int = 7) -> TwinLog:
    twin = DigitalTwin(OMNI, params, seed=seed)
    twin.send_twist(*_TWIST)
    twin.advance_to(60.0)
    return twin.log()


def _slip_drive(
    noisy: TwinLog, clean: TwinLog, params: TwinParams
) -> tuple[np.ndarray, np.ndarray]:
    """Times and (K, 3) innovations of the slip process, from the truth with and without slip."""
    t = noisy.ground_truth_t_s
    np.testing.assert_array_equal(t, clean.ground_truth_t_s)
    vx, vy, wz = clean.ground_truth_twist.T
    avx, avy, awz = noisy.ground_truth_twist.T
    keep = t > _SETTLED_S
    slip = np.column_stack(
        [
            avx[keep] / vx[keep] - 1.0,
            avy[keep] / vy[keep] - 1.0,
            (awz[keep] - wz[keep]) / (wz[keep] + 0.1 * (np.abs(vx[keep]) + np.abs(vy[keep]))),
        ]
    )
    decay = (t[1] - t[0]) / params.slip_correlation_s
    return t[keep][1:], slip[1:] - (1.0 - decay) * slip[:-1]


def test_gyro_accel_magnetometer_and_slip_noise_are_uncorrelated() -> None:
    # the truth at every simulation step, so the slip process can be read back from it
    noisy = replace(default_twin(OMNI), ground_truth_rate_hz=200.0, imu_noise=True)
    quiet = replace(noisy, imu_noise=False)
    no_slip = replace(quiet, slip_sigma=0.0)
    a, b, c = _minute(noisy), _minute(quiet), _minute(no_slip)
    # the IMU noise streams do not touch the truth
    np.testing.assert_array_equal(a.ground_truth, b.ground_truth)
    gyro = a.gyro_radps - b.gyro_radps
    accel = a.accel_mps2 - b.accel_mps2
    mag = a.magnetic_field_g - b.magnetic_field_g
    t_slip, slip = _slip_drive(b, c, noisy)
    # align on the simulation steps that have both an IMU sample and a slip draw
    t_imu = a.imu_t_s
    idx = np.searchsorted(t_slip, t_imu)
    ok = (idx < t_slip.size) & (np.abs(t_slip[np.minimum(idx, t_slip.size - 1)] - t_imu) < 1e-9)
    assert ok.sum() > 5000  # about one simulated minute at 100 Hz
    channels = np.column_stack([gyro[ok], accel[ok], mag[ok], slip[idx[ok]]])
    # each channel carries the noise it should (a channel of zeros would make the test empty)
    sigma = channels.std(axis=0)
    imu = OMNI.imu
    drive = noisy.slip_sigma * np.sqrt(2.0 * 0.005 / noisy.slip_correlation_s)
    expected = [imu.gyro_noise_radps] * 3 + [imu.accel_noise_mps2] * 3 + [0.002] * 3 + [drive] * 3
    np.testing.assert_allclose(sigma, expected, rtol=0.05)
    rho = np.corrcoef(channels.T)
    off_diagonal = np.abs(rho[~np.eye(12, dtype=bool)])
    assert off_diagonal.max() < 0.05


def test_streams_are_deterministic_per_seed_and_channel() -> None:
    first = [NoiseStream(3, NoiseChannel.GYRO, block=8).next3() for _ in range(2)]
    assert first[0] == first[1]
    gyro = NoiseStream(3, NoiseChannel.GYRO, block=8)
    accel = NoiseStream(3, NoiseChannel.ACCEL, block=8)
    other_seed = NoiseStream(4, NoiseChannel.GYRO, block=8)
    draws = np.array([gyro.next3() for _ in range(20)])  # crosses block boundaries
    assert draws.shape == (20, 3)
    assert len({tuple(r) for r in draws}) == 20
    assert accel.next3() != draws[0].tolist()
    assert other_seed.next3() != draws[0].tolist()


def test_log_columns_by_name() -> None:
    twin = DigitalTwin(OMNI, default_twin(OMNI), seed=1)
    twin.send_twist(0.2, 0.0, 0.1)
    twin.advance_to(2.0)
    log = twin.log()
    np.testing.assert_array_equal(log.odom_pose, log.odom[:, 1:4])
    np.testing.assert_array_equal(log.odom_twist, log.odom[:, 4:7])
    np.testing.assert_array_equal(log.ground_truth_t_s, log.ground_truth[:, 0])
    np.testing.assert_array_equal(log.ground_truth_pose, log.ground_truth[:, 1:4])
    np.testing.assert_array_equal(log.gyro_radps[:, 2], log.imu[:, 3])
    np.testing.assert_array_equal(log.accel_mps2, log.imu[:, 4:7])
    np.testing.assert_array_equal(log.magnetic_field_g, log.magnetometer[:, 1:])
    np.testing.assert_array_equal(log.dead_wheel_cumulative_counts, log.dead_wheel_counts[:, 1:])
    assert log.odom_t_s[-1] == pytest.approx(2.0)
    assert log.imu_t_s.size == log.magnetometer_t_s.size == log.gyro_radps.shape[0]
    assert log.dead_wheel_t_s.size == log.odom_t_s.size
