"""The long-run smoother (issue "Scale"): pose nodes at keyframes, the odometry preintegrated
between them, every sample bridged back. It must agree with the full-rate smoother (same
trajectory to a fraction of a millimetre, same shared parameters, same 1σ and coverage) and
take a fraction of its memory per pose."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from test_smoother_scale import OFFSET, _dead_reckoned, _long_run

from omnical.errors import ConfigError
from omnical.estimation.keyframes import (
    bridge,
    increment_design,
    keyframe_indices,
    keyframes_by_time,
    odometry_increments,
    preintegrate,
)
from omnical.estimation.se2 import between_poses, compose_poses
from omnical.estimation.smoother import SmoothedTrack, SmootherParams, smooth_track

SIGMAS = (0.01, 0.01, 0.005, 0.001, 0.001)


def _errors(sm: SmoothedTrack, truth: np.ndarray) -> tuple[float, float]:
    """RMSE of the positions against the truth, and the share within their own 1σ ellipse."""
    err = sm.poses[:, :2] - truth[:, :2]
    rms = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    z2 = np.einsum("ni,nij,nj->n", err, np.linalg.inv(sm.covariance[:, :2, :2]), err)
    return rms, float(np.mean(z2 <= 2.2789))  # χ²(2) at 68.27 %


@pytest.fixture(scope="module")
def both() -> tuple[dict[str, np.ndarray], SmoothedTrack, SmoothedTrack]:
    """A 4-minute drifting run at 50 Hz, smoothed at full rate and through keyframes
    (the long-run threshold lowered to 60 s so a modest run takes the long-run path)."""
    run = _long_run(4.0, rate_hz=50.0, seed=3)
    args = (run["odom"], run["fix_t"], run["fixes"], run["cov"])
    full = smooth_track(
        SmootherParams(hedge_offset_m=OFFSET, long_run_s=None), *args, gyro=run["gyro"]
    )
    keyed = smooth_track(
        SmootherParams(hedge_offset_m=OFFSET, long_run_s=60.0), *args, gyro=run["gyro"]
    )
    return run, full, keyed


def test_keyframe_smoother_agrees_with_the_full_rate_one(
    both: tuple[dict[str, np.ndarray], SmoothedTrack, SmoothedTrack],
) -> None:
    run, full, keyed = both
    assert full.keyframe_stride == 1
    assert keyed.keyframe_stride == 5  # 0.1 s at 50 Hz
    assert keyed.converged
    np.testing.assert_array_equal(keyed.t_s, full.t_s)
    assert keyed.poses.shape == full.poses.shape and keyed.covariance.shape == full.covariance.shape
    # the same trajectory to a fraction of a millimetre (its own 1σ is ≈ 3 mm)
    gap = np.hypot(*(keyed.poses[:, :2] - full.poses[:, :2]).T)
    assert float(np.sqrt(np.mean(gap**2))) < 1e-4
    assert float(gap.max()) < 3e-4
    assert float(np.max(np.abs(keyed.poses[:, 2] - full.poses[:, 2]))) < 2e-4
    # the same shared parameters, well inside their 1σ, with the same 1σ
    assert np.all(np.abs(keyed.shared - full.shared) <= 0.2 * full.shared_sigma + 1e-12)
    np.testing.assert_allclose(keyed.shared_sigma, full.shared_sigma, rtol=0.02)
    # the same own uncertainty per pose, and as good against the truth
    ratio = keyed.position_sigma_m / full.position_sigma_m
    assert float(ratio.min()) > 0.98 and float(ratio.max()) < 1.02
    rms_full, cover_full = _errors(full, run["truth"])
    rms_keyed, cover_keyed = _errors(keyed, run["truth"])
    assert rms_keyed < 1.02 * rms_full
    assert abs(cover_keyed - cover_full) < 0.02
    assert 0.5 < cover_keyed < 0.95  # the 1σ means something
    assert keyed.fixes_used == full.fixes_used


def test_short_runs_keep_the_full_rate_solution_exactly() -> None:
    """Under the threshold nothing changes: the pinned short-run results stay bit for bit."""
    run = _long_run(2.0, seed=1)
    args = (run["odom"], run["fix_t"], run["fixes"], run["cov"])
    default = smooth_track(SmootherParams(hedge_offset_m=OFFSET), *args, gyro=run["gyro"])
    never = smooth_track(
        SmootherParams(hedge_offset_m=OFFSET, long_run_s=None), *args, gyro=run["gyro"]
    )
    assert default.keyframe_stride == 1
    np.testing.assert_array_equal(default.poses, never.poses)
    np.testing.assert_array_equal(default.covariance, never.covariance)
    np.testing.assert_array_equal(default.shared, never.shared)


def _corrected_composite(inc: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """The exact composition of the corrected sub-increments (one segment)."""
    pose = np.zeros(3)
    for c in inc + increment_design(inc) @ theta:
        pose = compose_poses(pose, c)
    return pose


def test_preintegrated_increment_design_and_covariance() -> None:
    rng = np.random.default_rng(4)
    n = 23
    t = np.arange(n) * 0.02
    inc_true = np.column_stack(
        [
            rng.uniform(-0.01, 0.01, n - 1),
            rng.uniform(-0.01, 0.01, n - 1),
            rng.normal(0, 0.02, n - 1),
        ]
    )
    od = np.column_stack([t, _dead_reckoned(inc_true)])
    idx = keyframe_indices(n, 5)
    np.testing.assert_array_equal(idx, [0, 5, 10, 15, 20, 22])
    inc_k, design_k, cov_k = preintegrate(od, idx, SIGMAS)
    inc, sig = odometry_increments(od, *SIGMAS)
    theta = np.array([0.03, -0.05, 0.02, 0.01, -0.02, 0.015, -0.01])
    for i in range(idx.size - 1):
        a, b = idx[i], idx[i + 1]
        # the composite is the odometry's motion between the two keyframes
        expected = between_poses(od[a, 1:], od[b, 1:])
        np.testing.assert_allclose(inc_k[i, :2], expected[:2], atol=1e-15)
        assert inc_k[i, 2] == pytest.approx(float(np.sum(inc[a:b, 2])), abs=1e-15)
        # its θ design is the derivative of the exact corrected composition at θ = 0 …
        steps = [
            (_corrected_composite(inc[a:b], h * e) - _corrected_composite(inc[a:b], -h * e))
            / (2 * h)
            for e, h in zip(np.eye(7), [1e-6] * 7, strict=True)
        ]
        np.testing.assert_allclose(design_k[i], np.column_stack(steps), atol=1e-9)
        # … and linear to well below the odometry's own noise at a real correction
        exact = _corrected_composite(inc[a:b], theta)
        linear = inc_k[i] + design_k[i] @ theta
        assert float(np.max(np.abs(exact - linear))) < 1e-5
        # the covariance: the sub-increments' σ carried through the composition (numerically)
        jac = np.column_stack(
            [
                (_composite_of(inc[a:b] + d) - _composite_of(inc[a:b] - d)) / 2e-7
                for d in _unit_steps(b - a, 1e-7)
            ]
        )
        sub_cov = np.diag((sig[a:b] ** 2).ravel())
        np.testing.assert_allclose(cov_k[i], jac @ sub_cov @ jac.T, rtol=1e-5, atol=1e-15)
        assert np.all(np.linalg.eigvalsh(cov_k[i]) > 0)


def _composite_of(inc: np.ndarray) -> np.ndarray:
    pose = np.zeros(3)
    for c in inc:
        pose = compose_poses(pose, c)
    return pose


def _unit_steps(rows: int, h: float) -> list[np.ndarray]:
    out = []
    for k in range(rows * 3):
        d = np.zeros(rows * 3)
        d[k] = h
        out.append(d.reshape(rows, 3))
    return out


def test_bridge_follows_the_odometry_and_closes_on_the_keyframes() -> None:
    rng = np.random.default_rng(6)
    n = 1203  # several of bridge's chunks, and a short last interval
    inc = np.column_stack(
        [
            rng.uniform(0, 0.006, n - 1),
            rng.uniform(-0.003, 0.003, n - 1),
            rng.normal(0, 0.01, n - 1),
        ]
    )
    od = np.column_stack([np.arange(n) * 0.02, _dead_reckoned(inc)])
    od[:, 3] = np.unwrap(od[:, 3])
    idx = keyframe_indices(n, 5)
    theta = np.array([0.02, -0.03, 0.01, 0.0, 0.0, 0.0, 0.0])
    # keyframes exactly on the corrected odometry, carried by a rigid motion: no closure
    raw, _ = odometry_increments(od, *SIGMAS)
    corrected = raw + increment_design(raw) @ theta
    dead = np.zeros((n, 3))
    dead[0] = (1.0, 2.0, 0.5)
    for k in range(n - 1):
        dead[k + 1] = compose_poses(dead[k], corrected[k])
    cov_k = np.broadcast_to(np.diag([1e-6, 2e-6, 1e-5]), (idx.size, 3, 3)).copy()
    poses, cov = bridge(od, idx, SIGMAS, dead[idx], cov_k, theta)
    np.testing.assert_allclose(poses, dead, atol=1e-9)
    np.testing.assert_array_equal(poses[idx], dead[idx])
    np.testing.assert_array_equal(cov[idx], cov_k)
    # between keyframes: the keyframes' covariance plus the bridge's own (positive) share
    inner = np.setdiff1d(np.arange(n), idx)
    assert np.all(cov[inner, 0, 0] > 1e-6) and np.all(cov[inner, 2, 2] > 1e-5)
    assert np.all(cov[inner, 0, 0] < 1e-6 + 1e-7)  # ≤ Q / 4: Q ≈ 1e-7 m² per 0.1 s
    # a keyframe moved by 1 mm: its neighbours follow part of the way, the next keyframe not
    moved = dead[idx].copy()
    moved[10, 0] += 1e-3
    shifted, _ = bridge(od, idx, SIGMAS, moved, cov_k, theta)
    change = shifted[:, 0] - dead[:, 0]
    assert change[idx[10]] == pytest.approx(1e-3, abs=1e-12)
    assert np.all(change[idx[9] + 1 : idx[10]] > 0) and np.all(change[idx[10] + 1 : idx[11]] > 0)
    np.testing.assert_allclose(change[: idx[9] + 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(change[idx[11] :], 0.0, atol=1e-9)


def _peak_bytes(minutes: float, long_run_s: float | None) -> tuple[int, int]:
    run = _long_run(minutes, rate_hz=50.0, seed=2)
    args = (run["odom"], run["fix_t"], run["fixes"], run["cov"])
    params = SmootherParams(hedge_offset_m=OFFSET, max_iterations=3, long_run_s=long_run_s)
    tracemalloc.start()
    try:
        smooth_track(params, *args, gyro=run["gyro"])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return run["odom"].shape[0], peak


def test_keyframes_take_a_fraction_of_the_memory_per_pose() -> None:
    """Per odometry sample: the result (time, pose, covariance: 104 B), the odometry's copy,
    the gyro's integration and the keyframes' share of the normal equations — about half the
    full-rate path's."""
    n_short, short = _peak_bytes(3.0, 60.0)
    n_long, long = _peak_bytes(12.0, 60.0)
    per_pose = (long - short) / (n_long - n_short)
    assert per_pose < 450
    n_full, full = _peak_bytes(12.0, None)
    assert n_full == n_long and long < 0.6 * full


