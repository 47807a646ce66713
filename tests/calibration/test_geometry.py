"""Arc and circle fits, three-point arcs, headings and stand-still averages (seed 000 §3.2)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from omnical.calibration.procedures.geometry import (
    arc_length,
    fit_circle,
    mean_position,
)
from omnical.errors import GeometryError

NOISE_M = 0.02


def arc_points(
    curvature: float,
    length_m: float = 5.0,
    n: int = 100,
    *,
    heading: float = 0.3,
    start: tuple[float, float] = (1.0, 2.0),
) -> NDArray[np.float64]:
    """(n, 2) points along an arc of the given signed curvature, evenly spaced in arc length."""
    s = np.linspace(0.0, length_m, n)
    x = s * np.sinc(curvature * s / np.pi)  # sin(κs)/κ
    y = curvature * s**2 / 2.0 * np.sinc(curvature * s / (2.0 * np.pi)) ** 2  # (1 − cos κs)/κ
    c, sn = math.cos(heading), math.sin(heading)
    return np.column_stack([start[0] + c * x - sn * y, start[1] + sn * x + c * y])


@pytest.mark.parametrize(
    ("centre", "radius", "a0", "a1"),
    [((3.0, -2.0), 25.0, 0.2, 0.4), ((-40.0, 7.0), 2.0, -1.0, 2.5), ((0.0, 0.0), 100.0, 3.0, 3.05)],
)
@pytest.mark.parametrize("ccw", [True, False])
def test_exact_circle_is_recovered(
    centre: tuple[float, float], radius: float, a0: float, a1: float, ccw: bool
) -> None:
    angles = np.linspace(a0, a1, 40)
    if not ccw:
        angles = angles[::-1]
    pts = np.asarray(centre) + radius * np.column_stack([np.cos(angles), np.sin(angles)])
    fit = fit_circle(pts)
    sign = 1.0 if ccw else -1.0
    assert fit.curvature_per_m == pytest.approx(sign / radius, rel=1e-9)
    assert fit.radius_m == pytest.approx(radius, rel=1e-9)
    assert fit.centre_xy_m is not None
    np.testing.assert_allclose(fit.centre_xy_m, centre, atol=1e-7 * radius)
    assert fit.rms_m < 1e-9
    assert fit.n_points == 40
    true_length = radius * abs(a1 - a0)
    assert arc_length(fit, pts[0], pts[-1]) == pytest.approx(true_length, rel=1e-9)
    assert arc_length(fit, pts[-1], pts[0]) == pytest.approx(-true_length, rel=1e-9)


@pytest.mark.parametrize("turn", [1.0, 0.75])
def test_full_and_three_quarter_circles(turn: float) -> None:
    angles = np.linspace(0.0, turn * 2.0 * np.pi, 100, endpoint=turn < 1.0)
    pts = np.array([3.0, -2.0]) + 2.0 * np.column_stack([np.cos(angles), np.sin(angles)])
    fit = fit_circle(pts)
    assert fit.curvature_per_m == pytest.approx(0.5, rel=1e-9)
    assert fit.centre_xy_m is not None
    np.testing.assert_allclose(fit.centre_xy_m, [3.0, -2.0], atol=1e-9)
    if turn < 1.0:  # the arc length covers nearly a full circle from the middle of the data
        assert arc_length(fit, pts[0], pts[-1]) == pytest.approx(3.0 * np.pi, rel=1e-9)


@pytest.mark.parametrize("radius_m", [25.0, 100.0, 10_000.0])
def test_noisy_arc_curvature_within_stated_uncertainty(radius_m: float) -> None:
    kappa = 1.0 / radius_m
    n_seeds = 200
    z = np.empty(n_seeds)
    estimates = np.empty(n_seeds)
    for seed in range(n_seeds):
        rng = np.random.default_rng(seed)
        pts = arc_points(kappa) + rng.normal(scale=NOISE_M, size=(100, 2))
        fit = fit_circle(pts)
        estimates[seed] = fit.curvature_per_m
        z[seed] = (fit.curvature_per_m - kappa) / fit.curvature_std_per_m
        assert fit.rms_m == pytest.approx(NOISE_M, rel=0.25)
    within_1 = float(np.mean(np.abs(z) < 1.0))
    within_2 = float(np.mean(np.abs(z) < 2.0))
    assert 0.60 <= within_1 <= 0.76, within_1
    assert 0.91 <= within_2 <= 0.99, within_2
    # unbiased: the mean over the seeds is within 3 standard errors of the truth
    assert abs(estimates.mean() - kappa) < 3.0 * estimates.std() / math.sqrt(n_seeds)
    # a 5 m arc with 2 cm noise resolves curvature to about 2 mrad/m
    assert 0.0015 < float(np.std(estimates)) < 0.003


def test_straight_line_gives_zero_curvature_with_finite_uncertainty() -> None:
    x = np.linspace(0.0, 5.0, 30)
    line = np.column_stack([x, 0.5 * x + 1.0])
    fit = fit_circle(line)
    assert abs(fit.curvature_per_m) < 1e-12
    assert fit.radius_m > 1e11
    assert fit.rms_m < 1e-12
    assert arc_length(fit, line[0], line[-1]) == pytest.approx(math.hypot(5.0, 2.5), rel=1e-12)
    assert fit.heading_rad == pytest.approx(math.atan2(0.5, 1.0), abs=1e-12)

    rng = np.random.default_rng(7)
    noisy = line + rng.normal(scale=NOISE_M, size=line.shape)
    fit = fit_circle(noisy)
    assert 0.0 < fit.curvature_std_per_m < 0.02
    assert abs(fit.curvature_per_m) < 3.0 * fit.curvature_std_per_m
    assert math.isfinite(fit.radius_std_m)


def test_reversed_traversal_flips_the_sign() -> None:
    pts = arc_points(0.02)
    ccw = fit_circle(pts)
    cw = fit_circle(pts[::-1])
    assert ccw.curvature_per_m == pytest.approx(0.02, rel=1e-9)
    assert cw.curvature_per_m == pytest.approx(-0.02, rel=1e-9)
    assert cw.heading_rad == pytest.approx(ccw.heading_rad - np.pi, abs=1e-9) or (
        cw.heading_rad == pytest.approx(ccw.heading_rad + np.pi, abs=1e-9)
    )
    clockwise = arc_points(-0.04, heading=-2.0)
    assert fit_circle(clockwise).curvature_per_m == pytest.approx(-0.04, rel=1e-9)


def _with_outliers(
    rng: np.random.Generator, kappa: float, zone: slice | None = None
) -> NDArray[np.float64]:
    pts = arc_points(kappa) + rng.normal(scale=NOISE_M, size=(100, 2))
    if zone is None:  # NLOS jumps scattered along the track, in any direction
        idx = rng.choice(100, 10, replace=False)
        angle = rng.uniform(0.0, 2.0 * np.pi, 10)
        jump = np.column_stack([np.cos(angle), np.sin(angle)])
    else:  # an NLOS zone: the fixes there are all pushed the same way
        idx = rng.choice(np.arange(100)[zone], 10, replace=False)
        jump = np.tile([0.0, 1.0], (10, 1))
    pts[idx] += rng.uniform(0.3, 1.0, (10, 1)) * jump
    return pts


def test_robust_loss_rejects_scattered_outliers() -> None:
    kappa = 0.02
    err_linear, err_robust, z_robust = [], [], []
    for seed in range(40):
        pts = _with_outliers(np.random.default_rng(seed), kappa)
        err_linear.append(fit_circle(pts).curvature_per_m - kappa)
        robust = fit_circle(pts, loss="soft_l1", f_scale_m=0.05)
        err_robust.append(robust.curvature_per_m - kappa)
        z_robust.append(err_robust[-1] / robust.curvature_std_per_m)
    rms_linear = float(np.sqrt(np.mean(np.square(err_linear))))
    rms_robust = float(np.sqrt(np.mean(np.square(err_robust))))
    assert rms_robust < 0.3 * rms_linear
    assert rms_robust < 0.005
    assert 0.5 <= float(np.mean(np.abs(z_robust) < 1.0)) <= 0.85


def test_redescending_loss_handles_an_nlos_zone() -> None:
    kappa = 0.02
    err_soft_l1 = []
    err_cauchy = []
    for seed in range(10):
        pts = _with_outliers(np.random.default_rng(seed), kappa, zone=slice(40, 60))
        assert abs(fit_circle(pts).curvature_per_m - kappa) > 0.04
        cauchy = fit_circle(pts, loss="cauchy", f_scale_m=0.05)
        assert abs(cauchy.curvature_per_m - kappa) < 3.0 * cauchy.curvature_std_per_m
        err_cauchy.append(abs(cauchy.curvature_per_m - kappa))
        soft_l1 = fit_circle(pts, loss="soft_l1", f_scale_m=0.05)
        err_soft_l1.append(abs(soft_l1.curvature_per_m - kappa))
    # soft_l1 bounds the pull of each outlier but ten of them on one side still bend the arc
    assert np.mean(err_cauchy) < 0.5 * np.mean(err_soft_l1)


def test_zero_weight_equals_dropping_the_point() -> None:
    rng = np.random.default_rng(3)
    pts = arc_points(0.03, n=50) + rng.normal(scale=NOISE_M, size=(50, 2))
    pts[10] += [0.0, 2.0]
    weights = np.ones(50)
    weights[10] = 0.0
    weighted = fit_circle(pts, weights)
    dropped = fit_circle(np.delete(pts, 10, axis=0))
    assert weighted.curvature_per_m == pytest.approx(dropped.curvature_per_m, rel=1e-7)
    assert weighted.curvature_std_per_m == pytest.approx(dropped.curvature_std_per_m, rel=1e-6)
    assert weighted.n_points == 49
    assert weighted.residuals_m[10] > 1.9  # reported, though not used


def test_three_points_fit_exactly_with_unknown_uncertainty() -> None:
    fit = fit_circle([[0.0, 0.0], [1.0, 0.1], [2.0, 0.0]])
    # the circle through the three points: Menger curvature 2 (M − S) × (F − M) / (|SM| |MF| |SF|),
    # negative (S → M → F turns clockwise)
    sm, mf = np.array([1.0, 0.1]), np.array([1.0, -0.1])
    menger = 2.0 * (sm[0] * mf[1] - sm[1] * mf[0]) / (np.hypot(*sm) * np.hypot(*mf) * 2.0)
    assert fit.curvature_per_m == pytest.approx(menger, rel=1e-9)
    assert fit.curvature_std_per_m == math.inf


@pytest.mark.parametrize(
    ("points", "weights", "match"),
    [
        ([[0.0, 0.0], [1.0, 1.0]], None, "at least 3"),
        ([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 0.0, 0.0]], None, "shape"),
        ([[1.0, 1.0]] * 5, None, "coincide"),
        ([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0], [np.nan, 0.0]], None, "non-finite"),
        ([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0]], [1.0, -1.0, 1.0], "weights"),
        ([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0], [3.0, 1.0]], [1.0, 0.0, 1.0, 0.0], "positive"),
    ],
)
def test_fit_circle_refuses_degenerate_input(
    points: list[list[float]], weights: list[float] | None, match: str
) -> None:
    with pytest.raises(GeometryError, match=match):
        fit_circle(points, weights)


def test_fit_circle_refuses_bad_options() -> None:
    pts = arc_points(0.01, n=10)
    with pytest.raises(GeometryError, match="loss"):
        fit_circle(pts, loss="l2")  # type: ignore[arg-type]
    with pytest.raises(GeometryError, match="f_scale_m"):
        fit_circle(pts, loss="soft_l1", f_scale_m=0.0)


@pytest.mark.parametrize("robust", [True, False])
def test_mean_position_and_its_standard_error(robust: bool) -> None:
    truth = np.array([2.0, -1.0])
    n, sigma = 200, 0.03
    z = []
    for seed in range(200):
        rng = np.random.default_rng(seed)
        mean = mean_position(truth + rng.normal(scale=sigma, size=(n, 2)), robust=robust)
        np.testing.assert_allclose(mean.std_error_m, sigma / math.sqrt(n), rtol=0.2)
        z.extend((mean.mean_xy_m - truth) / mean.std_error_m)
        assert mean.n_points == n
    assert 0.62 <= float(np.mean(np.abs(z) < 1.0)) <= 0.74


def test_robust_mean_ignores_nlos_outliers() -> None:
    truth = np.array([2.0, -1.0, 0.4])
    rng = np.random.default_rng(11)
    pts = truth + rng.normal(scale=0.02, size=(100, 3))
    pts[:8] += [0.8, 0.5, 0.0]  # NLOS jumps, all the same way
    robust = mean_position(pts)
    plain = mean_position(pts, robust=False)
    assert np.all(np.abs(robust.mean_xy_m - truth) < 0.012)
    assert np.abs(plain.mean_xy_m - truth)[0] > 0.05
    assert np.all(robust.std_error_m[:2] < 0.2 * plain.std_error_m[:2])


def test_mean_position_edge_cases() -> None:
    quantised = np.array([[1.0, 2.0]] * 7 + [[1.001, 2.0], [1.0, 2.002]])
    mean = mean_position(quantised)
    np.testing.assert_allclose(mean.mean_xy_m, [1.0, 2.0], atol=2e-4)
    assert np.all(np.isfinite(mean.std_error_m))
    constant = mean_position(np.array([[1.0, 2.0]] * 5))
    np.testing.assert_array_equal(constant.mean_xy_m, [1.0, 2.0])
    np.testing.assert_array_equal(constant.std_error_m, [0.0, 0.0])
    single = mean_position([[1.0, 2.0]])
    np.testing.assert_array_equal(single.mean_xy_m, [1.0, 2.0])
    assert np.all(single.std_error_m == math.inf)
    with pytest.raises(GeometryError, match="at least 1"):
        mean_position(np.zeros((0, 2)))
    with pytest.raises(GeometryError, match="shape"):
        mean_position(np.zeros(4))
