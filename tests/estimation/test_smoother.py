"""The batch smoother on synthetic runs: lever arm, latency, odometry scale, outliers, 1σ."""

from __future__ import annotations

import numpy as np
import pytest

from omnical.errors import ConfigError, GeometryError
from omnical.estimation.se2 import between_poses, compose_poses
from omnical.estimation.smoother import SHARED_NAMES, SmootherParams, smooth_track

OFFSET = (0.04, -0.03)
LATENCY_S = 0.05


def _truth(t: np.ndarray) -> np.ndarray:
    """A Lissajous-like path in map with a slowly turning heading."""
    return np.column_stack(
        [
            2.9 + 0.8 * np.sin(0.2 * t),
            2.4 + 0.6 * np.sin(0.4 * t),
            1.57 + 0.3 * np.sin(0.1 * t),
        ]
    )


def _run(seed: int, *, lateral_scale: float = 1.0, outliers: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 60.0, 0.02)
    truth = _truth(t)
    # odometry: the true body increments, the lateral one scaled, a little slip, integrated
    inc = between_poses(truth[:-1], truth[1:])
    inc[:, 1] *= lateral_scale
    inc[:, :2] += rng.normal(0.0, 2e-5, (inc.shape[0], 2))
    odom = np.zeros_like(truth)
    for i in range(inc.shape[0]):
        odom[i + 1] = compose_poses(odom[i], inc[i])
    # fixes at 25 Hz: the hedgehog at t − latency, 2 cm noise, stamped at t
    tf = np.arange(0.5, 59.5, 0.04)
    at = _truth(tf - LATENCY_S)
    c, s = np.cos(at[:, 2]), np.sin(at[:, 2])
    hedge = np.column_stack(
        [at[:, 0] + c * OFFSET[0] - s * OFFSET[1], at[:, 1] + s * OFFSET[0] + c * OFFSET[1]]
    )
    fixes = hedge + rng.normal(0.0, 0.02, hedge.shape)
    if outliers:
        pick = rng.choice(tf.size, outliers, replace=False)
        fixes[pick] += rng.uniform(0.3, 1.0, (outliers, 2))
    cov = np.broadcast_to(np.eye(2) * 0.02**2, (tf.size, 2, 2)).copy()
    return {
        "t": t,
        "truth": truth,
        "odom": np.column_stack([t, odom]),
        "fix_t": tf,
        "fixes": fixes,
        "cov": cov,
    }


def test_smoother_recovers_the_track_latency_and_odometry_scale() -> None:
    run = _run(1, lateral_scale=1.1, outliers=40)
    sm = smooth_track(
        SmootherParams(hedge_offset_m=OFFSET), run["odom"], run["fix_t"], run["fixes"], run["cov"]
    )
    assert sm.converged
    err = np.hypot(*(sm.poses[:, :2] - run["truth"][:, :2]).T)
    rms = float(np.sqrt(np.mean(err**2)))
    # 1475 fixes of 2 cm, held together by the odometry: a few millimetres
    assert rms < 0.004
    # the uncertainty the smoother states is the error it makes (within a factor of 2)
    assert 0.5 < sm.position_sigma_rms_m / rms < 2.0
    assert abs(sm.latency_s - LATENCY_S) < max(4 * sm.latency_sigma_s, 0.005)
    shared = sm.shared_dict()
    # the odometry saw lateral motion 10 % too long: the correction is −1/11
    assert shared["scale_y"][0] == pytest.approx(1 / 1.1 - 1, abs=0.01)
    assert abs(shared["scale_x"][0]) < 0.01
    # the outliers (30 cm to 1 m) were down-weighted, the 2 cm fixes mostly not
    assert 40 <= sm.fixes_downweighted < 150
    assert set(shared) == set(SHARED_NAMES)
    np.testing.assert_allclose(np.unwrap(sm.poses[:, 2]), run["truth"][:, 2], atol=0.01)


def test_held_latency_and_gyro() -> None:
    run = _run(2)
    t = run["t"]
    yaw_rate = np.gradient(run["truth"][:, 2], t) + 0.002  # a gyro with a 2 mrad/s bias
    params = SmootherParams(hedge_offset_m=OFFSET, latency_s=LATENCY_S, estimate_latency=False)
    sm = smooth_track(
        params,
        run["odom"],
        run["fix_t"],
        run["fixes"],
        run["cov"],
        gyro=np.column_stack([t, yaw_rate]),
    )
    assert sm.latency_s == LATENCY_S and sm.latency_sigma_s == 0.0
    assert sm.shared_dict()["gyro_bias_radps"][0] == pytest.approx(0.002, abs=5e-4)
    err = np.hypot(*(sm.poses[:, :2] - run["truth"][:, :2]).T)
    assert float(np.sqrt(np.mean(err**2))) < 0.004


