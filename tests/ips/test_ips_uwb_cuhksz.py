"""Real data: UWB ranges of 3 tags to 8 anchors against motion capture (CUHK-SZ, MIT licence).

Provenance and columns: ``tests/data/uwb_planar_cuhksz/README.md``. Ranges with the authors'
per-link calibration ``(r − bias)/(1 + slope)`` (or raw), solved in 2D, against the tag position
from the motion-capture pose (with the authors' +7° yaw correction).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from omnical.ips.beacons import BeaconMap
from omnical.ips.solve.locate import solve_fixes

DATA = Path(__file__).resolve().parents[1] / "data" / "uwb_planar_cuhksz"
TAG_HEIGHT_M = 0.965
YAW_CORRECTION_DEG = 7.0


def _csv(name: str) -> NDArray[np.float64]:
    table: NDArray[np.float64] = np.loadtxt(DATA / name, delimiter=",", skiprows=1)
    return table


def _columns() -> list[str]:
    return (DATA / "dynamic_fast_every5.csv").read_text(encoding="utf-8").splitlines()[0].split(",")


def _anchors() -> BeaconMap:
    anchors = _csv("anchors.csv")
    return BeaconMap(anchors[:, 0].astype(np.int64), anchors[:, 1:4])


def _tag(tag: int, *, calibrated: bool) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return the ranges (rows, 8) of one tag and its true positions (rows, 2)."""
    rows = _csv("dynamic_fast_every5.csv")
    names = _columns()
    ranges = rows[:, [names.index(f"r_t{tag}_a{j}_m") for j in range(8)]]
    if calibrated:
        calibration = _csv("range_calibration.csv")
        link = calibration[calibration[:, 0] == tag]
        assert link[:, 1].tolist() == list(range(8))
        ranges = (ranges - link[:, 2]) / (1.0 + link[:, 3])
    body = _csv("tags_body_frame.csv")[tag, 1:3]
    yaw = np.deg2rad(rows[:, names.index("gt_yaw_deg")] + YAW_CORRECTION_DEG)
    x = rows[:, names.index("gt_x_m")] + np.cos(yaw) * body[0] - np.sin(yaw) * body[1]
    y = rows[:, names.index("gt_y_m")] + np.sin(yaw) * body[0] + np.cos(yaw) * body[1]
    return ranges, np.column_stack([x, y])


def _rmse(positions: NDArray[np.float64], truth: NDArray[np.float64]) -> float:
    return float(np.sqrt(np.mean(np.sum((positions[:, :2] - truth) ** 2, axis=1))))


@pytest.mark.parametrize("tag", [0, 1, 2])
@pytest.mark.parametrize(("method", "sigma_m"), [("lsq", 0.03), ("robust", 0.05)])
def test_calibrated_per_tag_rmse(tag: int, method: str, sigma_m: float) -> None:
    ranges, truth = _tag(tag, calibrated=True)
    fixes = solve_fixes(
        ranges,
        _anchors(),
        method=method,  # type: ignore[arg-type]
        hedge_z_m=TAG_HEIGHT_M,
        range_sigma_m=sigma_m,
    )
    assert np.all(np.isfinite(fixes.positions_map_m))
    assert _rmse(fixes.positions_map_m, truth) <= 0.06


@pytest.mark.parametrize("tag", [0, 1, 2])
def test_grid_on_real_data(tag: int) -> None:
    ranges, truth = _tag(tag, calibrated=True)
    every = slice(None, None, 6)
    grid = solve_fixes(ranges[every], _anchors(), method="grid", hedge_z_m=TAG_HEIGHT_M)
    lsq = solve_fixes(ranges[every], _anchors(), method="lsq", hedge_z_m=TAG_HEIGHT_M)
    assert _rmse(grid.positions_map_m, truth[every]) <= 0.065
    offset = np.linalg.norm(grid.positions_map_m - lsq.positions_map_m, axis=1)
    assert np.max(offset) < 2e-3


def test_calibration_is_what_makes_it_accurate() -> None:
    raw_errors: list[float] = []
    calibrated_errors: list[float] = []
    for tag in range(3):
        for calibrated, store in ((False, raw_errors), (True, calibrated_errors)):
            ranges, truth = _tag(tag, calibrated=calibrated)
            fixes = solve_fixes(ranges, _anchors(), method="lsq", hedge_z_m=TAG_HEIGHT_M)
            store.append(_rmse(fixes.positions_map_m, truth))
    # The dataset README measured 0.157 m raw and 0.049 m calibrated (all tags, all rows).
    assert 0.10 < np.sqrt(np.mean(np.square(raw_errors))) < 0.25
    assert np.sqrt(np.mean(np.square(calibrated_errors))) < 0.055


@pytest.mark.parametrize("calibrated", [False, True], ids=["raw", "calibrated"])
def test_ok_fix_ellipses_hold_the_truth_on_the_real_run(calibrated: bool) -> None:
    """Issue 29: the 95 % ellipses of the ok fixes of ``locate`` with no options hold the
    motion-capture truth 85–98 % of the time on the raw ranges, and still on the ranges with
    the authors' calibration (the bags of tests/ips/uwb_bags.py, tag 0, the full run).

    Raw ranges: 0.728 before (the link covariance was left out: it widened the ellipses by only
    2.6 jackknife standard errors; and nothing covered the run's own calibration being
    uncertain), 0.907 now (it predicts held-out blocks 3.5 standard errors better, which is
    enough; the bias and scale learned from the run add their jackknife covariance).
    Calibrated: 0.973 → 0.985. The fixes do not move: usable share and RMSE as before (0.0622
    raw, 0.0573 calibrated). docs/locate.md has the other tags and runs.
    """
    import uwb_bags as uwb

    from omnical.ips.from_recording import locate
    from omnical.ips.solve.fixes import CHI2_2DOF_95, FixStatus, mahalanobis_sq

    if uwb.cuhksz_dir()[1] != "dynamic_fast.csv":
        pytest.skip("the full CUHK-SZ run (../shared/datasets) is not here")
    run = uwb.cuhksz_run(0, calibrated=calibrated)
    fixes, _ = locate(run.recording)
    assert fixes.t_ns is not None
    delta = fixes.positions_map_m[:, :2] - uwb.truth_at(run, fixes.t_ns)
    ok = fixes.status == FixStatus.OK
    coverage = float(np.mean(mahalanobis_sq(fixes.covariance_xy_m2, delta)[ok] <= CHI2_2DOF_95))
    model = fixes.noise[0]
    assert model.link_covariance_m2 is not None, model.describe()
    assert model.calibration_covariance is not None, model.describe()
    if calibrated:
        assert 0.90 <= coverage <= 0.99, coverage  # measured 0.985 (0.973 before)
    else:
        assert 0.85 <= coverage <= 0.98, coverage  # measured 0.907 (0.728 before)
    usable = fixes.status <= FixStatus.DEGRADED
    assert usable.mean() >= 0.99
    rmse = float(np.sqrt(np.mean(np.sum(delta[usable] ** 2, axis=1))))
    assert rmse <= (0.0575 if calibrated else 0.0625), rmse
