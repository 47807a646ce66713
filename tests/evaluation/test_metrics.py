"""Seed 000 Table 4 measures on arrays, by hand."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from omnical.errors import GeometryError
from omnical.evaluation.alignment import align_positions
from omnical.evaluation.association import Trajectory
from omnical.evaluation.metrics import (
    METRIC_KEYS,
    TrackingMetrics,
    metrics_json,
    shift_to_hedgehog,
    track,
    tracking_metrics,
)


def test_measures_by_hand() -> None:
    est = np.array([[1.0, 0.0], [0.0, 2.0], [3.0, 4.0]])
    ref = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    m = tracking_metrics(est, ref)
    # errors (1, 0), (0, 2), (3, 4): distances 1, 2, 5
    assert m.rmse_m == pytest.approx(math.sqrt((1 + 4 + 25) / 3))
    assert m.rmse_x_m == pytest.approx(math.sqrt((1 + 0 + 9) / 3))
    assert m.rmse_y_m == pytest.approx(math.sqrt((0 + 4 + 16) / 3))
    assert m.max_m == 5.0
    assert m.final_m == 5.0
    assert m.n == 3
    assert m.rmse_m**2 == pytest.approx(m.rmse_x_m**2 + m.rmse_y_m**2)
    assert m.rmse_per_axis_m == pytest.approx(math.sqrt(30 / 6))


def test_rmse_by_hand_after_origin_alignment() -> None:
    ref = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    est = np.array([[5.0, 5.0], [6.0, 5.3], [7.0, 4.6]])
    aligned = align_positions(est, ref, "origin").xy_m  # no headings: shift by (−5, −5)
    m = tracking_metrics(aligned, ref)
    # errors 0, 0.3, 0.4
    assert m.rmse_m == pytest.approx(math.sqrt((0.09 + 0.16) / 3), abs=1e-12)
    assert m.rmse_x_m == pytest.approx(0.0, abs=1e-12)
    assert m.max_m == pytest.approx(0.4) and m.final_m == pytest.approx(0.4)


def test_rmse_by_hand_after_se2_alignment() -> None:
    # estimate (−1, 0.75), (1, −0.75) against (−1, 0), (1, 0): the best rotation is
    # atan(0.75); it lays the estimate on the x axis at ±1.25, 0.25 m from each reference point
    ref = np.array([[-1.0, 0.0], [1.0, 0.0]])
    est = np.array([[-1.0, 0.75], [1.0, -0.75]])
    alignment = align_positions(est, ref, "se2")
    assert alignment.transform.rotation_rad == pytest.approx(math.atan(0.75), abs=1e-15)
    np.testing.assert_allclose(alignment.xy_m, [[-1.25, 0.0], [1.25, 0.0]], atol=1e-15)
    m = tracking_metrics(alignment.xy_m, ref)
    assert (m.rmse_m, m.rmse_x_m, m.rmse_y_m, m.max_m) == pytest.approx((0.25, 0.25, 0.0, 0.25))


def test_table4_position_convention_matches_the_paper() -> None:
    # all four columns of seed 000 Table 4: position = sqrt((x² + y²) / 2)
    for pos, x, y in [
        (0.0083, 0.0089, 0.0076),
        (0.1119, 0.1518, 0.0445),
        (0.0085, 0.0086, 0.0083),
        (0.0171, 0.0168, 0.0173),
    ]:
        m = TrackingMetrics(math.hypot(x, y), x, y, 0.0, 0.0, 1)
        assert m.rmse_per_axis_m == pytest.approx(pos, abs=5e-5)
        assert m.rmse_m == pytest.approx(pos * math.sqrt(2), abs=1e-4)


def test_as_dict_and_json_keys() -> None:
    m = tracking_metrics(np.array([[0.1, 0.2]]), np.zeros((1, 2)))
    assert list(m.as_dict()) == ["rmse_m", "rmse_x_m", "rmse_y_m", "max_m", "final_m"]
    assert tuple(m.as_dict()) == METRIC_KEYS
    text = metrics_json({"odometry": m, "ips": m, "multilateration": m})
    data = json.loads(text)
    assert list(data) == ["odometry", "ips", "multilateration"]
    d = math.hypot(0.1, 0.2)
    expected = {"rmse_m": d, "rmse_x_m": 0.1, "rmse_y_m": 0.2, "max_m": d, "final_m": d}
    assert data["ips"] == pytest.approx(expected)


def test_track_measures_after_interpolation_and_alignment() -> None:
    t = np.linspace(0.0, 10.0, 11)
    ref = Trajectory(t, np.column_stack([t, np.zeros_like(t)]), np.zeros_like(t))
    # odometry frame: started at the origin, turned by 90°; sampled between reference samples
    te = np.linspace(0.25, 9.75, 39)
    est = Trajectory(
        te, np.column_stack([np.zeros_like(te), te - 0.25]), np.full(te.size, math.pi / 2)
    )
    out = track(est, ref, align_mode="origin")
    assert out.metrics.n == 39
    assert out.metrics.rmse_m == pytest.approx(0.0, abs=1e-12)
    assert out.alignment.transform.rotation_rad == pytest.approx(-math.pi / 2)
    np.testing.assert_allclose(out.errors_m, 0.0, atol=1e-12)


def test_shift_to_hedgehog_turns_with_yaw() -> None:
    ref = Trajectory(np.array([0.0, 1.0]), np.zeros((2, 2)), np.array([0.0, math.pi / 2]))
    moved = shift_to_hedgehog(ref, (0.04, -0.03, 0.4))
    np.testing.assert_allclose(moved.xy_m, [[0.04, -0.03], [0.03, 0.04]], atol=1e-15)
    with pytest.raises(GeometryError, match="headings"):
        shift_to_hedgehog(Trajectory(np.zeros(1), np.zeros((1, 2))), (0.1, 0.0))


def test_refusals() -> None:
    with pytest.raises(GeometryError, match="at least one pair"):
        tracking_metrics(np.zeros((0, 2)), np.zeros((0, 2)))
    with pytest.raises(GeometryError, match=r"two \(N, 2\) arrays, got \(2, 2\) and \(3, 2\)"):
        tracking_metrics(np.zeros((2, 2)), np.zeros((3, 2)))
    with pytest.raises(GeometryError, match="finite"):
        tracking_metrics(np.array([[np.nan, 0.0]]), np.zeros((1, 2)))
