"""The joint estimate on a long recording whose dead reckoning drifts far (issue "Scale").

A synthetic run, made here with numpy in a few milliseconds (no twin, no multilateration: the
fixes are given): a tour of forward, lateral, a triple turn on the spot, reverse and lateral
moves, repeated. The truth's rotational scaling is 6 % off the installed one, so the odometry's
heading drifts by 1.1 rad per tour and by 13 rad over the 12 tours: dead-reckoned from the
start, the track is a tangle that no single alignment fits. The former solver (slip
coordinates, one alignment from dead reckoning) stopped after 100 evaluations without
converging on such a run (on the 80-minute twin recording too); anchoring every keyframe to the
fixes around it and stepping the keyframes converges, to the truth within its uncertainty.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from omnical.calibration.joint.estimate import JointWarning, estimate_joint
from omnical.calibration.joint.model import real_increments
from omnical.calibration.joint.problem import (
    N_SHARED,
    SparseJointProblem,
    prepare_track,
    windowed_procrustes,
)
from omnical.estimation.se2 import integrate_increments
from omnical.ips.solve.fixes import Fixes, fixes_from_positions
from omnical.kinematics.correction import CorrectionFactors, compensate_twist
from omnical.recording.recording import Recording, RecordingBuilder

TRUTH = CorrectionFactors(1.02, 1.08, 1.06, 0.006, -0.004, 0.03, -0.02)
OFFSET = (0.05, -0.03)
LATENCY_S = 0.05  # the estimator's default, held
ODOM_HZ = 50.0
FIX_HZ = 16.0
FIX_SIGMA_M = 0.02
T0_NS = 1_700_000_000_000_000_000


def _tour() -> list[tuple[float, float, float, float]]:
    """(duration s, vx, vy, wz) of one tour, ≈ 47 s."""
    v, w = 0.3, 0.9
    return [
        (2.0, 0.0, 0.0, 0.0),
        (6.0, v, 0.0, 0.0),
        (1.0, 0.0, 0.0, 0.0),
        (5.0, 0.0, v, 0.0),
        (1.0, 0.0, 0.0, 0.0),
        (3.0 * 2.0 * math.pi / w, 0.0, 0.0, w),
        (1.0, 0.0, 0.0, 0.0),
        (6.0, -v, 0.0, 0.0),
        (1.0, 0.0, 0.0, 0.0),
        (5.0, 0.0, -v, 0.0),
    ]


def long_run(tours: int, seed: int = 3) -> tuple[Recording, Fixes]:
    """``tours`` tours of the truth robot: its /odom (installed: identity) and its fixes."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / ODOM_HZ
    twist = np.concatenate(
        [np.tile([vx, vy, wz], (round(d / dt), 1)) for d, vx, vy, wz in _tour() * tours]
    )
    ramp = np.convolve(np.ones(len(twist)), np.ones(25) / 25, mode="same")  # soften the ends
    real = twist * dt * ramp[:, None]
    # real motion: the commanded one plus the truth's cross-talk, and slip (random walks)
    dist = np.hypot(real[:, 0], real[:, 1])
    real[:, 2] += TRUTH.crosstalk_forward_rad_per_m * np.maximum(real[:, 0], 0.0)
    real[:, 2] -= TRUTH.crosstalk_reverse_rad_per_m * np.maximum(-real[:, 0], 0.0)
    real[:, 2] += TRUTH.crosstalk_left_rad_per_m * np.maximum(real[:, 1], 0.0)
    real[:, 2] -= TRUTH.crosstalk_right_rad_per_m * np.maximum(-real[:, 1], 0.0)
    real[:, :2] += rng.normal(0.0, 1.0, (len(real), 2)) * 0.001 * np.sqrt(dist)[:, None]
    real[:, 2] += rng.normal(0.0, 1.0, len(real)) * 0.002 * np.sqrt(np.abs(real[:, 2]))
    # what the wheels report (the plant's inverse), as odometry from a start off the map origin
    raw = compensate_twist(real, TRUTH)
    np.testing.assert_allclose(real_increments(raw, TRUTH), real, atol=1e-12)
    odom = integrate_increments([3.0, -1.0, 0.4], raw)
    truth = integrate_increments([2.0, 1.5, -0.3], real)
    t_s = np.arange(len(odom)) * dt
    builder = RecordingBuilder()
    builder.add_many(
        "/odom",
        T0_NS + np.round(t_s * 1e9).astype(np.int64),
        x_m=odom[:, 0],
        y_m=odom[:, 1],
        yaw_rad=np.arctan2(np.sin(odom[:, 2]), np.cos(odom[:, 2])),
        vx_mps=np.zeros(len(t_s)),
        vy_mps=np.zeros(len(t_s)),
        wz_radps=np.zeros(len(t_s)),
    )
    # fixes of the hedgehog, published LATENCY_S after the moment they measure
    t_fix = np.arange(0.5, t_s[-1] - 0.5, 1.0 / FIX_HZ)
    c, s = np.cos(truth[:, 2]), np.sin(truth[:, 2])
    hx = truth[:, 0] + c * OFFSET[0] - s * OFFSET[1]
    hy = truth[:, 1] + s * OFFSET[0] + c * OFFSET[1]
    xy = np.column_stack([np.interp(t_fix, t_s, hx), np.interp(t_fix, t_s, hy)])
    xy += rng.normal(0.0, FIX_SIGMA_M, xy.shape)
    fixes = fixes_from_positions(
        T0_NS + np.round((t_fix + LATENCY_S) * 1e9).astype(np.int64), xy, FIX_SIGMA_M, "synthetic"
    )
    return builder.build(), fixes


