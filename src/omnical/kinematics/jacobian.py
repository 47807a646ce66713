"""Inverse and forward kinematics of a wheeled omnidirectional base, from its wheel geometry.

Seed 001 Eq. 3–5 for any wheels (docs/CONVENTIONS.md), the forward model J⁺ (Eq. 9–11);
body twists (..., 3) as (v_x m/s, v_y m/s, Ω rad/s), wheel speeds (..., n) rad/s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError

__all__ = [
    "body_twist_from_wheel_speeds",
    "forward_jacobian",
    "inverse_jacobian",
    "wheel_speeds_from_body_twist",
]

_SIN_EPS = 1e-9


class Wheel(Protocol):
    """The geometry of one wheel the Jacobian needs (:class:`omnical.robot.description.Wheel`).

    Kinematics sits below the robot description: it reads any object with these attributes.
    """

    @property
    def name(self) -> str:
        """Wheel name, for messages."""

    @property
    def x_m(self) -> float:
        """Contact point x in base_link, m."""

    @property
    def y_m(self) -> float:
        """Contact point y in base_link, m."""

    @property
    def roller_angle_rad(self) -> float:
        """Roller angle γ, rad."""

    @property
    def radius_m(self) -> float:
        """Wheel radius, m."""

    @property
    def drive_direction_rad(self) -> float:
        """Direction the wheel drives in base_link, rad."""


def _wheel_row(wheel: Wheel) -> tuple[float, float, float]:
    sin_g = math.sin(wheel.roller_angle_rad)
    if abs(sin_g) < _SIN_EPS:
        msg = f"wheel {wheel.name!r}: roller angle 0 makes the wheel uncontrollable sideways"
        raise ConfigError(msg)
    cot_g = math.cos(wheel.roller_angle_rad) / sin_g
    dx, dy = math.cos(wheel.drive_direction_rad), math.sin(wheel.drive_direction_rad)
    nx, ny = -dy, dx
    ax, ay = dx - nx * cot_g, dy - ny * cot_g
    # Snap round-off (cos(π/2) ≈ 6e-17) so the seed's exact integers come out exactly.
    ax, ay = round(ax, 12) + 0.0, round(ay, 12) + 0.0
    return (ax, ay, wheel.x_m * ay - wheel.y_m * ax)


def inverse_jacobian(wheels: Sequence[Wheel]) -> NDArray[np.float64]:
    """Inverse kinematic Jacobian J, shape (n, 3): wheel speeds (rad/s) from body twist.

    Raises:
        ConfigError: a wheel's roller angle is 0 or the geometry cannot produce all three motions.
    """
    if len(wheels) < 3:
        msg = f"a holonomic base needs at least 3 wheels, got {len(wheels)}"
        raise ConfigError(msg)
    rows = np.array([_wheel_row(w) for w in wheels], dtype=np.float64)
    radii = np.array([w.radius_m for w in wheels], dtype=np.float64)
    J: NDArray[np.float64] = np.divide(rows, radii[:, None])
    if np.linalg.matrix_rank(J) < 3:
        msg = "wheel geometry is singular: the wheels cannot produce vx, vy and yaw independently"
        raise ConfigError(msg)
    return J


def forward_jacobian(J: ArrayLike) -> NDArray[np.float64]:
    """Pseudo-inverse J⁺ = (JᵀJ)⁻¹Jᵀ, shape (3, n): body twist from wheel speeds (seed 001 Eq. 9)."""
    Jm = np.asarray(J, dtype=np.float64)
    result = np.linalg.solve(Jm.T @ Jm, Jm.T)
    return np.asarray(result, dtype=np.float64)


def wheel_speeds_from_body_twist(J: ArrayLike, twist: ArrayLike) -> NDArray[np.float64]:
    """Wheel speeds (..., n) rad/s from body twists (..., 3) (seed 001 Eq. 7)."""
    result: NDArray[np.float64] = np.asarray(twist, dtype=np.float64) @ np.asarray(J).T
    return result


def body_twist_from_wheel_speeds(J_plus: ArrayLike, wheel_speeds: ArrayLike) -> NDArray[np.float64]:
    """Body twists (..., 3) from wheel speeds (..., n) rad/s (seed 001 Eq. 11)."""
    result: NDArray[np.float64] = np.asarray(wheel_speeds, dtype=np.float64) @ np.asarray(J_plus).T
    return result
