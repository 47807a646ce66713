"""Alignment: none, origin and least-squares SE(2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from omnical.errors import ChoiceError, GeometryError
from omnical.evaluation.alignment import (
    Transform2D,
    align_positions,
    fit_se2,
    origin_transform,
)


def _rot(theta: float) -> np.ndarray:
    return np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])


@pytest.mark.parametrize("theta", [0.0, 0.7, -2.0, 3.1, -3.1])
def test_se2_recovers_a_known_transform(theta: float) -> None:
    rng = np.random.default_rng(11)
    src = rng.uniform(-3, 3, size=(40, 2))
    t = np.array([1.5, -2.0])
    dst = src @ _rot(theta).T + t
    tf = fit_se2(src, dst)
    assert tf.rotation_rad == pytest.approx(theta, abs=1e-12)
    np.testing.assert_allclose(tf.translation_m, t, atol=1e-12)
    np.testing.assert_allclose(tf.apply(src), dst, atol=1e-12)
    aligned = align_positions(src, dst, "se2")
    np.testing.assert_allclose(aligned.xy_m, dst, atol=1e-12)


def test_se2_is_the_least_squares_optimum_with_noise() -> None:
    rng = np.random.default_rng(5)
    src = rng.uniform(-2, 2, size=(200, 2))
    dst = src @ _rot(0.4).T + [0.3, 0.1] + rng.normal(scale=0.05, size=src.shape)
    tf = fit_se2(src, dst)

    def cost(theta: float, t: np.ndarray) -> float:
        return float(np.sum((src @ _rot(theta).T + t - dst) ** 2))

    best = cost(tf.rotation_rad, np.array(tf.translation_m))
    for d_theta, d_t in [(1e-3, (0, 0)), (-1e-3, (0, 0)), (0, (1e-3, 0)), (0, (0, -1e-3))]:
        assert cost(tf.rotation_rad + d_theta, np.array(tf.translation_m) + d_t) > best
    assert tf.rotation_rad == pytest.approx(0.4, abs=0.01)


def test_se2_never_reflects() -> None:
    src = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    mirrored = src * [1.0, -1.0]
    r = Transform2D(fit_se2(src, mirrored).rotation_rad).rotation_matrix
    assert np.linalg.det(r) == pytest.approx(1.0)


def test_origin_alignment_puts_the_first_pose_on_the_reference() -> None:
    est = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    yaw_est = np.array([0.0, 0.0, 0.5])
    ref = np.array([[2.0, 3.0], [2.0, 4.0], [9.0, 9.0]])
    yaw_ref = np.array([math.pi / 2, 1.0, 1.0])
    out = align_positions(est, ref, "origin", estimate_yaw_rad=yaw_est, reference_yaw_rad=yaw_ref)
    # rotated by +90°: forward (1, 0) becomes (0, 1)
    np.testing.assert_allclose(out.xy_m, [[2.0, 3.0], [2.0, 4.0], [1.0, 4.0]], atol=1e-12)
    assert out.yaw_rad is not None
    np.testing.assert_allclose(out.yaw_rad, yaw_est + math.pi / 2)
    # without headings: a pure translation
    plain = align_positions(est, ref, "origin")
    np.testing.assert_allclose(plain.xy_m, est + np.array([2.0, 3.0]))
    assert plain.transform.rotation_rad == 0.0


def test_origin_transform_wraps_the_heading_difference() -> None:
    tf = origin_transform([0.0, 0.0], [0.0, 0.0], 3.0, -3.0)
    assert tf.rotation_rad == pytest.approx(2 * math.pi - 6.0)


def test_none_keeps_positions() -> None:
    xy = np.array([[1.0, 2.0], [3.0, 4.0]])
    out = align_positions(xy, xy + 1.0, "none")
    np.testing.assert_array_equal(out.xy_m, xy)


def test_transform_turns_then_translates() -> None:
    tf = Transform2D(np.pi / 2, (1.0, -2.0))
    np.testing.assert_allclose(tf.apply([[1.0, 0.0], [0.0, 2.0]]), [[1.0, -1.0], [-1.0, -2.0]])
    np.testing.assert_allclose(tf.rotation_matrix @ [1.0, 0.0], [0.0, 1.0], atol=1e-16)
    assert tf.pose == (1.0, -2.0, np.pi / 2)


def test_refusals() -> None:
    still = np.ones((5, 2))
    with pytest.raises(GeometryError, match="rotation is undetermined"):
        fit_se2(still, still)
    with pytest.raises(
        ChoiceError, match="alignment: unknown value 'best'; choose none, origin or se2"
    ):
        align_positions(still, still, "best")  # type: ignore[arg-type]
    with pytest.raises(GeometryError):
        align_positions(np.zeros((3, 2)), np.zeros((2, 2)), "none")
    with pytest.raises(GeometryError, match="headings"):
        align_positions(still, still, "origin", estimate_yaw_rad=np.zeros(2))
