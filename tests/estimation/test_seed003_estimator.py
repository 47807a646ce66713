"""The seed 003 estimator: the same trajectory online (in the loop) and offline (on arrays)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from omnical.bags.bag import read_bag, write_bag
from omnical.control.centred import CentredController, CentredMode
from omnical.control.loop import run_controller
from omnical.errors import ConfigError
from omnical.estimation.se2 import between_poses
from omnical.estimation.seed003_estimator import (
    Seed003Estimator,
    Seed003PoseSource,
    align_samples,
    seed003_samples_of,
    seed003_track,
)
from omnical.robot.loader import load_robot
from omnical.twin.clock import TwinClock
from omnical.twin.closed_loop import closed_loop_run
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.record import EPOCH_NS
from omnical.twin.seed003_sensors import TwinSeed003Samples, seed003_samples
from omnical.twin.simulator import DigitalTwin

OMNI = load_robot("omni-x")
TRIANGLE = ((1.2, 0.0), (0.6, 0.6), (0.0, 0.0))


def test_offline_on_arrays_equals_the_loop_bit_for_bit() -> None:
    params = replace(default_twin(OMNI), start_pose_map=(0.6, 1.8, 0.0))
    twin = DigitalTwin(OMNI, params, seed=5)
    twin.advance_to(1.0)
    source = Seed003PoseSource(
        Seed003Estimator(OMNI.dead_wheels), TwinSeed003Samples(twin, since_s=1.0)
    )
    controller = CentredController(TRIANGLE, mode=CentredMode.TRANSLATE)
    log = run_controller(controller, twin, TwinClock(twin), pose_source=source)
    assert log.reason == "done"
    online = source.estimates()
    # offline: plain arrays (what a bag's /dead_wheels, /imu and /imu/mag give)
    tl = twin.log()
    samples = align_samples(
        tl.dead_wheel_t_s,
        tl.dead_wheel_cumulative_counts,
        tl.imu_t_s,
        tl.gyro_radps[:, 2],
        tl.accel_mps2,
        tl.magnetometer_t_s,
        tl.magnetic_field_g,
    ).since(1.0)
    offline = seed003_track(samples, OMNI.dead_wheels)
    assert online.shape[0] > 500
    np.testing.assert_array_equal(offline[: online.shape[0]], online)


def test_closed_loop_run_on_seed003_follows_the_truth() -> None:
    params = replace(default_twin(OMNI), start_pose_map=(0.6, 1.8, 0.0))
    run = closed_loop_run(
        CentredController(TRIANGLE, mode=CentredMode.TRANSLATE),
        OMNI,
        params,
        seed=2,
        pose_source="seed003",
    )
    assert run.control.reason == "done"
    assert run.estimates is not None
    est = between_poses(np.asarray(run.path_origin_map), run.estimates[:, 1:])
    offline = seed003_track(seed003_samples(run.twin_log, since_s=1.0), OMNI.dead_wheels)
    np.testing.assert_allclose(offline[: len(est), 1:], est, atol=1e-12)
    truth = run.ground_truth_path()
    assert np.hypot(*truth[-1, 1:3]) < 0.05  # back at the start within 5 cm (truth)
    assert np.hypot(*est[-1, :2]) < 0.015


def test_ideal_twin_estimate_matches_truth() -> None:
    twin = DigitalTwin(OMNI, TwinParams.ideal_twin(start_pose_map=(0.0, 0.0, 0.0)), seed=0)
    twin.send_twist(0.2, 0.1, 0.3)
    twin.advance_to(6.0)
    log = twin.log()
    track = seed003_track(seed003_samples(log), OMNI.dead_wheels)
    gt = log.ground_truth_pose[-1]
    assert np.hypot(*(track[-1, 1:3] - gt[:2])) < 0.01
    assert abs(track[-1, 3] - gt[2]) < 0.01


def test_bad_samples_are_refused() -> None:
    est = Seed003Estimator(OMNI.dead_wheels)
    with pytest.raises(ConfigError, match="3 dead wheels"):
        est.update(0.0, (0.0, 0.0), 0.0, (0.0, 0.0, 9.8), (0.2, 0.0, 0.45))
    est.update(1.0, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 9.8), (0.2, 0.0, 0.45))
    with pytest.raises(ConfigError, match="after one"):
        est.update(0.5, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 9.8), (0.2, 0.0, 0.45))
    with pytest.raises(ConfigError, match="no IMU reading"):
        align_samples([0.0], [[0, 0, 0]], [1.0], [0.0], [[0, 0, 9.8]], [0.0], [[0.2, 0, 0.45]])


def test_offline_on_a_recorded_bag_gives_the_loops_trajectory(tmp_path: Path) -> None:
    params = replace(default_twin(OMNI), start_pose_map=(0.6, 1.8, 0.0))
    run = closed_loop_run(
        CentredController(TRIANGLE, mode=CentredMode.TRANSLATE),
        OMNI,
        params,
        seed=2,
        pose_source="seed003",
    )
    assert run.estimates is not None
    est = between_poses(np.asarray(run.path_origin_map), run.estimates[:, 1:])
    bag = read_bag(write_bag(run.recording, tmp_path / "triangle.mcap"))
    lead_in_s = (EPOCH_NS + 1_000_000_000 - bag.start_ns) / 1e9  # the loop started at 1 s
    samples = seed003_samples_of(bag, OMNI.dead_wheels, since_s=lead_in_s - 1e-9)
    offline = seed003_track(samples, OMNI.dead_wheels)
    assert len(est) > 500
    np.testing.assert_allclose(offline[: len(est), 1:], est, atol=1e-9)
    with pytest.raises(ConfigError, match="/imu/mag"):
        seed003_samples_of(bag.without("/imu/mag"), OMNI.dead_wheels)
