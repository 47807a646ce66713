"""SE(2) helpers and the odometry + IPS extended Kalman filter, offline and in the loop."""

from __future__ import annotations

import math

import numpy as np
import pytest

from omnical.control.waypoint import WaypointController
from omnical.errors import ConfigError
from omnical.estimation.fusion import (
    FusedPoseSource,
    FusionParams,
    FusionState,
    IpsFix,
    fusion_predict,
    fusion_update,
    initial_pose_from_fixes,
)
from omnical.estimation.se2 import between, compose, transform_point
from omnical.experiment.ports import RobotState
from omnical.robot.loader import load_robot
from omnical.trajectory.references import SEED001_SQUARE_M
from omnical.twin.closed_loop import ClosedLoopRun, closed_loop_run
from omnical.twin.ips_params import IpsParams
from omnical.twin.online_ips import OnlineIpsParams, TwinIpsSource
from omnical.twin.params import default_twin
from omnical.twin.record import EPOCH_NS
from omnical.twin.simulator import DigitalTwin

MECANUM = load_robot("rosy-mecanum")
SQUARE = (*SEED001_SQUARE_M[1:], SEED001_SQUARE_M[0])
OFFSET = (MECANUM.hedge_offset_m[0], MECANUM.hedge_offset_m[1])


# --------------------------------------------------------------------------- SE(2)


def test_predict_composes_and_grows_uncertainty_with_motion() -> None:
    params = FusionParams()
    s0 = FusionState.initial((1.0, 2.0, math.pi / 2), (0.01, 0.01, 0.01))
    s1 = fusion_predict(params, s0, (0.5, 0.0, 0.1), 1.0)
    assert s1.pose == pytest.approx((1.0, 2.5, math.pi / 2 + 0.1))
    # the yaw uncertainty spreads into the across-track (here x) position
    assert s1.cov[0, 0] > s1.cov[1, 1] > s0.cov[1, 1]
    assert s1.cov[0, 2] < 0.0  # more yaw (left turn) → more −x for a robot heading +y
    assert np.allclose(s1.cov, s1.cov.T)
    still = fusion_predict(params, s0, (0.0, 0.0, 0.0), 1.0)
    assert still.cov[0, 0] == pytest.approx(0.01**2 + 0.002**2)


def test_update_pulls_towards_the_fix_and_gates_outliers() -> None:
    params = FusionParams(hedge_offset_m=(0.1, 0.0), ips_sigma_m=0.02)
    s0 = FusionState.initial((0.0, 0.0, math.pi / 2), (0.05, 0.05, 0.02))
    hedge = transform_point(s0.pose, 0.1, 0.0)
    assert hedge == pytest.approx((0.0, 0.1))
    same, ok = fusion_update(params, s0, hedge)
    assert ok
    assert same.pose == pytest.approx(s0.pose)
    assert same.cov[0, 0] < s0.cov[0, 0]
    moved, ok = fusion_update(params, s0, (hedge[0] + 0.05, hedge[1]))
    assert ok
    # σ_prior² / (σ_prior² + σ_fix²) of the innovation, plus a little via the yaw
    assert moved.pose[0] == pytest.approx(0.05 * 0.05**2 / (0.05**2 + 0.02**2), rel=0.05)
    far, ok = fusion_update(params, s0, (hedge[0] + 3.0, hedge[1]))
    assert not ok
    assert far is s0


class _DelayedFixes:
    """Fixes of a robot driving along x at 0.2 m/s, arriving ``latency_s`` after measurement."""

    def __init__(self, latency_s: float, *, stamp_arrival: bool, seed: int) -> None:
        rng = np.random.default_rng(seed)
        t_meas = np.arange(0.0, 20.0, 0.04)
        noise = rng.normal(0.0, 0.02, (t_meas.size, 2))
        self.fixes = [
            IpsFix(
                t + latency_s if stamp_arrival else t,  # naive: pretend it was measured on arrival
                t + latency_s,
                0.2 * t + n[0],
                n[1],
            )
            for t, n in zip(t_meas, noise, strict=True)
        ]
        self.now = 0.0

    def poll(self) -> list[IpsFix]:
        ready = [f for f in self.fixes if f.t_arrival_s <= self.now + 1e-9]
        self.fixes = self.fixes[len(ready) :]
        return ready


