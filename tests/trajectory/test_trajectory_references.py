"""Reference paths of the seeds: Lissajous (seed 000), circle and square (seed 001), seed 003 paths."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from omnical.errors import ConfigError
from omnical.trajectory.profiles import phase_profile
from omnical.trajectory.references import (
    SEED001_SQUARE_M,
    SEED003_SQUARE_M,
    SEED003_TRIANGLE_M,
    Reference,
    circle,
    lissajous,
    polygon,
    waypoints,
)


def _path_length(ref: Reference) -> float:
    dense = ref.resampled(0.005)
    return float(np.sum(np.hypot(*np.diff(dense.poses[:, :2], axis=0).T)))


def _world_velocity_by_difference(ref: Reference, t: np.ndarray, h: float = 1e-5) -> np.ndarray:
    ahead, _ = ref.at(t + h)
    behind, _ = ref.at(t - h)
    return (ahead - behind) / (2.0 * h)


def _body_to_world(poses: np.ndarray, twists: np.ndarray) -> np.ndarray:
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    vx, vy = twists[:, 0], twists[:, 1]
    return np.stack([c * vx - s * vy, s * vx + c * vy, twists[:, 2]], axis=-1)


def test_lissajous_follows_eq5_and_eq6() -> None:
    ref = lissajous(phase_accel_radps2=0.03, phase_rate_radps=0.09)
    t = np.array([0.0, 2.0, 10.0, 40.0, 71.0])
    phi, phi_dot, _ = phase_profile(t, 0.03, 0.09, 2.0 * math.pi)
    poses, twists = ref.at(t)
    np.testing.assert_allclose(poses[:, 0], np.sin(2.0 * phi), atol=1e-12)
    np.testing.assert_allclose(poses[:, 1], np.cos(phi), atol=1e-12)
    np.testing.assert_allclose(poses[:, 2], math.pi / 2)
    # Eq. 6 in map, turned into the robot frame rotated 90° CCW: body (vx, vy) = (v_y, −v_x)
    vx_map, vy_map = 2.0 * phi_dot * np.cos(2.0 * phi), -phi_dot * np.sin(phi)
    np.testing.assert_allclose(twists[:, 0], vy_map, atol=1e-12)
    np.testing.assert_allclose(twists[:, 1], -vx_map, atol=1e-12)
    np.testing.assert_array_equal(twists[:, 2], 0.0)


def test_lissajous_twist_is_the_derivative_of_its_pose() -> None:
    ref = lissajous(origin_m=(2.0, 3.0), rotation_rad=0.4, heading_offset_rad=1.0)
    t = np.linspace(0.5, ref.duration_s - 0.5, 37)
    poses, twists = ref.at(t)
    np.testing.assert_allclose(
        _body_to_world(poses, twists), _world_velocity_by_difference(ref, t), atol=1e-7
    )
    np.testing.assert_allclose(poses[:, 2], 1.4)


def test_lissajous_defaults_match_the_paper_run() -> None:
    ref = lissajous()
    assert 60.0 <= ref.duration_s <= 90.0
    assert _path_length(ref) == pytest.approx(9.4294, abs=2e-3)  # "about 10 m"
    speed = np.hypot(ref.body_twists[:, 0], ref.body_twists[:, 1])
    assert speed.max() == pytest.approx(math.sqrt(5.0) * 0.09, rel=1e-3)  # |dp/dφ| = √5 at φ = π/2
    np.testing.assert_allclose(ref.poses[0], [0.0, 1.0, math.pi / 2], atol=1e-12)
    np.testing.assert_allclose(ref.poses[-1], [0.0, 1.0, math.pi / 2], atol=1e-12)
    np.testing.assert_array_equal(ref.body_twists[[0, -1]], 0.0)
    assert np.all(np.diff(ref.t_s) <= 0.02 + 1e-12)
    assert ref.t_s[-1] == ref.duration_s


def test_lissajous_rejects_bad_scale() -> None:
    with pytest.raises(ConfigError, match="scale"):
        lissajous(scale_m=0.0)
    with pytest.raises(ConfigError, match="dt_s"):
        lissajous(dt_s=0.0)


def test_circle_seed001() -> None:
    ref = circle(radius_m=1.0, speed_mps=0.1, accel_mps2=0.05)
    radius = np.hypot(ref.poses[:, 0], ref.poses[:, 1])
    np.testing.assert_allclose(radius, 1.0, atol=1e-12)
    np.testing.assert_allclose(ref.poses[0], [0.0, -1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(ref.poses[-1], [0.0, -1.0, 0.0], atol=1e-12)
    speed = np.hypot(ref.body_twists[:, 0], ref.body_twists[:, 1])
    assert speed.max() == pytest.approx(0.1)
    assert ref.duration_s == pytest.approx(2.0 * math.pi / 0.1 + 0.1 / 0.05)
    # counter-clockwise: angular momentum about the centre is positive
    world = _body_to_world(ref.poses, ref.body_twists)
    cross = ref.poses[:, 0] * world[:, 1] - ref.poses[:, 1] * world[:, 0]
    assert cross.min() >= 0.0
    assert cross.max() == pytest.approx(0.1)


def test_circle_facing_the_tangent_drives_forward() -> None:
    ref = circle(radius_m=0.5, speed_mps=0.2, face_tangent=True, clockwise=True)
    poses, twists = ref.at(np.array([ref.duration_s / 2]))
    assert twists[0, 0] == pytest.approx(0.2)
    assert twists[0, 1] == pytest.approx(0.0, abs=1e-12)
    assert twists[0, 2] == pytest.approx(-0.2 / 0.5)
    t = np.linspace(1.0, ref.duration_s - 1.0, 25)
    poses, twists = ref.at(t)
    np.testing.assert_allclose(
        _body_to_world(poses, twists), _world_velocity_by_difference(ref, t), atol=1e-7
    )


@pytest.mark.parametrize(
    ("vertices", "side_m"),
    [(SEED001_SQUARE_M, 1.0), (SEED003_SQUARE_M, 1.2), (SEED003_TRIANGLE_M, None)],
)
def test_polygons_visit_their_vertices_at_rest(
    vertices: tuple[tuple[float, float], ...], side_m: float | None
) -> None:
    ref = polygon(vertices, speed_mps=0.1, accel_mps2=0.1, dwell_s=1.0)
    loop = [*vertices, vertices[0]]
    lengths = [math.dist(a, b) for a, b in itertools.pairwise(loop)]
    if side_m is not None:
        assert lengths == pytest.approx([side_m] * 4)
    # each leg: L/v + v/a seconds; a one-second dwell between legs
    expected = sum(L / 0.1 + 1.0 for L in lengths) + (len(lengths) - 1) * 1.0
    assert ref.duration_s == pytest.approx(expected)
    assert _path_length(ref) == pytest.approx(sum(lengths), rel=1e-6)
    speed = np.hypot(ref.body_twists[:, 0], ref.body_twists[:, 1])
    assert speed.max() == pytest.approx(0.1)
    np.testing.assert_array_equal(ref.poses[:, 2], 0.0)
    leg_end = 0.0
    for (x, y), L in zip(loop[1:], lengths, strict=True):
        leg_end += L / 0.1 + 1.0
        pose, twist = ref.at([leg_end + 0.5])  # mid-dwell
        np.testing.assert_allclose(pose[0], [x, y, 0.0], atol=1e-12)
        np.testing.assert_array_equal(twist[0], 0.0)
        leg_end += 1.0


def test_polygon_face_travel_turns_in_place() -> None:
    ref = polygon(SEED003_TRIANGLE_M, face_travel=True, dwell_s=0.0)
    # at the second vertex the robot turns from 0 to the direction of (0.6, 0.6) − (1.2, 0): 135°
    arrive = 1.2 / 0.1 + 0.1 / 0.1  # first leg
    turned = arrive + math.radians(135.0) / 0.5 + 0.5 / 0.5  # turn at 0.5 rad/s, 0.5 rad/s²
    poses, _ = ref.at([arrive, 0.5 * (arrive + turned), turned])
    np.testing.assert_allclose(poses[:, :2], [[1.2, 0.0]] * 3, atol=1e-12)
    np.testing.assert_allclose(poses[:, 2], np.radians([0.0, 67.5, 135.0]), atol=1e-12)
    moving = np.hypot(ref.body_twists[:, 0], ref.body_twists[:, 1]) > 1e-9
    # when it translates, it drives straight ahead
    np.testing.assert_allclose(ref.body_twists[moving, 1], 0.0, atol=1e-12)
    assert np.all(ref.body_twists[moving, 0] > 0.0)
    assert np.abs(ref.body_twists[:, 2]).max() == pytest.approx(0.5)


def test_waypoints_turn_while_translating() -> None:
    ref = waypoints(
        [(0.0, 0.0, 0.0), (1.0, 0.0, math.pi / 2)],
        speed_mps=0.2,
        accel_mps2=0.2,
        yaw_rate_radps=1.0,
        yaw_accel_radps2=1.0,
    )
    # the translation is the slower axis: 1 m at 0.2 m/s, ramps of 1 s
    assert ref.duration_s == pytest.approx(6.0)
    np.testing.assert_allclose(ref.poses[-1], [1.0, 0.0, math.pi / 2], atol=1e-12)
    mid_pose, mid_twist = ref.at([3.0])
    np.testing.assert_allclose(mid_pose[0], [0.5, 0.0, math.pi / 4], atol=1e-12)
    assert mid_twist[0, 2] == pytest.approx(0.2 * math.pi / 2)
    t = np.linspace(0.3, 5.7, 19)
    poses, twists = ref.at(t)
    np.testing.assert_allclose(
        _body_to_world(poses, twists), _world_velocity_by_difference(ref, t), atol=1e-7
    )


def test_waypoints_take_the_short_way_round() -> None:
    ref = waypoints([(0.0, 0.0, math.radians(170.0)), (0.0, 0.0, math.radians(-170.0))])
    assert ref.poses[-1, 2] == pytest.approx(math.radians(190.0))


@pytest.mark.parametrize(
    ("points", "match"),
    [
        ([(0.0, 0.0)], "at least 2"),
        ([(0.0, 0.0), (1.0,)], "way-point 1"),
        ([(0.0, 0.0), (1.0, math.nan)], "way-point 1"),
    ],
)
def test_waypoints_reject_bad_points(points: list[tuple[float, ...]], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        waypoints(points)


def test_waypoints_reject_bad_rates() -> None:
    with pytest.raises(ConfigError, match="speed_mps"):
        waypoints([(0.0, 0.0), (1.0, 0.0)], speed_mps=0.0)
    with pytest.raises(ConfigError, match="dwell_s"):
        polygon(SEED001_SQUARE_M, dwell_s=-1.0)
