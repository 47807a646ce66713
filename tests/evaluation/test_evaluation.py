"""Association, alignment, Table 4 measures, evo parity, figures."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from omnical.evaluation.alignment import align_positions, fit_se2
from omnical.evaluation.association import Trajectory, associate, write_tum_pair
from omnical.evaluation.metrics import (
    METRIC_KEYS,
    evaluate_recording,
    metrics_json,
    track,
    tracking_metrics,
)
from omnical.experiment import load_script
from omnical.robot import load_robot
from omnical.twin import TwinParams, default_twin
from omnical.twin.session import simulate_run

ROSY = load_robot("rosy-mecanum")


def test_association_interpolates_not_nearest() -> None:
    ref = Trajectory(np.array([0.0, 1.0, 2.0]), np.array([[0.0, 0.0], [1.0, 2.0], [2.0, 0.0]]))
    est = Trajectory(np.array([-0.5, 0.25, 1.5, 2.5]), np.zeros((4, 2)))
    a = associate(est, ref)
    np.testing.assert_array_equal(a.t_s, [0.25, 1.5])  # outside the reference span: dropped
    np.testing.assert_allclose(a.reference_xy_m, [[0.25, 0.5], [1.5, 1.0]])


def test_se2_alignment_recovers_a_known_transform() -> None:
    rng = np.random.default_rng(3)
    src = rng.normal(size=(50, 2))
    theta, t = 0.7, np.array([1.5, -2.0])
    R = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    dst = src @ R.T + t
    tf = fit_se2(src, dst)
    assert tf.rotation_rad == pytest.approx(theta, abs=1e-12)
    np.testing.assert_allclose(tf.translation_m, t, atol=1e-12)


def test_metrics_by_hand() -> None:
    est = np.array([[1.0, 0.0], [0.0, 2.0], [0.0, 0.0]])
    ref = np.zeros((3, 2))
    m = tracking_metrics(est, ref)
    assert m.rmse_m == pytest.approx(math.sqrt((1 + 4 + 0) / 3))
    assert m.rmse_x_m == pytest.approx(math.sqrt(1 / 3))
    assert m.rmse_y_m == pytest.approx(math.sqrt(4 / 3))
    assert m.max_m == pytest.approx(2.0)
    assert m.final_m == pytest.approx(0.0)
    # seed 000 Table 4's "position" row: sqrt((0.1518² + 0.0445²)/2) = 0.1119
    paper = tracking_metrics(np.array([[0.1518, 0.0445]]), np.zeros((1, 2)))
    assert paper.rmse_per_axis_m == pytest.approx(0.1119, abs=5e-5)


@pytest.fixture(scope="module")
def tour_recording():  # type: ignore[no-untyped-def]
    return simulate_run(load_script("tour", ROSY.limits), ROSY, default_twin(ROSY), seed=4)


def test_evaluate_recording_against_ground_truth(tour_recording) -> None:  # type: ignore[no-untyped-def]
    results = evaluate_recording(tour_recording, hedge_offset_m=ROSY.hedge_offset_m)
    assert list(results) == ["odometry", "ips", "multilateration", "ground_truth"]
    assert results["ground_truth"].rmse_m == pytest.approx(0.0, abs=1e-9)
    # the uncalibrated odometry drifts (Table 2 truth); our multilateration is a few cm
    assert results["odometry"].max_m > 0.3
    assert results["multilateration"].rmse_m < results["ips"].rmse_m
    data = json.loads(metrics_json(results))
    assert set(data) == {"odometry", "ips", "multilateration", "ground_truth"}
    assert all(list(v) == list(METRIC_KEYS) for v in data.values())


def test_ideal_twin_odometry_matches_truth_after_origin_alignment() -> None:
    rec = simulate_run(load_script("tour", ROSY.limits), ROSY, TwinParams.ideal_twin(), seed=1)
    results = evaluate_recording(rec)
    assert results["odometry"].rmse_m < 0.005


def test_tum_export_reproduced_by_evo(tour_recording, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    evo_metrics = pytest.importorskip("evo.core.metrics")
    file_interface = pytest.importorskip("evo.tools.file_interface")
    gt = tour_recording.topic("/ground_truth")
    t0 = tour_recording.start_ns
    ref = Trajectory(gt.t_s(t0), np.column_stack([gt["x_m"], gt["y_m"]]), gt["yaw_rad"], "map")
    odom = tour_recording.topic("/odom")
    est = Trajectory(
        odom.t_s(t0), np.column_stack([odom["x_m"], odom["y_m"]]), odom["yaw_rad"], "odom"
    )
    tracked = track(est, ref, align_mode="se2")
    est_path, ref_path = write_tum_pair(
        tracked.association,
        tmp_path / "est.tum",
        tmp_path / "ref.tum",
        estimate_xy_m=tracked.alignment.xy_m,
    )
    traj_est = file_interface.read_tum_trajectory_file(str(est_path))
    traj_ref = file_interface.read_tum_trajectory_file(str(ref_path))
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((traj_ref, traj_est))
    assert ape.get_statistic(evo_metrics.StatisticsType.rmse) == pytest.approx(
        tracked.metrics.rmse_m, abs=1e-6
    )


def test_align_none_keeps_positions() -> None:
    xy = np.array([[1.0, 2.0], [3.0, 4.0]])
    out = align_positions(xy, xy + 1.0, "none")
    np.testing.assert_array_equal(out.xy_m, xy)


def test_figures_are_written(tour_recording, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from omnical.viz.trajectory import plot_position_time, plot_speeds, plot_tracking_paths

    gt = tour_recording.topic("/ground_truth")
    xy = np.column_stack([gt["x_m"], gt["y_m"]])
    t = gt.t_s(tour_recording.start_ns)
    for p in (
        plot_tracking_paths(tmp_path / "a.png", reference_xy_m=xy, odometry_xy_m=xy + 0.01),
        plot_position_time(tmp_path / "b.png", reference=(t, xy), estimates={"odometry": (t, xy)}),
        plot_speeds(tmp_path / "c.png", cmd_t_s=t, cmd_twist=np.zeros((t.size, 3))),
    ):
        assert p.is_file() and p.stat().st_size > 10_000