def test_long_run_settings_are_checked() -> None:
    with pytest.raises(ConfigError):
        SmootherParams(long_run_s=-1.0)
    with pytest.raises(ConfigError):
        SmootherParams(keyframe_interval_s=0.0)
    with pytest.raises(ConfigError):
        SmootherParams(keyframe_interval_s=1e4)  # two nodes for a whole run
    with pytest.raises(ConfigError):
        SmootherParams(long_run_s=float("nan"))


def test_keyframes_follow_elapsed_time_not_a_sample_count() -> None:
    """Review finding: odometry in bursts (stamps 10 µs apart, a burst every 0.1 s) had a stride
    of 10,000 samples from the median interval (a node every 200 s: the smoothed track 16–36 m
    off); a rate that drops mid-run stretched the nodes to 1.2 s. By elapsed time, both get a
    node about every interval."""
    burst = (np.arange(0.0, 60.0, 0.1)[:, None] + np.arange(5)[None, :] * 1e-5).ravel()
    keys = keyframes_by_time(burst, 0.1)
    assert keys[0] == 0 and keys[-1] == burst.size - 1
    assert np.all(np.diff(burst[keys[:-1]]) == pytest.approx(0.1, abs=1e-4))
    change = np.concatenate([np.arange(0.0, 30.0, 0.02), np.arange(30.0, 60.0, 0.25)])
    gaps = np.diff(change[keyframes_by_time(change, 0.1)])
    assert gaps.max() <= 0.25 + 1e-9  # one sample per node where samples are rarer
    uniform = np.arange(3000) * 0.02
    np.testing.assert_array_equal(keyframes_by_time(uniform, 0.1), keyframe_indices(3000, 5))