def _check(tours: int) -> None:
    rec, fixes = long_run(tours)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        est = estimate_joint([rec], fixes=[fixes], hedge_offset_m=(0.0, 0.0))
    assert est.warnings == (), est.warnings  # no "fit: ... without converging", nothing held
    assert not [w for w in caught if issubclass(w.category, JointWarning)]
    err = est.factors.as_vector() - TRUTH.as_vector()
    sigma = est.factor_sigma.as_vector()
    assert np.all(np.abs(err) < 4.0 * sigma), (err, sigma)
    assert np.all(np.abs(err[:3]) < 0.002 * TRUTH.scales), err
    assert np.all(np.abs(err[3:]) < 0.006), err
    assert math.hypot(est.hedge_offset_m[0] - OFFSET[0], est.hedge_offset_m[1] - OFFSET[1]) < 0.005


def test_a_long_drifting_run_converges_to_the_truth() -> None:
    """12 tours (≈ 9.5 minutes): 13 rad of heading drift dead-reckoned with the prior."""
    _check(12)


def test_a_wrong_assumed_latency_is_charged_to_the_sigma() -> None:
    """Held at 20 ms while the fixes lag 50 ms, the estimates shift (up to 5σ of the fit's own
    σ before): the σ now carry the assumed latency's error, as the fixes see it."""
    rec, fixes = long_run(12, seed=4)
    est = estimate_joint([rec], fixes=[fixes], hedge_offset_m=(0.0, 0.0), latency_s=0.02)
    assert est.latency_s == 0.02  # held, not estimated: the estimates are the held fit's
    assert "latency_s" not in est.held
    assert math.isnan(est.sigma["latency_s"])
    assert est.latency_from_fixes is not None
    preferred, sd = est.latency_from_fixes
    assert abs(preferred - LATENCY_S) < 3.0 * sd + 0.001, (preferred, sd)
    assert 0.0 < sd < 0.005
    z = (est.factors.as_vector() - TRUTH.as_vector()) / est.factor_sigma.as_vector()
    assert np.all(np.abs(z) < 2.5), z
    off = np.subtract(est.hedge_offset_m, OFFSET)
    off_z = off / [est.sigma["hedge_offset_x_m"], est.sigma["hedge_offset_y_m"]]
    assert np.all(np.abs(off_z) < 2.5), off_z
    assert est.warnings == ()


