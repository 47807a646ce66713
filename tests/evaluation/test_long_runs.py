"""What keeps ``omnical evaluate`` lean on a long recording (issue "Scale"): the smoother's
long-run path agrees with the full-rate one on a twin run, the ground truth is not evaluated
against itself, estimates and associations are not held twice, and the CLI reads only the
columns it uses and lets go of the tables the figures do not draw — same numbers throughout."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from omnical.bags.bag import read_bag, write_bag
from omnical.estimation.smoother import SmootherParams
from omnical.evaluation.association import Trajectory, associate
from omnical.evaluation.metrics import (
    GROUND_TRUTH_KEY,
    ODOMETRY_KEY,
    SMOOTHED_KEY,
    track_recording,
)
from omnical.recording.recording import Recording
from omnical.recording.topics import (
    BEACON_RAW_DISTANCE,
    CMD_VEL,
    EVALUATED,
    GROUND_TRUTH,
    HEDGE_POS_ANG,
    IMU,
    ODOM,
)
from omnical.reports.evaluate import _for_figures, _read_slim
from omnical.robot.description import RobotDescription

TOPICS = EVALUATED  # what `omnical evaluate` reads


def test_keyframe_smoothing_of_a_twin_run_matches_full_rate(
    default_tour: Recording, rosy: RobotDescription
) -> None:
    """The tour (≈ 80 s) taken as a long run (threshold lowered to 10 s): nodes every 0.1 s,
    the same trajectory to a small fraction of its own 1σ, the same errors against the truth."""
    base = SmootherParams(long_run_s=None)
    full = track_recording(default_tour, hedge_offset_m=rosy.hedge_offset_m, smoother=base)
    keyed = track_recording(
        default_tour, hedge_offset_m=rosy.hedge_offset_m, smoother=replace(base, long_run_s=10.0)
    )
    a, b = full[SMOOTHED_KEY], keyed[SMOOTHED_KEY]
    assert a.smoothing is not None and b.smoothing is not None
    assert a.smoothing.keyframe_stride == 1 and b.smoothing.keyframe_stride == 5
    gap = np.hypot(*(a.smoothing.poses[:, :2] - b.smoothing.poses[:, :2]).T)
    sigma = float(a.sigma_rms_m or 0.0)
    assert 0.0 < sigma < 0.01
    assert float(np.sqrt(np.mean(gap**2))) < 0.05 * sigma
    assert b.metrics.rmse_m == pytest.approx(a.metrics.rmse_m, rel=0.03)
    assert b.sigma_rms_m == pytest.approx(a.sigma_rms_m, rel=0.02)
    assert abs(b.smoothing.latency_s - a.smoothing.latency_s) < 0.2 * a.smoothing.latency_sigma_s
    for name in (ODOMETRY_KEY, "multilateration", "ips"):  # the others are untouched
        assert keyed[name].metrics == full[name].metrics


def test_ground_truth_as_the_reference_is_evaluated_only_alone(default_tour: Recording) -> None:
    every = track_recording(default_tour, smooth=False)
    lean = track_recording(default_tour, smooth=False, ground_truth_alone=True)
    assert GROUND_TRUTH_KEY in every and GROUND_TRUTH_KEY not in lean
    assert list(lean) == [k for k in every if k != GROUND_TRUTH_KEY]
    assert all(lean[k].metrics == every[k].metrics for k in lean)
    truth_only = default_tour.without(ODOM, HEDGE_POS_ANG, BEACON_RAW_DISTANCE)
    alone = track_recording(truth_only, smooth=False, ground_truth_alone=True)
    assert list(alone) == [GROUND_TRUTH_KEY]


def test_trajectories_and_associations_share_frozen_arrays() -> None:
    t = np.arange(100) * 0.1
    xy = np.column_stack([np.sin(t), np.cos(t)])
    # writeable arrays are copied: the caller may change them afterwards
    copied = Trajectory(t, xy)
    xy[0, 0] = 5.0
    assert copied.xy_m[0, 0] == 0.0 and not copied.xy_m.flags.writeable
    # read-only ones are taken as they are
    frozen = xy.copy()
    frozen.setflags(write=False)
    shared = Trajectory(t, frozen)
    assert shared.xy_m is frozen
    # a read-only view of a writable array is not frozen: its owner could change it (review)
    view = xy.view()
    view.setflags(write=False)
    guarded = Trajectory(t, view)
    xy[1, 0] = 7.0
    assert guarded.xy_m is not view and guarded.xy_m[1, 0] != 7.0
    # every sample kept: the association holds the estimate's arrays, not copies
    ref = Trajectory(np.arange(-1.0, 12.0, 0.5), np.zeros((26, 2)))
    whole = associate(shared, ref)
    assert np.shares_memory(whole.estimate_xy_m, frozen)
    np.testing.assert_array_equal(whole.index, np.arange(100))
    # some dropped: copies of the kept ones, as before
    part = associate(shared, Trajectory(np.arange(0.0, 5.0, 0.5), np.zeros((10, 2))))
    assert not np.shares_memory(part.estimate_xy_m, frozen)
    np.testing.assert_array_equal(part.estimate_xy_m, frozen[part.index])


def test_slim_read_is_read_bag_less_the_unused_columns(
    default_tour: Recording, tmp_path: Path
) -> None:
    bag = write_bag(default_tour, tmp_path / "tour.mcap")
    whole = read_bag(bag, TOPICS)
    slim = _read_slim(bag, TOPICS)
    assert slim.topics == whole.topics and slim.notes == whole.notes
    assert slim.start_ns == whole.start_ns
    assert slim.topic(IMU).names == ("gyro_z_radps",)
    assert slim.topic(GROUND_TRUTH).names == ("x_m", "y_m", "yaw_rad")
    assert slim.topic(HEDGE_POS_ANG).names == ("address", "x_m", "y_m", "z_m", "flags")
    for name in whole.topics:
        a, b = whole.topic(name), slim.topic(name)
        np.testing.assert_array_equal(a.t_ns, b.t_ns)
        for column in b.names:
            np.testing.assert_array_equal(a[column], b[column])
            assert a[column].dtype == b[column].dtype
        if name not in (IMU, GROUND_TRUTH, HEDGE_POS_ANG):
            assert a.names == b.names


def test_figures_keep_the_speeds_and_the_start(default_tour: Recording) -> None:
    drawn = _for_figures(default_tour)
    assert drawn.start_ns == default_tour.start_ns
    for name in (CMD_VEL, ODOM):
        assert drawn.topic(name) is default_tour.topic(name)
    assert not drawn.has(BEACON_RAW_DISTANCE) or len(drawn.topic(BEACON_RAW_DISTANCE)) == 1
    # when neither /cmd_vel nor /odom starts the run, the first row of the one that does stays
    late = default_tour.with_table(
        CMD_VEL, default_tour.topic(CMD_VEL).take(np.arange(10, len(default_tour.topic(CMD_VEL))))
    ).with_table(ODOM, default_tour.topic(ODOM).take(np.arange(10, len(default_tour.topic(ODOM)))))
    kept = _for_figures(late)
    assert kept.start_ns == late.start_ns < late.topic(ODOM).t_ns[0]
    assert sum(len(kept.topic(n)) for n in kept.topics) == (
        len(late.topic(CMD_VEL)) + len(late.topic(ODOM)) + 1
    )