def test_bad_input() -> None:
    with pytest.raises(ConfigError, match="huber_k"):
        SmootherParams(huber_k=0.0)
    with pytest.raises(ConfigError, match="hedge_offset_m"):
        SmootherParams(hedge_offset_m=(float("nan"), 0.0))
    odom = np.column_stack([np.arange(10.0), np.zeros((10, 3))])
    with pytest.raises(GeometryError, match="at least 3 fixes"):
        smooth_track(
            SmootherParams(), odom, [1.0, 2.0], np.zeros((2, 2)), np.tile(np.eye(2), (2, 1, 1))
        )
    with pytest.raises(GeometryError, match="N >= 2"):
        smooth_track(SmootherParams(), odom[:1], [], np.zeros((0, 2)), np.zeros((0, 2, 2)))


def test_heading_through_pi_is_continuous() -> None:
    """Odometry yaw wrapped to ±π while the robot turns round and round (the tour's turns)."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 40.0, 0.02)
    truth = np.column_stack([2.0 + 0.5 * np.sin(0.3 * t), 2.0 + 0.5 * np.cos(0.2 * t), 0.4 * t])
    inc = between_poses(truth[:-1], truth[1:])
    odom = np.zeros_like(truth)
    for i in range(inc.shape[0]):
        odom[i + 1] = compose_poses(odom[i], inc[i])
    odom[:, 2] = np.angle(np.exp(1j * odom[:, 2]))
    tf = np.arange(0.5, 39.5, 0.04)
    idx = np.searchsorted(t, tf)
    c, s = np.cos(truth[idx, 2]), np.sin(truth[idx, 2])
    hedge = truth[idx, :2] + np.column_stack([c * 0.04 + s * 0.03, s * 0.04 - c * 0.03])
    tf = t[idx]
    fixes = hedge + rng.normal(0.0, 0.02, hedge.shape)
    cov = np.tile(np.eye(2) * 0.02**2, (tf.size, 1, 1))
    params = SmootherParams(hedge_offset_m=OFFSET, estimate_latency=False)
    sm = smooth_track(params, np.column_stack([t, odom]), tf, fixes, cov)
    err = np.hypot(*(sm.poses[:, :2] - truth[:, :2]).T)
    assert float(np.sqrt(np.mean(err**2))) < 0.005
    assert sm.fixes_downweighted < 0.1 * sm.fixes_used


def test_odometry_delay_puts_the_poses_back_on_the_true_time() -> None:
    """Odometry stamped 30 ms after the motion (the twin: one control period late): from the
    fixes and the odometry alone only the latency between them is seen (0.05 − 0.03 s), and
    the smoothed poses lag the truth; told the delay, the smoother returns the poses at the
    true times and the fixes' own latency."""
    delay_s = 0.03
    run = _run(4)
    late = run["odom"].copy()
    late[:, 0] += delay_s
    errors = {}
    for told in (0.0, delay_s):
        params = SmootherParams(hedge_offset_m=OFFSET, odometry_delay_s=told)
        sm = smooth_track(params, late, run["fix_t"], run["fixes"], run["cov"])
        np.testing.assert_allclose(sm.t_s, run["t"] + delay_s - told)
        truth = np.column_stack([np.interp(sm.t_s, run["t"], run["truth"][:, k]) for k in (0, 1)])
        inside = (sm.t_s > 1.0) & (sm.t_s < 59.0)
        errors[told] = float(
            np.sqrt(np.mean(np.sum((sm.poses[inside, :2] - truth[inside]) ** 2, 1)))
        )
        expected = LATENCY_S - delay_s + told
        assert abs(sm.latency_s - expected) < max(4 * sm.latency_sigma_s, 0.005)
    # the path moves at ≈ 0.2–0.3 m/s: 30 ms is ≈ 7 mm along the track
    assert errors[delay_s] < 0.004 < errors[0.0]
    with pytest.raises(ConfigError, match="odometry_delay_s"):
        SmootherParams(odometry_delay_s=float("nan"))
