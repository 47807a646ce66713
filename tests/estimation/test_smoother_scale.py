"""The batch smoother at scale (issue "Scale", item 3): the banded solver is LAPACK's dense
solution, its memory grows by a fixed amount per pose, a long drifting run converges, garbage
stays bounded; and the figures of a long run are drawn through what a pixel can show."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from omnical.errors import GeometryError
from omnical.estimation.se2 import between_poses
from omnical.estimation.smoother import (
    _BAND,
    SmootherParams,
    _backward_congruence,
    _marginals_banded,
    _Normal,
    _solve_banded,
    smooth_track,
)
from omnical.reports.figures.trajectory import _step_indices, _thinned, envelope_indices

OFFSET = (0.04, -0.03)


def _dead_reckoned(inc: np.ndarray) -> np.ndarray:
    """Poses integrated from body increments, starting at the origin (yaw wrapped)."""
    yaw = np.concatenate([[0.0], np.cumsum(inc[:, 2])])
    c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    x = np.concatenate([[0.0], np.cumsum(c * inc[:, 0] - s * inc[:, 1])])
    y = np.concatenate([[0.0], np.cumsum(s * inc[:, 0] + c * inc[:, 1])])
    return np.column_stack([x, y, np.angle(np.exp(1j * yaw))])


def _long_run(minutes: float, rate_hz: float = 20.0, seed: int = 0) -> dict[str, np.ndarray]:
    """Loops round and round, odometry 10 % long sideways and turning 3 % too far (its heading
    drifts by radians over the run), fixes at 8 Hz with 2 cm noise, 50 ms late."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 60.0 * minutes, 1.0 / rate_hz)
    truth = np.column_stack(
        [
            3.0 + 1.5 * np.sin(0.05 * t),
            2.5 + 1.0 * np.sin(0.1 * t),
            0.25 * t + 0.5 * np.sin(0.03 * t),
        ]
    )
    inc = between_poses(truth[:-1], truth[1:])
    inc[:, 1] *= 1.1
    inc[:, 2] *= 1.03
    inc[:, :2] += rng.normal(0.0, 2e-5, (inc.shape[0], 2))
    tf = np.arange(0.5, t[-1] - 0.5, 0.125)
    at = np.column_stack([np.interp(tf - 0.05, t, truth[:, k]) for k in range(3)])
    c, s = np.cos(at[:, 2]), np.sin(at[:, 2])
    hedge = at[:, :2] + np.column_stack(
        [c * OFFSET[0] - s * OFFSET[1], s * OFFSET[0] + c * OFFSET[1]]
    )
    return {
        "truth": truth,
        "odom": np.column_stack([t, _dead_reckoned(inc)]),
        "fix_t": tf,
        "fixes": hedge + rng.normal(0.0, 0.02, hedge.shape),
        "cov": np.broadcast_to(np.eye(2) * 0.02**2, (tf.size, 2, 2)).copy(),
        "gyro": np.column_stack([t, np.gradient(truth[:, 2], t) + 0.002]),
    }


def _rms(sm_poses: np.ndarray, truth: np.ndarray) -> float:
    err = np.hypot(*(sm_poses[:, :2] - truth[:, :2]).T)
    return float(np.sqrt(np.mean(err**2)))