def test_a_right_assumed_latency_gives_the_sigma_of_the_latency_estimated() -> None:
    """Held where the fixes put it, the charge is the latency's own variance: the σ are those
    of the fit with the latency free (Schur complement), and the estimates the same."""
    rec, fixes = long_run(12, seed=4)
    free = estimate_joint([rec], fixes=[fixes], hedge_offset_m=(0.0, 0.0), estimate_latency=True)
    assert free.latency_from_fixes is None
    held = estimate_joint([rec], fixes=[fixes], hedge_offset_m=(0.0, 0.0), latency_s=free.latency_s)
    assert held.latency_from_fixes is not None
    preferred, sd = held.latency_from_fixes
    assert preferred == pytest.approx(free.latency_s, abs=1e-5)
    assert sd == pytest.approx(free.sigma["latency_s"], rel=1e-3)
    for name, s in held.sigma.items():
        if name != "latency_s":
            assert s == pytest.approx(free.sigma[name], rel=1e-3), name
    np.testing.assert_allclose(
        held.factors.as_vector(),
        free.factors.as_vector(),
        atol=1e-3 * np.min(free.factor_sigma.as_vector()),
    )


def test_windowed_procrustes_recovers_each_windows_transform_despite_outliers() -> None:
    """A track in four stretches, each mapped by its own transform: one window per stretch."""
    rng = np.random.default_rng(5)
    m = np.linspace(0.0, 40.0, 4000)  # motion so far, m
    q = np.column_stack([m, 0.5 * np.sin(m)])  # a wavy odometry track
    block = np.minimum((m // 10.0).astype(int), 3)
    yaws = 2.0 * np.pi - 0.2 + 0.15 * np.arange(4)  # crosses 2π: unwrapped, not jumping
    shifts = np.array([[0.3, -0.2], [0.8, 0.1], [1.1, 0.6], [1.0, 1.4]])
    c, s = np.cos(yaws[block]), np.sin(yaws[block])
    p = np.column_stack([c * q[:, 0] - s * q[:, 1], s * q[:, 0] + c * q[:, 1]]) + shifts[block]
    p += rng.normal(0.0, 0.01, p.shape)
    bad = rng.random(len(m)) < 0.05
    p[bad] += rng.uniform(0.5, 2.0, (int(bad.sum()), 2))
    out = windowed_procrustes(m, q, p, np.array([5.0, 15.0, 25.0, 35.0]), 1.5)
    np.testing.assert_allclose(out[:, :2], shifts, atol=0.02)
    np.testing.assert_allclose(out[:, 2], yaws - 2.0 * np.pi, atol=0.002)  # first in (−π, π]


def test_the_cached_jacobian_structure_gives_the_same_jacobian() -> None:
    """Once the fixes' samples repeat, the local Jacobian is refilled into a kept structure."""
    rec, fixes = long_run(2)
    noise = (0.004, 0.0005, 0.002, 0.0005)
    track = prepare_track(rec, fixes, CorrectionFactors(), model_sigma_m=0.01, noise=noise)
    problem = SparseJointProblem([track])
    full = np.zeros(len(problem.names))
    full[:7] = TRUTH.as_vector()
    full[9] = LATENCY_S
    problem.anchor(full)
    shared = np.arange(N_SHARED)
    fresh = [problem.linearise(full, shared) for _ in range(3)][-1]  # the third: refilled
    moved = full.copy()
    moved[:7] *= 1.001
    moved[N_SHARED + 3 :: 5] += 0.003
    kept = problem.linearise(moved, shared)
    direct = SparseJointProblem([track]).linearise(moved, shared)
    assert abs(kept.local - direct.local).max() < 1e-12 * abs(direct.local).max()
    np.testing.assert_array_equal(kept.fun, direct.fun)
    again = SparseJointProblem([track]).linearise(full, shared)
    assert abs(fresh.local - again.local).max() < 1e-12 * abs(again.local).max()
