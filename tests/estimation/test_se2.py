"""SE(2) on floats and arrays: group laws, round trips, and the array forms against the floats."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from omnical.errors import GeometryError
from omnical.estimation.se2 import (
    Pose2,
    between,
    between_poses,
    compose,
    compose_poses,
    invert,
    invert_poses,
    rotate,
    rotate_xy,
    transform_point,
    transform_points,
    wrap_angle,
    wrap_angles,
)

# positions within a kilometre, yaw over many turns (continuous yaw is never wrapped)
_COORD = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
_YAW = st.floats(-60.0, 60.0, allow_nan=False, allow_infinity=False)
_POSE = st.tuples(_COORD, _COORD, _YAW)
_ROWS = st.integers(1, 8)
# round trips go through a rotation and back: a few ulps of 1e3 m
_ATOL = 1e-9


def _poses(n: int) -> st.SearchStrategy[np.ndarray]:
    return st.lists(_POSE, min_size=n, max_size=n).map(lambda rows: np.array(rows, dtype=float))


_POSE_ARRAYS = _ROWS.flatmap(_poses)
_POSE_PAIRS = _ROWS.flatmap(lambda n: st.tuples(_poses(n), _poses(n)))


def _row(p: np.ndarray) -> Pose2:
    return (float(p[0]), float(p[1]), float(p[2]))


def _close(expected: tuple[float, ...]) -> object:
    """The float form's result, to the rounding of np.cos against math.cos on 1 km."""
    return pytest.approx(expected, rel=1e-12, abs=1e-11)


# --------------------------------------------------------------------------- group laws


@settings(max_examples=200, deadline=None)
@given(_POSE_PAIRS)
def test_between_undoes_compose(pair: tuple[np.ndarray, np.ndarray]) -> None:
    a, b = pair
    np.testing.assert_allclose(between_poses(a, compose_poses(a, b)), b, rtol=0, atol=_ATOL)
    np.testing.assert_allclose(compose_poses(a, between_poses(a, b)), b, rtol=0, atol=_ATOL)


@settings(max_examples=200, deadline=None)
@given(_POSE_ARRAYS)
def test_inverting_twice_is_the_identity(a: np.ndarray) -> None:
    np.testing.assert_allclose(invert_poses(invert_poses(a)), a, rtol=0, atol=_ATOL)
    identity = np.zeros_like(a)
    np.testing.assert_allclose(compose_poses(a, invert_poses(a)), identity, rtol=0, atol=_ATOL)
    np.testing.assert_allclose(compose_poses(invert_poses(a), a), identity, rtol=0, atol=_ATOL)


@settings(max_examples=200, deadline=None)
@given(_POSE_PAIRS)
def test_between_is_the_inverse_composed(pair: tuple[np.ndarray, np.ndarray]) -> None:
    a, b = pair
    np.testing.assert_allclose(
        between_poses(a, b), compose_poses(invert_poses(a), b), rtol=0, atol=_ATOL
    )


