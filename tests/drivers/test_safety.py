"""The path check before a real robot moves: where a path leaves the coverage, and from where
it would fit (issue 29: refusals named no position and suggested no start)."""

from __future__ import annotations

import numpy as np
import pytest

from omnical.calibration.procedures.scripts import hull_margin_m, hull_margins_m, nominal_path
from omnical.drivers.safety import Area, check_path, check_points, fitting_start
from omnical.experiment.script import parse_script
from omnical.ips.beacons import BeaconMap, default_beacon_map
from omnical.robot.loader import load_robot

LIMITS = load_robot("rosy-mecanum").limits
BEACONS = default_beacon_map()
FORWARD_2M = parse_script(
    {"name": "forward", "steps": [{"move": {"vx_mps": 0.2, "distance_m": 2.0}}]}, LIMITS
)


def _square(side_m: float) -> BeaconMap:
    xy = np.array([[0, 0], [side_m, 0], [side_m, side_m], [0, side_m]], dtype=np.float64)
    return BeaconMap(np.arange(1, 5), np.column_stack([xy, np.full(4, 2.0)]))


def test_a_refusal_names_where_the_path_leaves_and_a_start_that_fits() -> None:
    square = _square(4.0)
    verdict = check_path(FORWARD_2M, (3.0, 2.0, 0.0), square, margin_m=0.3)
    assert not verdict.ok
    assert verdict.coverage_margin_m == pytest.approx(-1.0, abs=0.02)
    assert "from the edge of the beacon coverage at (5.00, 2.00) m" in verdict.reason
    assert "it would fit from a start at (1.70, 2.00) m, 1.30 m from here" in verdict.reason
    fits = check_path(FORWARD_2M, (1.7, 2.0, 0.0), square, margin_m=0.3)
    assert fits.ok and fits.coverage_margin_m == pytest.approx(0.3, abs=0.02)


def test_a_nan_margin_refuses() -> None:
    # a NaN compared with `<` is never smaller: it passed every path (a user's --margin nan)
    square = _square(4.0)
    nan = float("nan")
    assert check_path(FORWARD_2M, (1.0, 2.0, 0.0), square, margin_m=0.3).ok
    assert not check_path(FORWARD_2M, (1.0, 2.0, 0.0), square, margin_m=nan).ok
    area = Area(0.0, 0.0, 4.0, 4.0)
    inside = np.array([[1.0, 2.0], [2.0, 2.0]])
    assert check_points(inside, square, margin_m=0.3, allowed=area).ok
    assert "allowed area" in check_points(inside, _square(40.0), margin_m=nan, allowed=area).reason


def test_the_allowed_area_and_no_start_at_all() -> None:
    square = _square(4.0)
    area = Area(0.0, 0.0, 2.5, 4.0)
    verdict = check_path(FORWARD_2M, (1.0, 2.0, 0.0), square, margin_m=0.3, allowed=area)
    assert "the allowed area at (3.00, 2.00) m" in verdict.reason
    assert "a start at (0.30, 2.00) m" not in verdict.reason  # 0.3 + 2 = 2.3 > 2.2
    assert "it fits from no start" in verdict.reason
    long_run = parse_script(
        {"name": "long", "steps": [{"move": {"vx_mps": 0.3, "distance_m": 5.0}}]}, LIMITS
    )
    assert "it fits from no start" in check_path(long_run, (1.0, 2.0, 0.0), square).reason


def test_fitting_start_agrees_with_checking_from_it() -> None:
    """The edge-by-edge shift rule against a direct check, on seed 000's beacons."""
    rng = np.random.default_rng(3)
    for _ in range(5):
        start = rng.uniform([0.5, 0.5], [3.0, 2.5])
        path = nominal_path(FORWARD_2M, (*start, float(rng.uniform(-3, 3))), step_s=0.02)[:, :2]
        found = fitting_start(path, (start[0], start[1]), BEACONS, margin_m=0.3)
        assert found is not None
        moved = path - start + np.asarray(found)
        assert hull_margin_m(moved, BEACONS) >= 0.3 - 1e-9
        assert hull_margins_m(moved, BEACONS).shape == (len(path),)
    assert check_points(path, BEACONS, margin_m=-100.0).ok