def _run_online(source: _DelayedFixes) -> np.ndarray:
    """Odometry under-reads by 3 %; returns (N, 2) t, x error of the fused estimate."""
    fused = FusedPoseSource(FusionParams(ips_sigma_m=0.02), source, (0.0, 0.0, 0.0))
    rows = []
    for t in np.arange(0.0, 20.0, 0.05):
        source.now = float(t)
        pose = fused(RobotState(float(t), (0.97 * 0.2 * t, 0.0, 0.0), (0.194, 0.0, 0.0), (), 0.0))
        rows.append((t, pose[0] - 0.2 * t))
    return np.array(rows)


def test_delayed_fixes_are_applied_at_their_measurement_time() -> None:
    """0.3 s of IPS latency at 0.2 m/s is 6 cm: the filter must compare each fix with the pose
    it had when the fix was measured (through the odometry history), not with the current one."""
    proper = _run_online(_DelayedFixes(0.3, stamp_arrival=False, seed=4))
    naive = _run_online(_DelayedFixes(0.3, stamp_arrival=True, seed=4))
    late = proper[:, 0] > 3.0
    rms_proper = float(np.sqrt(np.mean(proper[late, 1] ** 2)))
    assert rms_proper < 0.015
    assert float(np.mean(naive[late, 1])) < -0.04  # dragged back towards the stale fixes
    assert rms_proper < float(np.sqrt(np.mean(naive[late, 1] ** 2))) / 3.0


class _Replay:
    """A recorded run's fixes as a :class:`FixSource`: those measured by the time last set."""

    def __init__(self, fixes: np.ndarray) -> None:
        self.fixes = fixes[np.argsort(fixes[:, 0], kind="stable")]
        self.t_s = -math.inf
        self.next = 0

    def poll(self) -> list[IpsFix]:
        out = []
        while self.next < len(self.fixes) and self.fixes[self.next, 0] <= self.t_s:
            t, x, y = (float(v) for v in self.fixes[self.next])
            out.append(IpsFix(t, t, x, y))
            self.next += 1
        return out


def _fuse(
    params: FusionParams,
    odom: np.ndarray,
    fixes: np.ndarray,
    pose: tuple[float, float, float],
    sigma: tuple[float, float, float],
) -> np.ndarray:
    """The loop's fused pose source fed a recorded odometry (N, 4) and fixes (M, 3) t_meas, x,
    y (those before the first odometry sample left out): (N, 4) t, x, y, yaw in map."""
    replay = _Replay(fixes[fixes[:, 0] > odom[0, 0]])
    source = FusedPoseSource(params, replay, pose, initial_sigma=sigma)
    for t, x, y, yaw in odom.tolist():
        replay.t_s = t
        source(RobotState(t, (x, y, yaw), (0.0, 0.0, 0.0), (), 0.0))
    return source.estimates()


def test_offline_fusion_uses_measurement_times() -> None:
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 20.0, 0.02)
    odom = np.column_stack([t, 0.97 * 0.2 * t, np.zeros_like(t), np.zeros_like(t)])
    t_meas = np.arange(0.0, 20.0, 0.04)
    fixes = np.column_stack([t_meas, 0.2 * t_meas, np.zeros_like(t_meas)])
    fixes[:, 1:] += rng.normal(0.0, 0.02, (t_meas.size, 2))
    init = ((0.0, 0.0, 0.0), (0.01, 0.01, 0.01))
    out = _fuse(FusionParams(ips_sigma_m=0.02), odom, fixes, *init)
    late = t > 3.0
    assert np.sqrt(np.mean((out[late, 1] - 0.2 * t[late]) ** 2)) < 0.015
    assert abs(odom[-1, 1] - 0.2 * t[-1]) > 0.11  # the odometry alone is 12 cm short
    shifted = _fuse(FusionParams(ips_sigma_m=0.02), odom, fixes + np.array([0.3, 0.0, 0.0]), *init)
    assert np.mean(shifted[late, 1] - 0.2 * t[late]) < -0.04


