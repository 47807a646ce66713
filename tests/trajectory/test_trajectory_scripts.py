"""Feed-forward commands: SE(2) integration reproduces the reference; limits are refused."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omnical.errors import ConfigError, LimitError
from omnical.robot.loader import load_robot
from omnical.trajectory.references import (
    SEED001_SQUARE_M,
    SEED003_SQUARE_M,
    SEED003_TRIANGLE_M,
    Reference,
    circle,
    lissajous,
    polygon,
)
from omnical.trajectory.scripts import (
    body_twists_between,
    check_twist_limits,
    feedforward_commands,
    integrate_body_twists,
)

REFERENCES: dict[str, Callable[[], Reference]] = {
    "lissajous": lissajous,
    "circle": circle,
    "circle-tangent": lambda: circle(face_tangent=True, radius_m=0.8),
    "square-1m": lambda: polygon(SEED001_SQUARE_M),
    "square-1.2m": lambda: polygon(SEED003_SQUARE_M),
    "triangle": lambda: polygon(SEED003_TRIANGLE_M),
    "triangle-facing": lambda: polygon(SEED003_TRIANGLE_M, face_travel=True),
}


def _replay_error_m(ref: Reference, rate_hz: float, method: str) -> float:
    t, commands = feedforward_commands(ref, rate_hz, method=method)  # type: ignore[arg-type]
    poses = integrate_body_twists(t, commands, ref.poses[0])
    target, _ = ref.at(np.minimum(t, ref.duration_s))
    return float(np.hypot(*(poses[:, :2] - target[:, :2]).T).max())


@pytest.mark.parametrize("name", sorted(REFERENCES))
@pytest.mark.parametrize("method", ["exact", "midpoint"])
def test_feedforward_reproduces_reference_within_1mm(name: str, method: str) -> None:
    ref = REFERENCES[name]()
    assert _replay_error_m(ref, 50.0, method) < 1e-3


def test_exact_method_is_exact_at_any_rate_and_midpoint_is_second_order() -> None:
    ref = lissajous()
    assert _replay_error_m(ref, 5.0, "exact") < 1e-9
    coarse, fine = _replay_error_m(ref, 5.0, "midpoint"), _replay_error_m(ref, 10.0, "midpoint")
    assert 3.0 < coarse / fine < 5.0


def test_commands_cover_the_reference_and_end_with_a_stop() -> None:
    ref = polygon(SEED003_TRIANGLE_M)
    t, commands = feedforward_commands(ref, 50.0)
    assert t[0] == 0.0
    assert t[-1] >= ref.duration_s > t[-2]
    np.testing.assert_allclose(np.diff(t), 0.02)
    np.testing.assert_array_equal(commands[-1], 0.0)
    assert commands.shape == (t.size, 3)


def test_integration_of_a_constant_twist_is_a_circular_arc() -> None:
    v, w = 0.3, 0.5
    t = np.linspace(0.0, 4.0, 9)
    poses = integrate_body_twists(t, np.tile([v, 0.0, w], (t.size, 1)), (1.0, 2.0, 0.0))
    R = v / w
    np.testing.assert_allclose(poses[:, 0], 1.0 + R * np.sin(w * t), atol=1e-12)
    np.testing.assert_allclose(poses[:, 1], 2.0 + R * (1.0 - np.cos(w * t)), atol=1e-12)
    np.testing.assert_allclose(poses[:, 2], w * t, atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(st.integers(min_value=0, max_value=2**32 - 1))
def test_log_and_integration_are_inverse(seed: int) -> None:
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.01, 0.5, size=12))
    twists = rng.normal(0.0, [0.5, 0.5, 2.0], size=(12, 3))
    twists[rng.random(12) < 0.3, 2] = 0.0  # exercise θ = 0
    poses = integrate_body_twists(t, twists, rng.normal(size=3))
    np.testing.assert_allclose(body_twists_between(t, poses), twists[:-1], atol=1e-9)


def test_paper_references_respect_the_robot_limits() -> None:
    limits = load_robot("rosy-mecanum").limits
    for make in REFERENCES.values():
        feedforward_commands(make(), 50.0, limits=limits)


def test_too_fast_lissajous_is_refused_naming_the_axis() -> None:
    # the robot turned 90° sees v_x of Eq. 6 as −vy; 2SΩ = 0.9 m/s at φ = π against 0.8 m/s
    limits = replace(load_robot("rosy-mecanum").limits, max_ax_mps2=5.0, max_ay_mps2=5.0)
    fast = lissajous(phase_rate_radps=0.45, phase_accel_radps2=0.5)
    with pytest.raises(LimitError, match=r"vy = -0\.8\d* m/s exceeds max_vy_mps = 0\.8"):
        feedforward_commands(fast, 50.0, limits=limits)


def test_acceleration_limit_is_checked() -> None:
    limits = replace(load_robot("rosy-mecanum").limits, max_ax_mps2=0.05)
    with pytest.raises(LimitError, match=r"ax = .* exceeds max_ax_mps2 = 0\.05"):
        feedforward_commands(polygon(SEED001_SQUARE_M, accel_mps2=0.1), 50.0, limits=limits)
    feedforward_commands(polygon(SEED001_SQUARE_M, accel_mps2=0.04), 50.0, limits=limits)


def test_first_violation_is_reported() -> None:
    limits = load_robot("omni-x").limits  # max wz 2 rad/s, alpha 2 rad/s²
    t = np.array([0.0, 1.0, 2.0, 3.0])
    twists = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 2.5], [0.0, 0.0, 2.5], [0.0, 0.0, 0.0]])
    with pytest.raises(
        LimitError, match=r"command 1 at t = 1.000 s: wz = 2.5 rad/s exceeds max_wz_radps = 2"
    ):
        check_twist_limits(t, twists, limits)
    step = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    with pytest.raises(
        LimitError, match=r"command 0 .* alpha = 10 rad/s² exceeds max_alpha_radps2"
    ):
        check_twist_limits([0.0, 0.1], step, limits)
    check_twist_limits([0.0, 0.1], step, limits, initial_twist=(0.0, 0.0, 1.0))


def test_bad_inputs_are_config_errors() -> None:
    ref = polygon(SEED001_SQUARE_M)
    with pytest.raises(ConfigError, match="rate"):
        feedforward_commands(ref, 0.0)
    with pytest.raises(ConfigError, match="method"):
        feedforward_commands(ref, 10.0, method="euler")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="increase"):
        body_twists_between([0.0, 0.0], np.zeros((2, 3)))
    with pytest.raises(ConfigError, match="expected"):
        integrate_body_twists([0.0, 1.0], np.zeros((3, 3)))
    assert math.isclose(ref.duration_s, 4 * (10.0 + 1.0) + 3 * 1.0)
