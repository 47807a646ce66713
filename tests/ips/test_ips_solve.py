"""Multilateration: exact recovery, least-squares oracle, statuses, reasons, covariance."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from ips_synthetic import exact_distances, locate_recording, measure, trajectory_inside
from scipy.optimize import least_squares

from omnical.choices import LocateMethod
from omnical.errors import ChoiceError, ConfigError
from omnical.ips.beacons import BeaconMap, default_beacon_map
from omnical.ips.solve._fit import SolverOptions, chi2_threshold
from omnical.ips.solve.fixes import FixReason, FixStatus, ellipses_from_covariances
from omnical.ips.solve.locate import solve_fixes

MS = 1_000_000
SQUARE = BeaconMap(
    np.array([1, 2, 3, 4]),
    np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [2.0, 2.0, 0.0]]),
)
SOLID = BeaconMap(
    np.array([1, 2, 3, 4, 5]),
    np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.5], [0.0, 5.0, 1.0], [5.0, 5.0, 2.5], [2.5, 2.5, 3.0]]),
)


@settings(max_examples=60, deadline=None)
@given(st.floats(-1.0, 7.0), st.floats(-1.0, 6.0), st.sampled_from(["lsq", "robust"]))
def test_noiseless_distances_give_the_point_back(x: float, y: float, method: str) -> None:
    beacons = default_beacon_map()
    point = np.array([[x, y, 0.4]])
    assume(np.min(np.hypot(x - beacons.positions_m[:, 0], y - beacons.positions_m[:, 1])) > 0.05)
    fixes = solve_fixes(exact_distances(beacons, point), beacons, method=method)  # type: ignore[arg-type]
    np.testing.assert_allclose(fixes.positions_map_m, point, atol=1e-6)
    assert fixes.status[0] == FixStatus.OK
    assert fixes.residual_rms_m[0] < 1e-6


def test_known_hedge_height_below_the_beacons() -> None:
    beacons = default_beacon_map()
    truth = np.array([[2.0, 3.0, 0.1], [4.5, 1.0, 0.1]])
    distances = exact_distances(beacons, truth)
    right = solve_fixes(distances, beacons, method="lsq", hedge_z_m=0.1)
    np.testing.assert_allclose(right.positions_map_m, truth, atol=1e-9)
    wrong = solve_fixes(distances, beacons, method="lsq", hedge_z_m=0.4)
    assert np.all(np.linalg.norm(wrong.positions_map_m[:, :2] - truth[:, :2], axis=1) > 1e-3)


@pytest.mark.parametrize("method", ["lsq", "robust", "grid"])
def test_a_height_per_fix(method: str) -> None:
    beacons = default_beacon_map()
    truth = np.array([[2.0, 3.0, 0.1], [4.5, 1.0, 0.3], [1.0, 1.0, 0.9]])
    fixes = solve_fixes(
        exact_distances(beacons, truth),
        beacons,
        method=method,  # type: ignore[arg-type]
        hedge_z_m=truth[:, 2],
    )
    np.testing.assert_allclose(
        fixes.positions_map_m, truth, atol=1e-3 if method == "grid" else 1e-8
    )


def test_robust_in_three_dimensions() -> None:
    truth = np.array([[2.0, 3.0, 1.0], [3.0, 2.0, 0.5]])
    distances = exact_distances(SOLID, truth)
    distances[[0, 1], [4, 1]] += [0.4, 0.7]
    fixes = solve_fixes(distances, SOLID, method="robust", dims=3)
    np.testing.assert_allclose(fixes.positions_map_m, truth, atol=1e-8)
    assert fixes.used[[0, 1], [4, 1]].tolist() == [False, False]
    # Issue 11: a clearly identified NLOS range left out of a consistent rest leaves an ok fix.
    assert fixes.status.tolist() == [FixStatus.OK, FixStatus.OK]
    assert np.all(fixes.has_reason(FixReason.OUTLIER_REJECTED))


def test_three_dimensional_solution() -> None:
    truth = np.array([[2.0, 3.0, 1.0], [1.0, 4.0, 0.2], [3.5, 1.5, 2.0]])
    fixes = solve_fixes(exact_distances(SOLID, truth), SOLID, method="lsq", dims=3)
    np.testing.assert_allclose(fixes.positions_map_m, truth, atol=1e-8)
    assert np.all(fixes.status == FixStatus.OK)
    assert np.all(fixes.sigma_z_m > 0.0)


def test_lsq_matches_scipy_least_squares() -> None:
    rng = np.random.default_rng(11)
    beacons = default_beacon_map()
    data = measure(rng, beacons, trajectory_inside(rng, 200), sigma_m=0.03, outlier_rate=0.1)
    fixes = solve_fixes(data.distances_m, beacons, method="lsq")
    positions = beacons.positions_m
    for i in range(0, 200, 7):

        def residual(p: np.ndarray, d: np.ndarray = data.distances_m[i]) -> np.ndarray:
            modelled: np.ndarray = np.hypot(p[0] - positions[:, 0], p[1] - positions[:, 1])
            difference: np.ndarray = modelled - d
            return difference

        reference = least_squares(residual, data.truth_m[i, :2], xtol=1e-14, ftol=1e-14).x
        np.testing.assert_allclose(fixes.positions_map_m[i, :2], reference, atol=1e-6)


def test_covariance_hdop_and_sigma_floor_at_the_centre_of_a_square() -> None:
    fixes = solve_fixes(
        exact_distances(SQUARE, np.array([[1.0, 1.0, 0.0]])),
        SQUARE,
        method="lsq",
        hedge_z_m=0.0,
        range_sigma_m=0.02,
    )
    # Unit vectors at ±45°: JᵀJ = 2 I, so HDOP = 1 and C = σ²/2 I with σ̂ floored to 0.02.
    assert fixes.hdop[0] == pytest.approx(1.0)
    assert fixes.range_sigma_m[0] == pytest.approx(0.02)
    np.testing.assert_allclose(fixes.covariance_xy_m2[0], 0.0002 * np.eye(2), atol=1e-15)
    one_sigma = fixes.ellipses()
    assert one_sigma.semi_major_m[0] == pytest.approx(0.02 / np.sqrt(2))


def test_sigma_estimated_from_residuals_above_the_floor() -> None:
    distances = exact_distances(SQUARE, np.array([[1.0, 1.0, 0.0]]))
    distances[0] += np.array([0.1, -0.1, -0.1, 0.1])  # residuals orthogonal to JᵀJ's range
    fixes = solve_fixes(distances, SQUARE, method="lsq", hedge_z_m=0.0, range_sigma_m=0.02)
    np.testing.assert_allclose(fixes.positions_map_m[0, :2], [1.0, 1.0], atol=1e-3)
    rss = np.sum(
        (
            np.hypot(*(fixes.positions_map_m[0, :2, None] - SQUARE.positions_m[:, :2].T))
            - distances[0]
        )
        ** 2
    )
    assert fixes.range_sigma_m[0] == pytest.approx(np.sqrt(rss / 2), rel=1e-6)
    assert fixes.residual_rms_m[0] == pytest.approx(np.sqrt(rss / 4), rel=1e-6)
    assert fixes.error_eq4_m[0] == pytest.approx(np.sqrt(rss) / 16, rel=1e-6)
    assert fixes.status[0] == FixStatus.DEGRADED
    assert fixes.has_reason(FixReason.HIGH_RESIDUAL)[0]


def test_ellipse_axes_and_angle() -> None:
    angle = 0.3
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    cov = rotation @ np.diag([4.0, 1.0]) @ rotation.T
    ellipses = ellipses_from_covariances(cov[None], scale=1.0)
    assert ellipses.semi_major_m[0] == pytest.approx(2.0)
    assert ellipses.semi_minor_m[0] == pytest.approx(1.0)
    assert ellipses.angle_rad[0] == pytest.approx(angle)


def test_robust_drops_a_single_nlos_range() -> None:
    beacons = default_beacon_map()
    truth = np.array([[2.0, 2.5, 0.4], [4.0, 1.0, 0.4], [1.2, 3.9, 0.4]])
    distances = exact_distances(beacons, truth)
    distances[np.arange(3), [2, 0, 3]] += [0.5, 0.2, 1.0]
    robust = solve_fixes(distances, beacons, method="robust")
    np.testing.assert_allclose(robust.positions_map_m, truth, atol=1e-6)
    # Issue 11: ok when the dropped beacon was clearly the one, degraded when it was a guess.
    ambiguous = robust.has_reason(FixReason.AMBIGUOUS_OUTLIER)
    assert np.all(robust.status == np.where(ambiguous, FixStatus.DEGRADED, FixStatus.OK))
    assert robust.status.tolist().count(FixStatus.OK) >= 2
    assert np.all(robust.has_reason(FixReason.OUTLIER_REJECTED))
    assert robust.used[np.arange(3), [2, 0, 3]].tolist() == [False, False, False]
    assert robust.n_used.tolist() == [3, 3, 3]
    plain = solve_fixes(distances, beacons, method="lsq")
    assert np.all(np.linalg.norm(plain.positions_map_m - truth, axis=1) > 0.02)
    assert np.all(plain.has_reason(FixReason.HIGH_RESIDUAL))


def test_robust_rejects_two_nlos_ranges_of_four() -> None:
    beacons = default_beacon_map()
    distances = exact_distances(beacons, np.array([[2.0, 2.5, 0.4]]))
    distances[0, [0, 3]] += [0.6, 0.4]
    fixes = solve_fixes(distances, beacons, method="robust")
    assert fixes.status[0] == FixStatus.REJECTED
    assert np.all(np.isfinite(fixes.positions_map_m[0]))


def test_robust_drops_several_nlos_ranges_with_many_beacons() -> None:
    angles = np.linspace(0.0, 2 * np.pi, 9)[:-1]
    ring = BeaconMap(
        np.arange(8), np.column_stack([4 * np.cos(angles), 3 * np.sin(angles), np.zeros(8)])
    )
    truth = np.array([[0.5, -0.4, 0.0]])
    distances = exact_distances(ring, truth)
    distances[0, [1, 4]] += [0.8, 0.3]
    fixes = solve_fixes(distances, ring, method="robust", hedge_z_m=0.0)
    np.testing.assert_allclose(fixes.positions_map_m, truth, atol=1e-6)
    assert fixes.used[0].tolist() == [True, False, True, True, False, True, True, True]


@pytest.mark.parametrize("method", ["lsq", "robust", "grid"])
def test_bad_input_is_flagged_and_never_raises(method: str) -> None:
    beacons = default_beacon_map()
    truth = np.array([[2.0, 2.0, 0.4]] * 6)
    distances = exact_distances(beacons, truth)
    distances[1, 0] = -1.0  # negative: invalid, three beacons remain
    distances[2, :2] = np.nan  # two beacons only
    distances[3, :] = np.nan  # nothing heard
    distances[4, 1] = np.inf
    fixes = solve_fixes(distances, beacons, method=method)  # type: ignore[arg-type]
    assert fixes.status.tolist()[0] == FixStatus.OK
    assert fixes.has_reason(FixReason.INVALID_DISTANCE).tolist() == [
        False,
        True,
        False,
        False,
        True,
        False,
    ]
    assert fixes.status[2] == fixes.status[3] == FixStatus.DEGENERATE
    assert fixes.has_reason(FixReason.TOO_FEW_BEACONS).tolist() == [
        False,
        False,
        True,
        True,
        False,
        False,
    ]
    assert np.all(np.isnan(fixes.positions_map_m[[2, 3]]))
    assert np.all(np.isnan(fixes.covariance_xy_m2[[2, 3]]))
    good = [0, 1, 4, 5]
    np.testing.assert_allclose(fixes.positions_map_m[good], truth[good], atol=1e-3)
    assert fixes.n_used.tolist() == [4, 3, 0, 0, 3, 4]


def test_no_fixes_give_an_empty_result() -> None:
    fixes = solve_fixes(np.zeros((0, 4)), default_beacon_map())
    assert len(fixes) == 0
    assert fixes.positions_map_m.shape == (0, 3)
    assert fixes.used.shape == (0, 4)


def test_solver_options_are_validated() -> None:
    with pytest.raises(ConfigError, match="alpha out of range"):
        SolverOptions(alpha=1.5)
    with pytest.raises(ConfigError, match="max_iterations out of range"):
        SolverOptions(iterations=5, max_iterations=3)


def test_collinear_beacons_are_degenerate() -> None:
    line = BeaconMap(np.arange(4), np.column_stack([np.arange(4.0), np.zeros(4), np.zeros(4)]))
    distances = exact_distances(line, np.array([[1.5, 2.0, 0.0]]))
    fixes = solve_fixes(distances, line, method="lsq", hedge_z_m=0.0)
    assert fixes.status[0] == FixStatus.DEGENERATE
    assert fixes.has_reason(FixReason.SINGULAR_GEOMETRY)[0]


def test_three_dimensional_special_cases() -> None:
    beacons = default_beacon_map()
    coplanar = solve_fixes(exact_distances(beacons, np.array([[2.0, 2.0, 1.0]])), beacons, dims=3)
    assert coplanar.status[0] == FixStatus.DEGENERATE
    assert coplanar.has_reason(FixReason.SINGULAR_GEOMETRY)[0]
    four = BeaconMap(SOLID.addresses[[0, 1, 2, 4]], SOLID.positions_m[[0, 1, 2, 4]])
    distances = exact_distances(four, np.array([[2.0, 3.0, 1.0]] * 2))
    distances[1, 3] = np.nan  # three beacons: two mirror solutions
    fixes = solve_fixes(distances, four, dims=3)
    np.testing.assert_allclose(fixes.positions_map_m[0], [2.0, 3.0, 1.0], atol=1e-8)
    assert fixes.status.tolist() == [FixStatus.OK, FixStatus.DEGENERATE]
    assert fixes.has_reason(FixReason.TOO_FEW_BEACONS).tolist() == [False, True]


def test_unknown_hedge_height() -> None:
    no_hedge = BeaconMap(default_beacon_map().addresses, default_beacon_map().positions_m)
    distances = exact_distances(no_hedge, np.array([[2.0, 2.0, 0.4], [3.0, 1.0, 0.4]]))
    with pytest.raises(ConfigError, match="needs the hedgehog height"):
        solve_fixes(distances, no_hedge)
    fixes = solve_fixes(distances, no_hedge, hedge_z_m=[0.4, np.nan])
    assert fixes.status.tolist() == [FixStatus.OK, FixStatus.DEGENERATE]
    assert fixes.has_reason(FixReason.UNKNOWN_HEDGE_HEIGHT).tolist() == [False, True]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"method": "magic"}, "method: unknown value 'magic'; choose robust, lsq or grid"),
        ({"dims": 4}, "dims must be 2 or 3"),
        ({"range_sigma_m": -0.1}, "must be positive"),
        ({"range_sigma_m": [0.1, 0.2]}, r"shape \(4,\)"),
        ({"hedge_z_m": [0.1, 0.2, 0.3]}, r"hedge_z_m must be a scalar or shape \(2,\)"),
        ({"method": "grid", "dims": 3}, "'grid' solves 2D fixes only"),
    ],
)
def test_misuse_raises_config_error(kwargs: dict[str, object], message: str) -> None:
    beacons = default_beacon_map()
    distances = exact_distances(beacons, np.array([[2.0, 2.0, 0.4]] * 2))
    with pytest.raises(ConfigError, match=message):
        solve_fixes(distances, beacons, **kwargs)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"shape \(n, 4\)"):
        solve_fixes(distances[:, :3], beacons)


def test_per_beacon_sigma_weights_the_fit() -> None:
    beacons = default_beacon_map()
    truth = np.array([[2.0, 2.5, 0.4]])
    distances = exact_distances(beacons, truth)
    distances[0, 1] += 0.05  # a small error on a beacon declared noisy
    uniform = solve_fixes(distances, beacons, method="lsq", range_sigma_m=[0.02] * 4)
    same = solve_fixes(distances, beacons, method="lsq", range_sigma_m=0.02)
    np.testing.assert_array_equal(uniform.positions_map_m, same.positions_map_m)
    weighted = solve_fixes(distances, beacons, method="lsq", range_sigma_m=[0.02, 0.5, 0.02, 0.02])
    error_uniform = np.linalg.norm(same.positions_map_m - truth)
    error_weighted = np.linalg.norm(weighted.positions_map_m - truth)
    assert error_weighted < 0.05 * error_uniform


def test_chunks_and_threads_do_not_change_results() -> None:
    rng = np.random.default_rng(5)
    beacons = default_beacon_map()
    data = measure(rng, beacons, trajectory_inside(rng, 3000), sigma_m=0.02, outlier_rate=0.1)
    one = solve_fixes(data.distances_m, beacons)
    many = solve_fixes(data.distances_m, beacons, chunk_size=257, workers=2)
    # Blocks stop iterating when all their fixes have converged: equal to rounding.
    np.testing.assert_allclose(one.positions_map_m, many.positions_map_m, atol=1e-9)
    np.testing.assert_array_equal(one.status, many.status)
    np.testing.assert_array_equal(one.used, many.used)


def test_locate_recording_end_to_end() -> None:
    rng = np.random.default_rng(9)
    beacons = default_beacon_map()
    truth = trajectory_inside(rng, 50)
    distances = exact_distances(beacons, truth)
    t_ns, hedge, beacon, distance = [], [], [], []
    for i in range(50):
        order = rng.permutation(4)
        for k, j in enumerate(order):
            t_ns.append(i * 100 * MS + k * 3 * MS)
            hedge.append(10)
            beacon.append(int(beacons.addresses[j]))
            distance.append(np.nan if (i == 7 and j == 2) else distances[i, j])
        if i == 3:
            t_ns.append(i * 100 * MS + 12 * MS)
            hedge.append(10)
            beacon.append(42)
            distance.append(1.0)
    fixes = locate_recording(
        np.array(t_ns),
        np.array(hedge),
        np.array(beacon),
        np.array(distance),
        beacons,
        method="robust",
    )
    assert len(fixes) == 50
    assert fixes.t_ns is not None and fixes.address_hedge is not None
    np.testing.assert_array_equal(fixes.t_ns, np.arange(50) * 100 * MS)
    assert set(fixes.address_hedge.tolist()) == {10}
    np.testing.assert_allclose(fixes.positions_map_m, truth, atol=1e-6)
    assert np.flatnonzero(fixes.has_reason(FixReason.UNKNOWN_BEACON)).tolist() == [3]
    assert np.flatnonzero(fixes.has_reason(FixReason.INVALID_DISTANCE)).tolist() == [7]
    assert fixes.n_used[7] == 3


def test_locate_recording_flags_hedgehogs_without_height() -> None:
    beacons = default_beacon_map()
    distances = exact_distances(beacons, np.array([[2.0, 2.0, 0.4]]))[0]
    t_ns = np.array([0, 1, 2, 3, 100, 101, 102, 103]) * MS
    hedge = np.array([10] * 4 + [11] * 4)
    beacon = np.tile(beacons.addresses, 2)
    fixes = locate_recording(t_ns, hedge, beacon, np.tile(distances, 2), beacons)
    assert fixes.status.tolist() == [FixStatus.OK, FixStatus.DEGENERATE]
    fallback = locate_recording(t_ns, hedge, beacon, np.tile(distances, 2), beacons, hedge_z_m=0.4)
    assert fallback.status.tolist() == [FixStatus.OK, FixStatus.OK]


@pytest.mark.parametrize("alpha", [0.5, 0.05, 0.01, 1e-4])
def test_chi2_threshold_equals_scipy_stats(alpha: float) -> None:
    stats = pytest.importorskip("scipy.stats")
    dof = np.array([0, 1, 2, 3, 5, 8, 13])
    threshold = chi2_threshold(dof, alpha)
    assert threshold[0] == np.inf
    np.testing.assert_allclose(threshold[1:], stats.chi2.isf(alpha, dof[1:]), rtol=1e-12)


def test_method_enum_and_plain_string_agree() -> None:
    beacons = default_beacon_map()
    distances = exact_distances(beacons, np.array([[2.0, 3.0, 0.4], [4.0, 1.0, 0.4]]))
    by_enum = solve_fixes(distances, beacons, method=LocateMethod.LSQ)
    by_text = solve_fixes(distances, beacons, method="lsq")
    np.testing.assert_array_equal(by_enum.positions_map_m, by_text.positions_map_m)
    assert by_enum.method == by_text.method == "lsq"
    with pytest.raises(ChoiceError, match="solve_fixes: method: unknown value 'LSQ'"):
        solve_fixes(distances, beacons, method="LSQ")  # type: ignore[arg-type]