def test_yaw_becomes_observable_from_the_travel_direction() -> None:
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 15.0, 0.02)
    odom = np.column_stack([t, 0.15 * t, np.zeros_like(t), np.zeros_like(t)])
    true_yaw = 0.1  # the robot really heads 0.1 rad left of where it was believed to
    xy = 0.15 * t[::2, None] * np.array([math.cos(true_yaw), math.sin(true_yaw)])
    fixes = np.column_stack([t[::2], xy + rng.normal(0.0, 0.02, xy.shape)])
    out = _fuse(FusionParams(ips_sigma_m=0.02), odom, fixes, (0.0, 0.0, 0.0), (0.01, 0.01, 0.2))
    assert out[-1, 3] == pytest.approx(true_yaw, abs=0.02)
    assert out[-1, 1:3] == pytest.approx(xy[-1], abs=0.03)


def test_fusion_validation_and_initial_pose() -> None:
    with pytest.raises(ConfigError, match="ips_sigma_m"):
        FusionParams(ips_sigma_m=0.0)
    with pytest.raises(ConfigError, match="hedge_offset_m"):
        FusionParams(hedge_offset_m=(0.0, math.nan))
    with pytest.raises(ConfigError, match="rate_hz"):
        OnlineIpsParams(rate_hz=0.0)
    with pytest.raises(ConfigError, match="no fixes"):
        initial_pose_from_fixes([], 0.0, (0.0, 0.0))
    fixes = [IpsFix(0.0, 0.05, 2.0 + d, 3.1 - d) for d in (-0.01, 0.0, 0.01)]
    assert initial_pose_from_fixes(fixes, math.pi / 2, (0.1, 0.0)) == pytest.approx(
        (2.0, 3.0, math.pi / 2)
    )
    online = OnlineIpsParams.from_ips_params(IpsParams())
    assert online.rate_hz == pytest.approx(25.0)
    assert online.latency_s == pytest.approx(0.05)
    assert 0.015 < online.sigma_m < 0.03


# --------------------------------------------------------------------------- online on the twin


def test_twin_ips_source_rate_latency_and_noise() -> None:
    twin = DigitalTwin(MECANUM, default_twin(MECANUM), seed=6)
    source = TwinIpsSource(twin, OnlineIpsParams(sigma_m=0.02, latency_s=0.05), seed=6)
    fixes: list[IpsFix] = []
    for k in range(81):
        twin.advance_to(k * 0.05)
        got = source.poll()
        assert all(f.t_arrival_s <= twin.t_s + 1e-9 for f in got)
        fixes += got
    t_meas = np.array([f.t_meas_s for f in fixes])
    assert len(fixes) == 99  # 25 Hz over 4 s, the last ones still in flight
    assert np.diff(t_meas) == pytest.approx(np.full(98, 0.04))
    assert all(f.t_arrival_s - f.t_meas_s == pytest.approx(0.05) for f in fixes)
    xy = np.array([(f.x_m, f.y_m) for f in fixes])
    hedge = transform_point(twin.ground_truth_pose, *OFFSET)
    assert xy.mean(axis=0) == pytest.approx(hedge, abs=0.006)
    assert xy.std(axis=0) == pytest.approx([0.02, 0.02], abs=0.005)


def test_fused_source_follows_the_truth_while_driving() -> None:
    params = default_twin(MECANUM)
    twin = DigitalTwin(MECANUM, params, seed=7)
    source = TwinIpsSource(twin, OnlineIpsParams(), seed=7)
    start = params.start_pose_map
    fused = FusedPoseSource(
        FusionParams(hedge_offset_m=OFFSET, ips_sigma_m=0.02), source, start, path_origin_map=start
    )
    twin.send_twist(0.1, 0.05, 0.1)
    errors = []
    for k in range(400):
        twin.advance_to(k * 0.05)
        pose_path = fused(twin.read_state())
        truth_path = between(start, twin.ground_truth_pose)
        errors.append(math.hypot(pose_path[0] - truth_path[0], pose_path[1] - truth_path[1]))
    assert max(errors[40:]) < 0.03
    assert fused.accepted > 450
    assert fused.estimates().shape == (400, 4)
    assert np.all(np.diag(fused.state.cov) > 0.0)


