"""Kinematics against the seeds' equations, and round-trip properties."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omnical.errors import ConfigError
from omnical.kinematics.jacobian import (
    body_twist_from_wheel_speeds,
    forward_jacobian,
    inverse_jacobian,
    wheel_speeds_from_body_twist,
)
from omnical.robot.description import Wheel
from omnical.robot.loader import load_robot


def _seed001_wheels(lx: float, ly: float, R: float) -> list[Wheel]:
    # seed 001 Table 2: γ = −45, 45, −45, 45; lx_i = −lx, lx, lx, −lx; ly_i = ly, ly, −ly, −ly
    gammas = [-45.0, 45.0, -45.0, 45.0]
    xs = [-lx, lx, lx, -lx]
    ys = [ly, ly, -ly, -ly]
    return [Wheel(f"w{i + 1}", xs[i], ys[i], math.radians(gammas[i]), R) for i in range(4)]


@pytest.mark.parametrize(
    ("lx", "ly", "R"), [(0.2, 0.235, 0.0762), (0.3, 0.25, 0.05), (1.0, 2.0, 1.0)]
)
def test_seed001_eq7_inverse_jacobian_exact(lx: float, ly: float, R: float) -> None:
    J = inverse_jacobian(_seed001_wheels(lx, ly, R))
    L = lx + ly
    expected = (1.0 / R) * np.array([[1, 1, -L], [1, -1, -L], [1, 1, L], [1, -1, L]], dtype=float)
    np.testing.assert_array_equal(J, expected)


@pytest.mark.parametrize(("lx", "ly", "R"), [(0.2, 0.235, 0.0762), (0.3, 0.25, 0.05)])
def test_seed001_eq10_pseudo_inverse(lx: float, ly: float, R: float) -> None:
    J_plus = forward_jacobian(inverse_jacobian(_seed001_wheels(lx, ly, R)))
    L = lx + ly
    expected = (R / 4.0) * np.array(
        [[1, 1, 1, 1], [1, -1, 1, -1], [-1 / L, -1 / L, 1 / L, 1 / L]], dtype=float
    )
    np.testing.assert_allclose(J_plus, expected, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(
        J_plus @ inverse_jacobian(_seed001_wheels(lx, ly, R)), np.eye(3), atol=1e-12
    )


def test_seed001_eq5_single_wheel() -> None:
    # v_i = v_x − l_yi Ω − (v_y + l_xi Ω) / tan γ_i for an arbitrary wheel
    w = Wheel("w", 0.3, -0.1, math.radians(30.0), 1.0)
    vx, vy, om = 0.4, -0.2, 0.7
    expected = vx - w.y_m * om - (vy + w.x_m * om) / math.tan(w.roller_angle_rad)
    got = wheel_speeds_from_body_twist(
        inverse_jacobian([w, *_seed001_wheels(0.2, 0.2, 1.0)]), [vx, vy, om]
    )[0]
    assert got == pytest.approx(expected, rel=1e-12)


def test_seed003_eq4_5_omni_x_under_stated_convention() -> None:
    # Convention (omni-x.yaml): wheel i at angle −α_i, rolling along the CCW tangent; the third
    # column of seed 003 Eq. 4, written "R", is the wheel's distance d from the centre.
    robot = load_robot("omni-x")
    r = robot.wheels[0].radius_m
    d = math.hypot(robot.wheels[0].x_m, robot.wheels[0].y_m)
    alphas = np.radians([45.0, 135.0, 225.0, 315.0])
    expected = (1.0 / r) * np.column_stack([np.sin(alphas), np.cos(alphas), np.full(4, d)])
    np.testing.assert_allclose(inverse_jacobian(robot.wheels), expected, rtol=1e-9)


def test_rosy_preset_matches_seed000_eq2() -> None:
    robot = load_robot("rosy-mecanum")
    J = inverse_jacobian(robot.wheels)
    R = robot.wheels[0].radius_m
    L = 0.2 + 0.235
    np.testing.assert_allclose(J * R, [[1, 1, -L], [1, -1, -L], [1, 1, L], [1, -1, L]], atol=1e-12)


def test_singular_geometry_is_rejected() -> None:
    # all wheels rolling forward with omni rollers: no lateral authority
    wheels = [
        Wheel(f"w{i}", x, y, math.pi / 2, 0.05)
        for i, (x, y) in enumerate([(1, 1), (1, -1), (-1, 1)])
    ]
    with pytest.raises(ConfigError, match="singular"):
        inverse_jacobian(wheels)


twists = st.tuples(
    st.floats(-2.0, 2.0, allow_nan=False),
    st.floats(-2.0, 2.0, allow_nan=False),
    st.floats(-5.0, 5.0, allow_nan=False),
)


@settings(max_examples=200, deadline=None)
@given(twist=twists, preset=st.sampled_from(["rosy-mecanum", "omni-x"]))
def test_forward_after_inverse_is_identity(twist: tuple[float, float, float], preset: str) -> None:
    J = inverse_jacobian(load_robot(preset).wheels)
    back = body_twist_from_wheel_speeds(forward_jacobian(J), wheel_speeds_from_body_twist(J, twist))
    np.testing.assert_allclose(back, twist, atol=1e-9)


def test_batched_shapes() -> None:
    J = inverse_jacobian(load_robot("rosy-mecanum").wheels)
    rng = np.random.default_rng(7)
    tw = rng.normal(size=(5, 6, 3))
    ws = wheel_speeds_from_body_twist(J, tw)
    assert ws.shape == (5, 6, 4)
    np.testing.assert_allclose(
        body_twist_from_wheel_speeds(forward_jacobian(J), ws), tw, atol=1e-12
    )
