"""Correlated link errors (``omnical.ips.solve.linkcov``): found when there, not invented."""

from __future__ import annotations

import numpy as np
import pytest

from omnical.ips import CHI2_2DOF_95, BeaconMap, FixStatus, mahalanobis_sq
from omnical.ips.solve.linkcov import loewner_max
from omnical.ips.solve.locate import solve_self_calibrated
from omnical.ips.solve.noise_model import NoiseModel

M = 8
SIGMA_M = 0.04


def _beacons() -> BeaconMap:
    angle = np.linspace(0.0, 2.0 * np.pi, M, endpoint=False)
    positions = np.column_stack([5.0 * np.cos(angle), 4.0 * np.sin(angle), np.full(M, 1.0)])
    return BeaconMap(np.arange(1, M + 1), positions)


def _run(seed: int, correlation: float, n: int = 3000) -> tuple[np.ndarray, np.ndarray]:
    """Ranges from a tag looping inside the beacons (z = 1 m, their plane), with link errors
    of σ 4 cm correlated ``correlation · cos(Δφ)`` between beacons Δφ apart round the ring
    (the pattern of a shift of the tag seen from the middle: nearly invisible in one fix's
    residuals, visible over the run as the tag moves)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 150.0, n)
    truth = np.column_stack([2.5 * np.sin(0.21 * t), 2.0 * np.sin(0.34 * t + 0.5), np.ones(n)])
    angle = np.linspace(0.0, 2.0 * np.pi, M, endpoint=False)
    shape = (1.0 - correlation) * np.eye(M) + correlation * np.cos(angle[:, None] - angle[None])
    covariance = SIGMA_M**2 * shape
    errors = rng.multivariate_normal(np.zeros(M), covariance, n)
    ranges = np.linalg.norm(truth[:, None, :] - _beacons().positions_m[None], axis=2) + errors
    return ranges, truth[:, :2]


def _coverage(seed: int, correlation: float) -> tuple[float, NoiseModel]:
    ranges, truth = _run(seed, correlation)
    fixes = solve_self_calibrated(ranges, _beacons(), hedge_z_m=1.0)
    ok = fixes.status == FixStatus.OK
    m2 = mahalanobis_sq(fixes.covariance_xy_m2, fixes.positions_map_m[:, :2] - truth)
    return float(np.mean(m2[ok] <= CHI2_2DOF_95)), fixes.noise[0]


@pytest.mark.parametrize("seed", [1, 2])
def test_correlated_link_errors_widen_the_ellipses_to_the_truth(seed: int) -> None:
    """The links err together (ρ 0.7 · cos Δφ): independent-noise ellipses hold the truth far
    less than 95 % of the time; the learned link covariance brings them back."""
    coverage, model = _coverage(seed, 0.7)
    assert model.link_covariance_m2 is not None, model.describe()
    assert model.widening > 1.5
    assert 0.90 <= coverage <= 0.98, coverage
    assert any("correlated" in line for line in model.describe())


@pytest.mark.parametrize("seed", [1, 2])
def test_independent_link_errors_are_left_alone(seed: int) -> None:
    coverage, model = _coverage(seed, 0.0)
    assert model.link_covariance_m2 is None, (model.widening, model.widening_sd)
    assert abs(model.widening - 1.0) < 3.0 * model.widening_sd
    assert 0.92 <= coverage <= 0.98, coverage


def test_without_it_the_ellipses_were_too_small() -> None:
    """The same correlated run solved with σ fixed (nothing learned): coverage far below 95 %."""
    ranges, truth = _run(1, 0.7)
    fixes = solve_self_calibrated(ranges, _beacons(), hedge_z_m=1.0, range_sigma_m=SIGMA_M)
    ok = fixes.status == FixStatus.OK
    m2 = mahalanobis_sq(fixes.covariance_xy_m2, fixes.positions_map_m[:, :2] - truth)
    assert fixes.noise[0].link_covariance_m2 is None
    assert np.mean(m2[ok] <= CHI2_2DOF_95) < 0.85


def test_loewner_max_is_at_least_both() -> None:
    rng = np.random.default_rng(5)
    a_half, b_half = rng.normal(size=(200, 2, 2)), rng.normal(size=(200, 2, 2))
    a = a_half @ np.swapaxes(a_half, 1, 2) + 1e-3 * np.eye(2)
    b = b_half @ np.swapaxes(b_half, 1, 2) + 1e-3 * np.eye(2)
    c = loewner_max(a, b)
    for other in (a, b):
        assert np.all(np.linalg.eigvalsh(c - other) > -1e-9)
    np.testing.assert_allclose(loewner_max(a, a), a, atol=1e-12)
    np.testing.assert_allclose(loewner_max(a, 0.5 * a), a, atol=1e-12)
    np.testing.assert_allclose(loewner_max(a, 2.0 * a), 2.0 * a, atol=1e-12)