def _path_error_rms_m(run: ClosedLoopRun) -> float:
    """RMS distance between the pose the controller used and the true pose (path frame)."""
    c = run.control
    gt = run.ground_truth_path()
    rows = np.searchsorted(gt[:, 0], c.t_s[:-1] - 1e-9)
    d = c.pose[:-1, :2] - gt[rows, 1:3]
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


def test_fused_closed_loop_beats_odometry_on_the_default_twin() -> None:
    """Seed 000 §2.4: the odometry loop tracks its own belief; IPS fusion brings the truth in."""
    ctrl = WaypointController(SQUARE)
    params = default_twin(MECANUM)
    odo = closed_loop_run(ctrl, MECANUM, params, seed=3, pose_source="odometry")
    fused = closed_loop_run(ctrl, MECANUM, params, seed=3, pose_source="fused")
    assert odo.control.reason == fused.control.reason == "done"
    odo_gt = odo.final_error_m(SQUARE[-1], "ground_truth")
    fused_gt = fused.final_error_m(SQUARE[-1], "ground_truth")
    assert odo_gt > 0.05  # measured 8.7 cm
    assert fused_gt < 0.025  # measured 1.3 cm
    assert _path_error_rms_m(fused) < 0.015
    assert _path_error_rms_m(odo) > 2.0 * _path_error_rms_m(fused)
    assert fused.estimates is not None
    assert fused.estimates.shape[0] == fused.control.t_s.shape[0] - 1
    # the odometry itself still drifts in the fused run: the loop no longer follows it
    assert fused.final_error_m(SQUARE[-1], "odometry") > 0.04


def test_offline_fusion_of_a_recording_with_the_full_simulated_ips() -> None:
    """The fused pose source on the post-hoc IPS of a recording (outliers, drops, quantisation, latency)."""
    params = default_twin(MECANUM)
    run = closed_loop_run(WaypointController(SQUARE), MECANUM, params, seed=5)
    rec = run.recording
    od, hp, gt = rec.topic("/odom"), rec.topic("/hedge_pos_ang"), rec.topic("/ground_truth")
    t_odom = (od.t_ns - EPOCH_NS) / 1e9
    odom = np.column_stack([t_odom, od["x_m"], od["y_m"], od["yaw_rad"]])
    good = (np.asarray(hp["flags"]) & 1) == 0
    latency = params.ips.latency_s + params.ips.latency_periods / params.ips.rate_max_hz
    fixes = np.column_stack([(hp.t_ns - EPOCH_NS) / 1e9 - latency, hp["x_m"], hp["y_m"]])[good]
    start = params.start_pose_map
    fp = FusionParams(hedge_offset_m=OFFSET, ips_sigma_m=0.03)
    out = _fuse(fp, odom, fixes, start, (0.02, 0.02, 0.05))
    t_gt = (gt.t_ns - EPOCH_NS) / 1e9
    gx, gy = np.interp(out[:, 0], t_gt, gt["x_m"]), np.interp(out[:, 0], t_gt, gt["y_m"])
    fused_rms = float(np.sqrt(np.mean((out[:, 1] - gx) ** 2 + (out[:, 2] - gy) ** 2)))
    odom_map = np.array([compose(start, (x, y, 0.0))[:2] for x, y in odom[:, 1:3]])
    odom_rms = float(np.sqrt(np.mean((odom_map[:, 0] - gx) ** 2 + (odom_map[:, 1] - gy) ** 2)))
    assert fused_rms < 0.01  # measured 5 mm
    assert odom_rms > 0.025  # measured 3.6 cm


def test_fused_source_needs_a_first_state_before_old_fixes() -> None:
    class _Fixed:
        def __init__(self) -> None:
            self.sent = False

        def poll(self) -> list[IpsFix]:
            if self.sent:
                return []
            self.sent = True
            return [IpsFix(0.0, 0.0, 0.0, 0.0)]

    fused = FusedPoseSource(FusionParams(), _Fixed(), (0.0, 0.0, 0.0))
    state = RobotState(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (), 0.0)
    assert fused(state) == pytest.approx((0.0, 0.0, 0.0))
    assert fused.accepted == 1
