"""The compiled Gauss–Newton (numba) against the numpy reference, and the faster learning helpers.

The compiled kernel runs the numpy kernels' arithmetic in the same order with the same
iteration schedule, so the two must agree bit for bit on chunks of two or more fixes (with a
single fix numpy's ``einsum`` sums over the beacons in another order: agreement to rounding).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from ips_synthetic import exact_distances, measure, trajectory_inside, trajectory_near_edges

from omnical.errors import ConfigError
from omnical.ips import BeaconMap, default_beacon_map, solve_fixes
from omnical.ips.solve._fit import SolverOptions, fit, use_compiled
from omnical.ips.solve._kernels import RangeProblem
from omnical.ips.solve.linkcov import _solve
from omnical.ips.solve.locate import solve_self_calibrated
from omnical.ips.solve.selfcal import _column_medians, _column_spreads

pytest.importorskip("numba")

NUMPY = SolverOptions(engine="numpy")
COMPILED = SolverOptions(engine="compiled")


def _problem(
    rng: np.random.Generator, n: int, m: int, dims: int, *, weighted: bool, per_fix_offset: bool
) -> tuple[RangeProblem, np.ndarray]:
    """A random range problem with missing, NaN, far-off and degenerate fixes mixed in."""
    beacons = rng.uniform(-5.0, 5.0, (m, 3))
    beacons[:, 2] = rng.uniform(1.5, 3.0, m) if dims == 2 else rng.uniform(0.0, 3.0, m)
    truth = rng.uniform(-4.0, 4.0, (n, 3))
    truth[:, 2] = 0.3
    distance = np.sqrt(((truth[None, :, :] - beacons[:, None, :]) ** 2).sum(axis=2))
    distance += rng.normal(0.0, 0.02, distance.shape)
    distance += np.where(rng.random(distance.shape) < 0.1, rng.uniform(0.1, 3.0), 0.0)
    used = rng.random(distance.shape) > 0.15
    distance[~used & (rng.random(distance.shape) < 0.5)] = np.nan
    used &= np.isfinite(distance)
    distance = np.where(used, distance, 0.0)
    collinear = rng.random(n) < 0.05  # fixes whose used beacons are two: singular
    used[:, collinear] = False
    used[:2, collinear] = True
    if dims == 2:
        # one height for the chunk: offsets (m, 1); else one per fix: (m, n)
        heights = rng.uniform(0.0, 0.6, (1, n)) if per_fix_offset else np.full((1, 1), 0.3)
        dz = heights - beacons[:, 2:3]
        axes = (beacons[:, 0:1], beacons[:, 1:2])
    else:
        dz = np.zeros((m, 1))
        axes = (beacons[:, 0:1], beacons[:, 1:2], beacons[:, 2:3])
    precision = rng.uniform(0.5, 2.0, (m, 1)) if weighted else None
    return RangeProblem(axes, distance, dz * dz, precision), used


def _assert_same_fit(a: object, b: object, exact: bool) -> None:
    for field in ("point", "normal"):
        for x, y in zip(getattr(a, field), getattr(b, field), strict=True):
            if exact:
                np.testing.assert_array_equal(x, y)
            else:
                np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(a.reason, b.reason)  # type: ignore[attr-defined]
    if exact:
        np.testing.assert_array_equal(a.cost, b.cost)  # type: ignore[attr-defined]
    else:
        np.testing.assert_allclose(a.cost, b.cost, rtol=1e-9, atol=1e-12)  # type: ignore[attr-defined]


@pytest.mark.parametrize("dims", [2, 3])
@pytest.mark.parametrize("weighted", [False, True])
@pytest.mark.parametrize("per_fix_offset", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_compiled_fit_is_the_numpy_fit_bit_for_bit(
    dims: int, weighted: bool, per_fix_offset: bool, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    m = int(rng.integers(dims + 1, 9))
    problem, used = _problem(rng, 300, m, dims, weighted=weighted, per_fix_offset=per_fix_offset)
    for options in (
        dataclasses.replace(NUMPY, max_iterations=20),
        dataclasses.replace(NUMPY, iterations=2, max_iterations=2),  # leave-one-out scoring
        dataclasses.replace(NUMPY, iterations=1, max_iterations=3),
    ):
        reference = fit(problem, used, options)
        compiled = fit(problem, used, dataclasses.replace(options, engine="compiled"))
        _assert_same_fit(reference, compiled, exact=True)
        start = tuple(p + 0.3 for p in reference.point)
        reference = fit(problem, used, options, start=start)
        compiled = fit(problem, used, dataclasses.replace(options, engine="compiled"), start=start)
        _assert_same_fit(reference, compiled, exact=True)


def test_tiny_chunks_with_one_slow_fix_are_bit_for_bit() -> None:
    # one slow fix of several: its safeguarded steps run through numpy, as in the reference
    options = dataclasses.replace(NUMPY, max_iterations=20)
    for seed in range(60):
        rng = np.random.default_rng(100 + seed)
        problem, used = _problem(rng, 2 + seed % 3, 4, 2, weighted=False, per_fix_offset=False)
        reference = fit(problem, used, options)
        compiled = fit(problem, used, dataclasses.replace(options, engine="compiled"))
        _assert_same_fit(reference, compiled, exact=True)


def test_compiled_fit_of_a_single_fix_agrees_to_rounding() -> None:
    rng = np.random.default_rng(7)
    problem, used = _problem(rng, 40, 5, 2, weighted=False, per_fix_offset=False)
    for j in range(40):
        sub, sub_used = problem.take(np.array([j])), used[:, [j]]
        _assert_same_fit(fit(sub, sub_used, NUMPY), fit(sub, sub_used, COMPILED), exact=False)


@pytest.mark.parametrize("method", ["lsq", "robust"])
def test_solve_fixes_gives_the_same_fixes_with_either_engine(method: str) -> None:
    rng = np.random.default_rng(3)
    beacons = default_beacon_map()
    truth = np.vstack([trajectory_inside(rng, 400), trajectory_near_edges(rng, 200)])
    ranges = measure(rng, beacons, truth, sigma_m=0.02, outlier_rate=0.1).distances_m
    ranges[::17, 1] = np.nan  # missing
    ranges[::23, :2] = np.nan  # too few beacons
    ranges[::29, 3] = -1.0  # invalid
    ranges[5] = np.inf
    fixes = [
        solve_fixes(ranges, beacons, method=method, hedge_z_m=0.4, options=options)
        for options in (NUMPY, COMPILED)
    ]
    for name in ("positions_map_m", "covariance_xy_m2", "residual_rms_m", "range_sigma_m"):
        np.testing.assert_array_equal(getattr(fixes[0], name), getattr(fixes[1], name))
    np.testing.assert_array_equal(fixes[0].status, fixes[1].status)
    np.testing.assert_array_equal(fixes[0].reason, fixes[1].reason)
    np.testing.assert_array_equal(fixes[0].used, fixes[1].used)


def test_self_calibrated_solve_is_the_same_with_either_engine() -> None:
    rng = np.random.default_rng(11)
    beacons = default_beacon_map()
    truth = trajectory_inside(rng, 1500)
    ranges = measure(rng, beacons, truth, sigma_m=0.02, outlier_rate=0.05).distances_m
    ranges[:, 2] += 0.05  # a bias for the self-calibration to find
    fixes = [
        solve_self_calibrated(ranges, beacons, hedge_z_m=0.4, options=options)
        for options in (NUMPY, COMPILED)
    ]
    np.testing.assert_array_equal(fixes[0].positions_map_m, fixes[1].positions_map_m)
    np.testing.assert_array_equal(fixes[0].covariance_xy_m2, fixes[1].covariance_xy_m2)
    np.testing.assert_array_equal(fixes[0].status, fixes[1].status)
    np.testing.assert_array_equal(fixes[0].noise[0].sigma_m, fixes[1].noise[0].sigma_m)
    np.testing.assert_array_equal(fixes[0].noise[0].bias_m, fixes[1].noise[0].bias_m)


def test_collinear_map_is_degenerate_with_the_compiled_engine() -> None:
    beacons = BeaconMap(
        np.arange(1, 5, dtype=np.int64),
        np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 2.0], [2.0, 0.0, 2.0], [3.0, 0.0, 2.0]]),
    )
    points = np.array([[1.0, 1.0, 0.4], [2.5, -1.0, 0.4]])
    fixes = solve_fixes(exact_distances(beacons, points), beacons, hedge_z_m=0.4, options=COMPILED)
    assert np.all(np.isnan(fixes.positions_map_m))
    assert np.all(fixes.status == 3)


def test_engine_choice() -> None:
    assert not use_compiled("numpy")
    assert use_compiled("compiled")
    assert use_compiled("auto")  # numba is imported by now (this module imported it)
    with pytest.raises(ConfigError, match="engine"):
        SolverOptions(engine="fortran")  # type: ignore[arg-type]


def test_column_medians_and_spreads_match_numpy() -> None:
    rng = np.random.default_rng(5)
    for trial in range(200):
        values = rng.normal(size=(int(rng.integers(1, 50)), 4))
        if trial % 3 == 0:
            values = np.round(values, 1)  # ties
        mask = rng.random(values.shape) < 0.7
        medians, spreads = _column_medians(values, mask), _column_spreads(values, mask)
        for k in range(4):
            column = values[mask[:, k], k]
            if column.size == 0:
                assert np.isnan(medians[k]) and spreads[k] == 0.0
                continue
            assert medians[k] == np.median(column)
            assert spreads[k] == np.subtract(*np.percentile(column, [90, 10]))


def test_stacked_link_covariance_solve_is_each_solve() -> None:
    rng = np.random.default_rng(2)
    m = 4
    upper = np.triu_indices(m)
    p = upper[0].size
    a = rng.normal(size=(5, 2 * p, p))
    normals = np.einsum("kip,kiq->kpq", a, a)
    rhs = rng.normal(size=(5, p))
    stacked = _solve(normals, rhs, upper)
    for k in range(5):
        np.testing.assert_array_equal(stacked[k], _solve(normals[k], rhs[k], upper))
