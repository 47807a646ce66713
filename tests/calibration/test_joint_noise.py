"""The joint estimator's noise model and 1σ (issue 29): honest over random robots.

The fixes' noise and the slip are estimated from the residuals, the σ come from a sandwich
covariance; here the linear algebra behind them, the robust scale, the slip estimate against the
slip simulated, and the coverage of the 1σ over twenty twin robots with random true factors.
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from typing import Any

import foreign_sim as fs
import numpy as np
import pytest
from scipy import sparse

from omnical.calibration.campaign import estimate_factors
from omnical.calibration.joint.estimate import FACTOR_NAMES, _m_scale, estimate_joint
from omnical.calibration.joint.problem import NormalEquations
from omnical.experiment.library import builtin_script_data
from omnical.experiment.script import parse_script
from omnical.kinematics.correction import CorrectionFactors
from omnical.recording.recording import Recording
from omnical.robot.loader import load_robot
from omnical.twin.params import default_twin
from omnical.twin.session import simulate_run

ROBOT = load_robot("rosy-mecanum")


def _tour(params: Any, seed: int) -> Recording:
    script = parse_script(builtin_script_data("tour"), ROBOT.limits)
    return simulate_run(script, ROBOT, params, seed=seed).without(
        "/ground_truth", "/omnical/events"
    )


def _random_truth(rng: np.random.Generator) -> CorrectionFactors:
    """Scalings within ±6 % (rotational ±4 %), cross-talks of either sign up to 35 mrad/m."""
    scales = 1.0 + rng.uniform(-1.0, 1.0, 3) * np.array([0.06, 0.06, 0.04])
    return CorrectionFactors.from_vector(np.concatenate([scales, rng.uniform(-0.035, 0.035, 4)]))


def test_selected_inverse_and_leverages_match_the_dense_inverse() -> None:
    rng = np.random.default_rng(0)
    rows, n_local, n_shared = 400, 60, 5
    local = np.zeros((rows, n_local))
    for r in range(rows):
        k = int(rng.integers(1, 5))
        c = int(rng.integers(0, n_local - k + 1))
        local[r, c : c + k] = rng.normal(size=k)
    shared = rng.normal(size=(rows, n_shared))
    w = rng.uniform(0.2, 1.0, rows)
    normal = NormalEquations(sparse.csr_matrix(local), shared, w)
    inv = normal.inverse(np.ones(n_shared))
    weighted = np.hstack([local, shared]) * np.sqrt(w)[:, None]
    dense = np.linalg.inv(weighted.T @ weighted)
    hat = np.einsum("ij,jk,ik->i", weighted, dense, weighted)
    np.testing.assert_allclose(normal.leverages(inv), hat, atol=1e-12)
    named = np.array([3, 10, 20])
    cols_local, cols_shared = normal.inverse_columns(inv, named)
    cols = np.concatenate([n_local + np.arange(n_shared), named])
    np.testing.assert_allclose(cols_local, dense[:n_local][:, cols], atol=1e-12)
    np.testing.assert_allclose(cols_shared, dense[n_local:][:, cols], atol=1e-12)
    b = normal.band
    band = local * np.sqrt(w)[:, None]
    b_inv = np.linalg.inv(band.T @ band)
    for j in range(n_local):
        for i in range(max(0, j - b), j + 1):
            assert inv.band[b + i - j, j] == pytest.approx(b_inv[i, j], abs=1e-12)


def test_robust_scale_is_the_variance_of_the_inliers() -> None:
    rng = np.random.default_rng(1)
    r = rng.normal(size=20000)
    assert _m_scale(r, r.size, "soft_l1", 2.0) == pytest.approx(1.0, rel=0.03)
    assert _m_scale(3.0 * r, r.size, "soft_l1", 2.0) == pytest.approx(9.0, rel=0.03)
    with_outliers = np.where(rng.random(r.size) < 0.02, 30.0 * r, r)  # NLOS-like tails
    assert _m_scale(with_outliers, r.size, "soft_l1", 2.0) < 1.3
    assert float(np.mean(with_outliers**2)) > 15.0


@pytest.mark.slow
def test_the_slip_estimate_follows_the_slip() -> None:
    """The twin's tour at 0.3 % and 1 % slip: the slip's variance about 11 times larger."""
    found = {}
    for slip in (0.003, 0.01):
        params = replace(default_twin(ROBOT), slip_sigma=slip)
        values = []
        for seed in range(1, 7):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                est = estimate_joint([_tour(params, seed)], hedge_offset_m=ROBOT.hedge_offset_m[:2])
            values.append(est.noise_variance["slip_along"])
        found[slip] = float(np.median(values))
    assert 5.0 < found[0.01] / found[0.003] < 25.0, found


def test_a_held_latency_is_not_taken_for_slip() -> None:
    """The independent simulator without slip, its latency 70 ms held at the assumed 50 ms.

    Held during the noise estimation, the latency's error passed for slip at every start and
    stop (the slip came out 1.3 times the given densities); now the latency is free for it.
    """
    twist, duration = fs.square_dance()
    truth = replace(fs.ForeignTruth(), start_map=(1.5, 1.6, 0.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = estimate_joint(
            [fs.simulate(twist, duration, truth, seed=2)], hedge_offset_m=truth.hedge_offset_m
        )
    assert est.latency_s == 0.05
    assert est.latency_from_fixes is not None
    assert est.latency_from_fixes[0] == pytest.approx(truth.latency_s, abs=0.005)
    assert est.noise_variance["slip_along"] < 0.3


@pytest.mark.slow
def test_one_sigma_covers_two_thirds_over_twenty_random_robots() -> None:
    """Twenty twin robots with random true factors, the tour each, estimated as the CLI does.

    Honest σ: within 1σ 68 % of the time, within 2σ 95 %, RMS of error/σ 1. Measured on these
    seeds: 68 % and 97 %, RMS 0.97, every factor 60–75 %; the former σ (one residual variance
    for everything, the slip as given) gave 74 %, 100 %, RMS 0.81 and the rotational scaling
    90 % here (80 % over a hundred robots).
    """
    base = default_twin(ROBOT)
    z = []
    for seed in range(1, 21):
        truth = _random_truth(np.random.default_rng(seed))
        rec = _tour(replace(base, true_factors=truth), seed)
        est = estimate_factors([rec], method="joint", hedge_offset_m=ROBOT.hedge_offset_m)
        assert not est.held, est.held
        sigma = np.array([est.sigma[n] for n in FACTOR_NAMES])
        z.append((est.factors.as_vector() - truth.as_vector()) / sigma)
    zs = np.array(z)
    within = np.abs(zs) <= 1.0
    assert 0.58 <= np.mean(within) <= 0.78
    assert np.mean(np.abs(zs) <= 2.0) >= 0.9
    assert 0.85 <= float(np.sqrt(np.mean(zs**2))) <= 1.2
    per_factor = np.mean(within, axis=0)
    assert np.all((per_factor >= 0.45) & (per_factor <= 0.85)), dict(
        zip(FACTOR_NAMES, per_factor, strict=True)
    )