def test_bursty_odometry_is_smoothed_as_well_as_evenly_stamped_odometry() -> None:
    """The same 4-minute run with its odometry stamped in bursts (each 0.1 s of samples stamped
    at the window's end, 10 µs apart, as a relayed link delivers them) through keyframes: the
    positions stay as close to the truth as the evenly stamped run's."""
    run = _long_run(4.0, rate_hz=50.0, seed=3)
    odom = run["odom"].copy()
    t = odom[:, 0]
    window = np.floor((t - t[0]) / 0.1 + 1e-9)
    first = np.searchsorted(window, window)  # each sample's window's first row
    odom[:, 0] = t[0] + (window + 1.0) * 0.1 + (np.arange(t.size) - first) * 1e-5
    assert np.all(np.diff(odom[:, 0]) > 0)
    params = SmootherParams(hedge_offset_m=OFFSET, long_run_s=60.0)
    even = smooth_track(params, run["odom"], run["fix_t"], run["fixes"], run["cov"])
    bursty = smooth_track(params, odom, run["fix_t"], run["fixes"], run["cov"])
    assert 3 <= bursty.keyframe_stride <= 7
    rms_even, _ = _errors(even, run["truth"])
    # the samples the smoother kept (it drops those outside the fixes' span), by their stamps
    kept = np.searchsorted(odom[:, 0], bursty.t_s)
    np.testing.assert_array_equal(odom[kept, 0], bursty.t_s)
    err = bursty.poses[:, :2] - run["truth"][kept, :2]
    rms_bursty = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    assert rms_bursty < max(2.0 * rms_even, rms_even + 0.01), (rms_even, rms_bursty)
