"""Holonomic tracking of a time-parameterised reference (feed-forward + map-frame PID)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from omnical.control.tracking import TrackingController, TrackingState, tracking_step
from omnical.errors import ConfigError
from omnical.robot.loader import load_robot
from omnical.trajectory.references import Reference, circle, polygon
from omnical.twin.closed_loop import ClosedLoopRun, closed_loop_run
from omnical.twin.params import TwinParams, default_twin

MECANUM = load_robot("rosy-mecanum")


def _rmse_vs_reference(run: ClosedLoopRun, ref: Reference, source: str) -> float:
    """RMSE of the odometry or true path against the reference while it moves, m."""
    t0 = run.control.t_s[0]
    path = run.odometry_path() if source == "odometry" else run.ground_truth_path()
    rows = path[(path[:, 0] >= t0) & (path[:, 0] <= t0 + ref.duration_s)]
    poses, _ = ref.at(rows[:, 0] - t0)
    err = np.hypot(rows[:, 1] - poses[:, 0], rows[:, 2] - poses[:, 1])
    return float(np.sqrt(np.mean(err**2)))


def test_tracking_step_is_pure_feed_forward_on_the_reference() -> None:
    ref = circle(center_m=(0.0, 1.0), face_tangent=True)
    ctrl = TrackingController(ref)
    t = 20.0
    poses, twists = ref.at(t)
    pose = (float(poses[0, 0]), float(poses[0, 1]), float(poses[0, 2]))
    out, state = tracking_step(ctrl, TrackingState(), t, pose, 0.05)
    assert out.twist == pytest.approx(tuple(twists[0]), abs=1e-12)
    assert out.mode == "track"
    # 5 cm to the right of the reference (map frame): the correction pushes left (+y map),
    # i.e. along −x in the body of a robot whose yaw is the tangent (+π/2 + polar angle)
    off = (pose[0], pose[1] - 0.05, pose[2])
    out, _ = tracking_step(ctrl, TrackingState(), t, off, 0.05)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    vy_map = s * out.twist[0] + c * out.twist[1]
    ff_vy_map = s * twists[0, 0] + c * twists[0, 1]
    assert vy_map - ff_vy_map == pytest.approx(0.1, abs=1e-3)  # 2 (m/s)/m × 5 cm, + integral
    out, _ = tracking_step(ctrl, state, ref.duration_s + 2.5, pose, 0.05)
    assert out.done
    with pytest.raises(ConfigError, match="settle_s"):
        TrackingController(ref, settle_s=-1.0)


@pytest.mark.parametrize("face_tangent", [False, True])
def test_circle_tracking_on_the_ideal_twin(face_tangent: bool) -> None:
    ref = circle(radius_m=1.0, center_m=(0.0, 1.0), face_tangent=face_tangent)
    run = closed_loop_run(TrackingController(ref), MECANUM, TwinParams.ideal_twin(), seed=2)
    assert run.control.reason == "done"
    rmse_odom = _rmse_vs_reference(run, ref, "odometry")
    rmse_gt = _rmse_vs_reference(run, ref, "ground_truth")
    assert rmse_odom <= 0.02  # the requirement; measured ≈ 0.1 mm
    assert rmse_odom < 0.002
    assert rmse_gt < 0.005
    yaw = run.ground_truth_path()[-1, 3]
    assert yaw == pytest.approx(2.0 * math.pi if face_tangent else 0.0, abs=0.01)


def test_tracking_on_the_default_twin_is_fooled_sideways() -> None:
    """At constant heading the circle needs lateral motion, which the default twin under-does
    by 13 % (seed 000 Table 2, lateral scaling 1.13) unseen by the odometry."""
    ref = circle(radius_m=1.0, center_m=(0.0, 1.0))
    run = closed_loop_run(TrackingController(ref), MECANUM, default_twin(MECANUM), seed=2)
    assert _rmse_vs_reference(run, ref, "odometry") < 0.002
    assert 0.05 < _rmse_vs_reference(run, ref, "ground_truth") < 0.4


def test_square_tracking_with_holonomic_legs() -> None:
    ref = polygon(((0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)), dwell_s=0.5)
    run = closed_loop_run(TrackingController(ref), MECANUM, TwinParams.ideal_twin(), seed=4)
    assert _rmse_vs_reference(run, ref, "odometry") < 0.002
    assert run.final_error_m((0.0, 0.0), "ground_truth") < 0.005
