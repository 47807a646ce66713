"""Systematic link errors (``omnical.ips.solve.linkcov``): found when there, not invented."""

from __future__ import annotations

import numpy as np
import pytest

from omnical.ips.beacons import BeaconMap
from omnical.ips.solve import linkcov
from omnical.ips.solve.fixes import CHI2_2DOF_95, FixStatus, mahalanobis_sq
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
    assert model.link_covariance_z > 3.0
    assert model.widening > 1.5
    assert 0.90 <= coverage <= 0.98, coverage
    assert any("correlated" in line for line in model.describe())


@pytest.mark.parametrize("seed", [1, 2])
def test_independent_link_errors_are_left_alone(seed: int) -> None:
    coverage, model = _coverage(seed, 0.0)
    assert model.link_covariance_m2 is None, (model.widening, model.link_covariance_z)
    assert model.link_covariance_z < 3.0
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


def _slow_run(seed: int, n: int = 3000) -> tuple[np.ndarray, np.ndarray]:
    """Ranges with no bias or scale error, but with link errors that drift: σ 4 cm over ~5 s
    (AR(1), independent between links) on top of white noise of σ 2 cm, as real UWB errors
    follow the tag through multipath. The self-calibration reads part of each drift as a bias,
    and how much it learns wrongly depends on what the run happened to do."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 150.0, n)
    truth = np.column_stack([2.5 * np.sin(0.21 * t), 2.0 * np.sin(0.34 * t + 0.5), np.ones(n)])
    a = np.exp(-(t[1] - t[0]) / 5.0)
    drift = np.empty((n, M))
    drift[0] = rng.normal(0.0, 0.04, M)
    for i in range(1, n):
        drift[i] = a * drift[i - 1] + np.sqrt(1.0 - a * a) * rng.normal(0.0, 0.04, M)
    ranges = np.linalg.norm(truth[:, None, :] - _beacons().positions_m[None], axis=2)
    return ranges + drift + rng.normal(0.0, 0.02, (n, M)), truth[:, :2]


@pytest.mark.parametrize("seed", [1, 4])
def test_the_calibrations_own_uncertainty_is_in_the_ellipses(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Drifting link errors: the learned biases are only as good as the run lets them be (their
    block jackknife over the run); carried into the fixes, the ellipses hold the truth
    (measured 0.955 / 0.969), without it they did not (0.883 / 0.918)."""
    ranges, truth = _slow_run(seed)

    def coverage() -> tuple[float, NoiseModel]:
        fixes = solve_self_calibrated(ranges, _beacons(), hedge_z_m=1.0)
        ok = fixes.status == FixStatus.OK
        m2 = mahalanobis_sq(fixes.covariance_xy_m2, fixes.positions_map_m[:, :2] - truth)
        return float(np.mean(m2[ok] <= CHI2_2DOF_95)), fixes.noise[0]

    covered, model = coverage()
    assert model.calibration_covariance is not None
    assert model.calibration_widening > 0.2
    assert any("bias and scale only so well" in line for line in model.describe())
    assert 0.93 <= covered <= 0.98, covered
    monkeypatch.setattr(linkcov, "_calibration_covariance", lambda _: np.zeros((2 * M, 2 * M)))
    without, _ = coverage()
    assert without < covered - 0.03, (without, covered)


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
