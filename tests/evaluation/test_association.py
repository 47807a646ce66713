"""Time association: linear interpolation of the reference at the estimate's times."""

from __future__ import annotations

import math

import numpy as np
import pytest

from omnical.errors import GeometryError
from omnical.evaluation.association import Trajectory, associate


def _linear_reference() -> Trajectory:
    # x = 2 t + 1, y = −0.5 t, on an irregular grid: interpolation must be exact anywhere
    t = np.array([0.0, 0.3, 1.0, 1.1, 2.5, 4.0])
    return Trajectory(t, np.column_stack([2 * t + 1, -0.5 * t]), 0.1 * t, "map")


def test_interpolation_is_exact_for_linear_motion() -> None:
    ref = _linear_reference()
    t = np.array([0.05, 0.3, 0.77, 1.05, 3.9, 4.0])
    est = Trajectory(t, np.zeros((t.size, 2)), np.zeros(t.size))
    a = associate(est, ref)
    np.testing.assert_array_equal(a.index, np.arange(t.size))
    np.testing.assert_allclose(a.reference_xy_m, np.column_stack([2 * t + 1, -0.5 * t]), atol=1e-15)
    assert a.reference_yaw_rad is not None
    np.testing.assert_allclose(a.reference_yaw_rad, 0.1 * t, atol=1e-15)


def test_not_nearest_neighbour() -> None:
    ref = Trajectory(np.array([0.0, 1.0]), np.array([[0.0, 0.0], [1.0, 0.0]]))
    est = Trajectory(np.array([0.4]), np.zeros((1, 2)))
    # nearest neighbour would give x = 0
    assert associate(est, ref).reference_xy_m[0, 0] == pytest.approx(0.4, abs=1e-15)


def test_samples_outside_the_reference_are_dropped() -> None:
    ref = _linear_reference()
    t = np.array([-0.01, 0.0, 2.0, 4.0, 4.01])
    a = associate(Trajectory(t, np.zeros((5, 2))), ref)
    np.testing.assert_array_equal(a.index, [1, 2, 3])
    np.testing.assert_array_equal(a.t_s, [0.0, 2.0, 4.0])
    np.testing.assert_array_equal(a.estimate_xy_m, np.zeros((3, 2)))


def test_long_reference_gaps_are_not_interpolated() -> None:
    # reference steps: 0.3, 0.7, 0.1, 1.4 (1.1 → 2.5 s) and 1.5 s (2.5 → 4.0 s)
    ref = _linear_reference()
    t = np.array([0.5, 1.1, 1.5, 2.4, 2.5, 3.0, 4.0])
    est = Trajectory(t, np.zeros((t.size, 2)))
    assert len(associate(est, ref)) == 7
    assert len(associate(est, ref, max_gap_s=1.5)) == 7
    # 1.5, 2.4 and 3.0 fall inside gaps over 1 s; 1.1, 2.5 and 4.0 sit on reference samples
    a = associate(est, ref, max_gap_s=1.0)
    np.testing.assert_array_equal(a.t_s, [0.5, 1.1, 2.5, 4.0])
    a = associate(est, ref, max_gap_s=0.5)
    np.testing.assert_array_equal(a.t_s, [1.1, 2.5, 4.0])


def test_yaw_is_interpolated_through_the_wrap() -> None:
    ref = Trajectory(
        np.array([0.0, 1.0]), np.zeros((2, 2)), np.array([math.pi - 0.1, -math.pi + 0.1])
    )
    est = Trajectory(np.array([0.5]), np.zeros((1, 2)), np.array([0.0]))
    a = associate(est, ref)
    assert a.reference_yaw_rad is not None
    # through ±π, not back through 0
    assert a.reference_yaw_rad[0] == pytest.approx(math.pi, abs=1e-12)


def test_headings_only_when_both_have_them() -> None:
    ref = _linear_reference()
    est = Trajectory(np.array([1.0]), np.zeros((1, 2)))
    a = associate(est, ref)
    assert a.estimate_yaw_rad is None and a.reference_yaw_rad is None


@pytest.mark.parametrize(
    ("t_ref", "t_est", "gap"),
    [
        ([0.0, 1.0, 1.0, 2.0], [0.5], None),  # repeated reference time
        ([0.0, 1.0], [2.0, 3.0], None),  # no overlap
        ([0.0, 1.0], [0.5], 0.0),  # bad gap
    ],
)
def test_association_refuses(t_ref: list[float], t_est: list[float], gap: float | None) -> None:
    ref = Trajectory(np.array(t_ref), np.zeros((len(t_ref), 2)))
    est = Trajectory(np.array(t_est), np.zeros((len(t_est), 2)))
    with pytest.raises(GeometryError):
        associate(est, ref, max_gap_s=gap)


def test_trajectory_validates_its_arrays() -> None:
    with pytest.raises(GeometryError, match="positions"):
        Trajectory(np.zeros(3), np.zeros((3, 3)))
    with pytest.raises(GeometryError, match="non-decreasing"):
        Trajectory(np.array([1.0, 0.0]), np.zeros((2, 2)))
    with pytest.raises(GeometryError, match="finite"):
        Trajectory(np.array([0.0, 1.0]), np.array([[0.0, np.nan], [0.0, 0.0]]))
    with pytest.raises(GeometryError, match="covariances"):
        Trajectory(np.zeros(2), np.zeros((2, 2)), covariance_xy_m2=np.zeros((2, 2)))
    tr = Trajectory(np.zeros(2), np.zeros((2, 2)))
    assert not tr.xy_m.flags.writeable
