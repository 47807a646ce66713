"""Honest confidence: 95 % ellipses of OK fixes cover the truth; robust beats plain LSQ on NLOS.

Synthetic data on the default 4-beacon map (seed 000, Table 3): Gaussian range noise σ and
NLOS outliers, each range independently biased by +0.1…1 m with probability 5 % or 10 %
(so 19 % or 34 % of the fixes hold at least one outlier).
"""

from __future__ import annotations

import numpy as np
import pytest
from ips_synthetic import measure, trajectory_inside, trajectory_near_edges

from omnical.ips.beacons import default_beacon_map
from omnical.ips.solve.fixes import CHI2_2DOF_95, FixReason, FixStatus
from omnical.ips.solve.locate import solve_fixes

N_FIXES = 4000
SEEDS = [1, 2, 3]


def _trajectory(where: str, seed: int) -> np.ndarray:
    rng = np.random.default_rng(1000 + seed)
    if where == "inside":
        return trajectory_inside(rng, N_FIXES)
    return trajectory_near_edges(rng, N_FIXES)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("outlier_rate", [0.0, 0.05, 0.10])
@pytest.mark.parametrize("where", ["inside", "edges"])
@pytest.mark.parametrize("sigma_m", [0.02, 0.05])
def test_ok_ellipses_cover_the_truth(
    seed: int, outlier_rate: float, where: str, sigma_m: float
) -> None:
    rng = np.random.default_rng(seed)
    beacons = default_beacon_map()
    data = measure(
        rng, beacons, _trajectory(where, seed), sigma_m=sigma_m, outlier_rate=outlier_rate
    )
    fixes = solve_fixes(data.distances_m, beacons, method="robust", range_sigma_m=sigma_m)
    ok = fixes.status == FixStatus.OK
    assert ok.mean() > 0.5
    coverage = fixes.contains(data.truth_m[:, :2], scale=CHI2_2DOF_95)[ok].mean()
    assert 0.90 <= coverage <= 0.98, coverage


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("outlier_rate", [0.05, 0.10])
@pytest.mark.parametrize("where", ["inside", "edges"])
def test_robust_halves_the_95th_percentile_error(
    seed: int, outlier_rate: float, where: str
) -> None:
    rng = np.random.default_rng(seed)
    beacons = default_beacon_map()
    data = measure(rng, beacons, _trajectory(where, seed), sigma_m=0.02, outlier_rate=outlier_rate)
    errors = {}
    for method in ("lsq", "robust"):
        fixes = solve_fixes(data.distances_m, beacons, method=method)
        assert not np.any(fixes.status == FixStatus.DEGENERATE)
        # Every fix counts, rejected ones with their best-effort position.
        errors[method] = np.linalg.norm(fixes.positions_map_m - data.truth_m, axis=1)
    p95_lsq, p95_robust = (np.percentile(errors[m], 95) for m in ("lsq", "robust"))
    assert p95_robust <= 0.5 * p95_lsq, (p95_robust, p95_lsq)


def test_robust_flags_most_outlier_fixes() -> None:
    rng = np.random.default_rng(4)
    beacons = default_beacon_map()
    data = measure(rng, beacons, trajectory_inside(rng, N_FIXES), sigma_m=0.02, outlier_rate=0.05)
    fixes = solve_fixes(data.distances_m, beacons, method="robust")
    large = np.any(data.outlier, axis=1) & (
        np.max(
            data.distances_m
            - np.linalg.norm(data.truth_m[:, None, :] - beacons.positions_m[None], axis=2),
            axis=1,
        )
        > 0.3
    )
    # Issue 11: a fix whose NLOS range was clearly identified and left out stays ok (its three
    # other ranges agree); what is flagged is that an outlier was left out, or the fix.
    flagged = fixes.has_reason(FixReason.OUTLIER_REJECTED) | (fixes.status != FixStatus.OK)
    assert np.mean(flagged[large]) > 0.95
    ok_large = large & (fixes.status == FixStatus.OK)
    error = np.linalg.norm(fixes.positions_map_m - data.truth_m, axis=1)
    assert np.percentile(error[ok_large], 95) < 0.06
    single = np.sum(data.outlier, axis=1) == 1
    dropped_right = ~fixes.used[data.outlier & single[:, None]]
    assert dropped_right.mean() > 0.85