def _arrow_system(n: int, nf: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A random positive definite H of the smoother's arrow shape (every term on two
    consecutive poses and the shared parameters) and a right-hand side: dense, the oracle."""
    rng = np.random.default_rng(seed)
    size = 3 * n + nf
    hess = np.diag(rng.uniform(0.1, 1.0, size))
    for k in range(n - 1):
        cols = [*range(3 * k, 3 * k + 6), *range(3 * n, size)]
        jac = rng.normal(size=(4, len(cols)))
        hess[np.ix_(cols, cols)] += jac.T @ jac
    return hess, rng.normal(size=size)


def _normal_of(hess: np.ndarray, b: np.ndarray, n: int) -> _Normal:
    """``hess`` in the banded arrow storage the smoother solves."""
    m = 3 * n
    band = np.zeros((_BAND + 1, m), order="F")
    for d in range(_BAND + 1):  # band[_BAND + i − j, j] = A[i, j], j − i = d
        band[_BAND - d, d:] = np.diagonal(hess[:m, :m], offset=d)
    return _Normal(
        band=band,
        border=hess[m:, :m].reshape(-1, n, 3).copy(),
        shared=hess[m:, m:].copy(),
        b_pose=b[:m].reshape(n, 3).copy(),
        b_shared=b[m:].copy(),
    )


class _Seen:
    """What :func:`_marginals_banded` shows its visitor."""

    def __init__(self) -> None:
        self.sigma: np.ndarray | None = None
        self.g: np.ndarray | None = None
        self.columns: list[tuple[np.ndarray, np.ndarray]] = []

    def pose_block(self, sigma: np.ndarray, g: np.ndarray) -> None:
        self.sigma, self.g = sigma.copy(), g.copy()

    def column(self, col: np.ndarray, root: np.ndarray) -> None:
        self.columns.append((col.copy(), root.copy()))


@pytest.mark.parametrize(("n", "nf"), [(2, 0), (9, 3), (40, 11)])
def test_banded_arrow_solve_and_marginals_are_lapacks_dense_ones(n: int, nf: int) -> None:
    """Steps (damped or not) and marginals by the banded Cholesky and the Schur complement
    equal LAPACK's dense solve and inverse of the same H; the visitor sees the pose block's
    inverse and low-rank terms that add up to the rest of the covariance."""
    hess, b = _arrow_system(n, nf, seed=n + nf)
    m = 3 * n
    for lam in (0.0, 1e-2):
        step = _solve_banded(_normal_of(hess, b, n), lam)
        assert step is not None
        expected = np.linalg.solve(hess + lam * np.diag(np.diag(hess)), b)
        np.testing.assert_allclose(step[0].ravel(), expected[:m], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(step[1], expected[m:], rtol=1e-9, atol=1e-12)
    seen = _Seen()
    sigma, shared_cov = _marginals_banded(_normal_of(hess, b, n), seen)
    cov = np.linalg.inv(hess)
    blocks = cov[:m, :m].reshape(n, 3, n, 3)[np.arange(n), :, np.arange(n)]
    np.testing.assert_allclose(sigma, blocks, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(shared_cov, cov[m:, m:], rtol=1e-9, atol=1e-12)
    pose_inv = np.linalg.inv(hess[:m, :m]).reshape(n, 3, n, 3)
    assert seen.sigma is not None and seen.g is not None
    np.testing.assert_allclose(seen.sigma, pose_inv[np.arange(n), :, np.arange(n)], rtol=1e-9)
    cross = -seen.g[:-1] @ seen.sigma[1:]  # Σ_k,k+1 = −G_k Σ_k+1
    np.testing.assert_allclose(
        cross, pose_inv[np.arange(n - 1), :, np.arange(1, n)], rtol=1e-9, atol=1e-12
    )
    assert len(seen.columns) == nf
    if nf:
        lower = sum(np.outer(-c.ravel(), r) for c, r in seen.columns)
        np.testing.assert_allclose(lower, cov[:m, m:], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("n", [1, 2, 3, 7, 50, 101, 1000])
def test_chunked_backward_recursion_is_the_recursion(n: int) -> None:
    rng = np.random.default_rng(n)
    a = rng.normal(size=(n, 3, 3))
    p = a @ np.swapaxes(a, 1, 2) + np.eye(3)
    g = 0.3 * rng.normal(size=(n, 3, 3))
    expected = np.empty_like(p)
    expected[-1] = p[-1]
    for k in range(n - 2, -1, -1):
        expected[k] = p[k] + g[k] @ expected[k + 1] @ g[k].T
    got = _backward_congruence(p.copy(), g)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12)


def test_long_drifting_run_converges_from_windowed_starts() -> None:
    """12 minutes: the odometry's heading is off by ≈ 5 rad at the end; the smoother still
    lands on the truth (rigid fits per minute start it near it). A long run by default: pose
    nodes at keyframes (test_smoother_keyframes compares them with the full-rate path)."""
    run = _long_run(12.0)
    sm = smooth_track(
        SmootherParams(hedge_offset_m=OFFSET),
        run["odom"],
        run["fix_t"],
        run["fixes"],
        run["cov"],
        gyro=run["gyro"],
    )
    assert sm.converged and sm.keyframe_stride == 2  # 0.1 s at 20 Hz
    rms = _rms(sm.poses, run["truth"])
    assert rms < 0.004
    assert 0.5 < sm.position_sigma_rms_m / rms < 2.0
    shared = sm.shared_dict()
    assert shared["scale_y"][0] == pytest.approx(1 / 1.1 - 1, abs=0.005)
    assert shared["scale_yaw"][0] == pytest.approx(1 / 1.03 - 1, abs=0.005)
    assert shared["gyro_bias_radps"][0] == pytest.approx(0.002, abs=3e-4)


def _peak_bytes(minutes: float) -> tuple[int, int]:
    run = _long_run(minutes, rate_hz=50.0, seed=2)
    args = (run["odom"], run["fix_t"], run["fixes"], run["cov"])
    tracemalloc.start()
    try:
        params = SmootherParams(hedge_offset_m=OFFSET, max_iterations=3, long_run_s=None)
        smooth_track(params, *args)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return run["odom"].shape[0], peak


def test_memory_grows_by_a_fixed_amount_per_pose() -> None:
    """Full rate (every odometry sample a pose node, whatever the length): the sparse LU's
    factors and the dense (3N, 9) solves are gone: ≈ 0.8 kB per pose (the normal equations'
    band and border, the inputs, a few pose-sized vectors), the linearisation's temporaries
    bounded whatever the length."""
    n_short, short = _peak_bytes(4.0)
    n_long, long = _peak_bytes(16.0)
    per_pose = (long - short) / (n_long - n_short)
    assert per_pose < 1000
    assert long < 1100 * n_long + 16e6


def test_garbage_stays_bounded() -> None:
    """Random numbers for odometry and fixes (a corrupt recording): a result or a
    GeometryError, in bounded time and memory — never a factorisation that fills in."""
    rng = np.random.default_rng(5)
    n = 10_000
    t = np.arange(n) * 0.02
    odom = np.column_stack([t, rng.normal(size=(n, 3))])
    tf = np.sort(rng.uniform(0.0, t[-1], 5000))
    fixes = rng.normal(size=(tf.size, 2))
    cov = np.broadcast_to(np.eye(2) * 0.02**2, (tf.size, 2, 2))
    tracemalloc.start()
    try:
        try:
            sm = smooth_track(SmootherParams(max_iterations=10), odom, tf, fixes, cov)
            assert sm.poses.shape == (n, 3)
        except GeometryError:
            pass
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1100 * n + 16e6


def test_envelope_keeps_every_extreme_and_short_series() -> None:
    rng = np.random.default_rng(0)
    short = rng.normal(size=1000)
    np.testing.assert_array_equal(envelope_indices(short), np.arange(1000))
    v = np.cumsum(rng.normal(size=200_001))
    v[123_457] += 50.0  # a spike must survive
    keep = envelope_indices(v, 4000)
    assert keep.size <= 4001 and np.all(np.diff(keep) > 0)
    assert keep[0] == 0 and keep[-1] == v.size - 1
    assert 123_457 in keep
    assert v[keep].max() == v.max() and v[keep].min() == v.min()
    # the envelope of every bin of ≈ 200 samples (< a pixel) is kept
    size = -(-v.size // 1000)
    for start in range(0, v.size, 97 * size):
        b = v[start : start + size]
        inside = v[keep[(keep >= start) & (keep < start + size)]]
        assert inside.max() == b.max() and inside.min() == b.min()
    nan = v.copy()
    nan[10] = np.nan
    assert envelope_indices(nan).size == v.size


def test_steps_and_thinned_paths() -> None:
    steps = np.repeat(np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.0, 0.0, 0.8]]), 1000, axis=0)
    keep = _step_indices(steps)
    np.testing.assert_array_equal(keep, [0, 1000, 2000, 2999])
    xy = np.column_stack([np.arange(120_001.0), np.zeros(120_001)])
    thin = _thinned(xy, 50_000)
    assert thin.shape[0] <= 50_001 and thin[-1, 0] == xy[-1, 0] and thin[0, 0] == 0.0
    assert _thinned(xy[:10]).shape == (10, 2)
