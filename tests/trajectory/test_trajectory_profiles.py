"""The trapezoidal phase law of seed 000 §4.2."""

from __future__ import annotations

import math

import numpy as np
import pytest

from omnical.errors import ConfigError
from omnical.trajectory.profiles import phase_profile, profile_duration, profile_timing

TWO_PI = 2.0 * math.pi


def test_trapezoid_timing_matches_closed_form() -> None:
    timing = profile_timing(0.03, 0.09, TWO_PI)
    assert timing.ramp_s == pytest.approx(3.0)
    assert timing.cruise_s == pytest.approx(TWO_PI / 0.09 - 3.0)
    assert timing.duration_s == pytest.approx(TWO_PI / 0.09 + 0.09 / 0.03)
    assert timing.peak_rate == 0.09
    assert not timing.triangular
    assert profile_duration(0.03, 0.09, TWO_PI) == pytest.approx(72.81317008)


def test_phases_of_seed000_law() -> None:
    A, W = 0.03, 0.09
    total = profile_duration(A, W, TWO_PI)
    t = np.array([-1.0, 0.0, 1.5, 3.0, 30.0, total - 3.0, total - 1.0, total, total + 5.0])
    phi, phi_dot, phi_ddot = phase_profile(t, A, W, TWO_PI)
    # ramp up: φ = A t²/2, φ̇ = A t
    assert phi[2] == pytest.approx(0.5 * A * 1.5**2)
    assert phi_dot[2] == pytest.approx(A * 1.5)
    assert phi_ddot[:4].tolist() == [0.0, A, A, 0.0]
    # cruise at Ω
    assert phi_dot[4] == pytest.approx(W)
    assert phi[4] == pytest.approx(0.5 * A * 9.0 + W * 27.0)
    # deceleration starts at φ = 2π − Ω²/(2A), as the paper states
    assert phi[5] == pytest.approx(TWO_PI - W * W / (2.0 * A))
    assert phi_ddot[6] == -A
    assert phi_dot[6] == pytest.approx(A * 1.0)
    # stops exactly at 2π and stays there
    assert phi[7] == TWO_PI
    assert phi[8] == TWO_PI
    assert phi_dot[0] == phi_dot[7] == phi_dot[8] == 0.0
    assert phi[0] == 0.0


def test_profile_is_self_consistent() -> None:
    A, W = 0.5, 2.0
    total = profile_duration(A, W, 20.0)
    t = np.linspace(0.0, total, 200_001)
    phi, phi_dot, phi_ddot = phase_profile(t, A, W, 20.0)
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (phi_dot[1:] + phi_dot[:-1]) * np.diff(t))])
    np.testing.assert_allclose(integral, phi, atol=1e-6)
    assert phi_dot.max() == pytest.approx(W)
    assert np.abs(phi_ddot).max() == A
    assert np.all(np.diff(phi) >= 0.0)


def test_triangular_when_travel_is_short() -> None:
    A, W, d = 1.0, 2.0, 1.0  # Ω²/A = 4 > 1
    timing = profile_timing(A, W, d)
    assert timing.triangular
    assert timing.peak_rate == pytest.approx(1.0)
    assert timing.cruise_s == 0.0
    assert timing.duration_s == pytest.approx(2.0)
    phi, phi_dot, _ = phase_profile([1.0, 2.0], A, W, d)
    assert phi.tolist() == pytest.approx([0.5, 1.0])
    assert phi_dot[0] == pytest.approx(1.0)


def test_broadcasts_over_many_profiles() -> None:
    phi, phi_dot, _ = phase_profile(1.0, [1.0, 2.0], 10.0, [100.0, 100.0])
    assert phi.tolist() == pytest.approx([0.5, 1.0])
    assert phi_dot.tolist() == pytest.approx([1.0, 2.0])


def test_zero_travel_is_at_rest() -> None:
    phi, phi_dot, phi_ddot = phase_profile([0.0, 1.0], 1.0, 1.0, 0.0)
    assert phi.tolist() == [0.0, 0.0]
    assert phi_dot.tolist() == [0.0, 0.0]
    assert phi_ddot.tolist() == [0.0, 0.0]
    assert profile_duration(1.0, 1.0, 0.0) == 0.0


@pytest.mark.parametrize(
    ("A", "W", "d"), [(0.0, 1.0, 1.0), (1.0, -1.0, 1.0), (1.0, 1.0, -1.0), (math.nan, 1.0, 1.0)]
)
def test_rejects_bad_parameters(A: float, W: float, d: float) -> None:
    with pytest.raises(ConfigError, match="profile"):
        phase_profile(0.0, A, W, d)
    with pytest.raises(ConfigError, match="profile"):
        profile_timing(A, W, d)