@settings(max_examples=100, deadline=None)
@given(_ROWS.flatmap(lambda n: st.tuples(_poses(n), _poses(n), _poses(n))))
def test_composition_is_associative(triple: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
    a, b, c = triple
    left = compose_poses(compose_poses(a, b), c)
    right = compose_poses(a, compose_poses(b, c))
    np.testing.assert_allclose(left, right, rtol=0, atol=1e-8)


@settings(max_examples=200, deadline=None)
@given(_POSE_PAIRS)
def test_transform_points_is_composition_with_a_point(pair: tuple[np.ndarray, np.ndarray]) -> None:
    poses, other = pair
    xy = other[:, :2]
    with_zero_yaw = np.column_stack([xy, np.zeros(len(xy))])
    np.testing.assert_allclose(
        transform_points(poses, xy), compose_poses(poses, with_zero_yaw)[:, :2], rtol=0, atol=0
    )
    back = between_poses(poses, np.column_stack([transform_points(poses, xy), poses[:, 2]]))
    np.testing.assert_allclose(back[:, :2], xy, rtol=0, atol=_ATOL)


@settings(max_examples=200, deadline=None)
@given(_YAW, _YAW, _POSE_ARRAYS)
def test_rotations_add_and_keep_lengths(alpha: float, beta: float, rows: np.ndarray) -> None:
    xy = rows[:, :2]
    turned = rotate_xy(alpha, xy)
    np.testing.assert_allclose(np.hypot(*turned.T), np.hypot(*xy.T), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(
        rotate_xy(beta, turned), rotate_xy(alpha + beta, xy), rtol=0, atol=1e-9
    )


# --------------------------------------------------------------------------- arrays = floats


@settings(max_examples=200, deadline=None)
@given(_POSE_PAIRS)
def test_array_forms_equal_the_float_forms_row_by_row(pair: tuple[np.ndarray, np.ndarray]) -> None:
    a, b = pair
    composed, inverted = compose_poses(a, b), invert_poses(a)
    relative, points = between_poses(a, b), transform_points(a, b[:, :2])
    turned = rotate_xy(a[:, 2], b[:, :2])
    for i in range(len(a)):
        ai, bi = _row(a[i]), _row(b[i])
        assert tuple(composed[i]) == _close(compose(ai, bi))
        assert tuple(inverted[i]) == _close(invert(ai))
        assert tuple(relative[i]) == _close(between(ai, bi))
        assert tuple(points[i]) == _close(transform_point(ai, bi[0], bi[1]))
        assert tuple(turned[i]) == _close(rotate(ai[2], bi[0], bi[1]))


@settings(max_examples=100, deadline=None)
@given(_POSE, _POSE_ARRAYS)
def test_one_origin_broadcasts_against_many_poses(origin: Pose2, poses: np.ndarray) -> None:
    expressed = between_poses(np.array(origin), poses)
    assert expressed.shape == poses.shape
    for i in range(len(poses)):
        assert tuple(expressed[i]) == _close(between(origin, _row(poses[i])))
    offset = poses[0, :2]
    track = transform_points(poses, offset)
    assert track.shape == (len(poses), 2)
    for i in range(len(poses)):
        expected = transform_point(_row(poses[i]), float(offset[0]), float(offset[1]))
        assert tuple(track[i]) == _close(expected)


def test_a_quarter_turn_moves_forward_to_the_left() -> None:
    # REP-103: x forward, y left, yaw counter-clockwise
    np.testing.assert_allclose(
        compose_poses([1.0, 2.0, math.pi / 2], [1.0, 0.0, 0.0]), [1.0, 3.0, math.pi / 2]
    )
    np.testing.assert_allclose(rotate_xy(math.pi / 2, [[1.0, 0.0]]), [[0.0, 1.0]], atol=1e-16)
    np.testing.assert_allclose(
        between_poses([1.0, 1.0, math.pi / 2], [[1.0, 2.0, math.pi]]),
        [[1.0, 0.0, math.pi / 2]],
        atol=1e-15,
    )


# --------------------------------------------------------------------------- wrapping


@settings(max_examples=300, deadline=None)
@given(arrays(np.float64, st.integers(1, 20), elements=st.floats(-1e6, 1e6)))
@example(np.array([math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 5 * math.pi, 0.0, -0.0]))
@example(np.array([2 * math.pi, -2 * math.pi, 7 * math.pi / 2, 1e-300, 1e300]))
def test_wrap_angles_equals_wrap_angle_exactly(angles: np.ndarray) -> None:
    wrapped = wrap_angles(angles)
    expected = np.array([wrap_angle(float(a)) for a in angles])
    np.testing.assert_array_equal(wrapped, expected)
    assert np.all(np.abs(wrapped) <= math.pi)


@settings(max_examples=200, deadline=None)
@given(st.floats(-1e4, 1e4), st.integers(-1000, 1000))
def test_wrapping_removes_whole_turns(angle: float, turns: int) -> None:
    # the same direction whatever whole turns are added (to the rounding of adding them)
    a, b = wrap_angle(angle), wrap_angle(angle + 2.0 * math.pi * turns)
    assert abs(wrap_angle(a - b)) <= 1e-9


def test_wrap_angles_keeps_shape_and_maps_infinity_to_nan() -> None:
    assert wrap_angles(3.0 * math.pi / 2).shape == ()
    assert float(wrap_angles(3.0 * math.pi / 2)) == pytest.approx(-math.pi / 2)
    assert wrap_angles(np.zeros((2, 3))).shape == (2, 3)
    out = wrap_angles([np.inf, -np.inf, np.nan, 1.0])
    assert np.isnan(out[:3]).all()
    assert out[3] == 1.0


# --------------------------------------------------------------------------- shapes


@pytest.mark.parametrize(
    ("call", "args"),
    [
        (compose_poses, ([0.0, 0.0], [0.0, 0.0, 0.0])),
        (between_poses, ([0.0, 0.0, 0.0], [[0.0, 0.0]])),
        (invert_poses, (1.0,)),
        (rotate_xy, (0.0, [1.0, 2.0, 3.0])),
        (transform_points, ([0.0, 0.0, 0.0], [[1.0, 2.0, 3.0]])),
    ],
)
def test_wrong_last_axis_is_refused(call: object, args: tuple[object, ...]) -> None:
    with pytest.raises(GeometryError, match="last axis"):
        call(*args)  # type: ignore[operator]
