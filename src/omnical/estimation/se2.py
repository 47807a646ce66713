"""Planar rigid motions (SE(2)) on plain float tuples, for controllers and filters.

A pose is ``(x m, y m, yaw rad)`` of a child frame in a parent frame; a body twist is
``(vx m/s, vy m/s, wz rad/s)`` in the child frame (CONVENTIONS.md). ``compose(a, b)`` is a ⊕ b:
the pose b, given in the frame of a, expressed in a's parent frame.

These run once per control tick on three numbers, so they work on Python floats rather than
numpy arrays (several times faster for a single pose).
"""

from __future__ import annotations

import math

__all__ = [
    "Pose2",
    "Twist",
    "between",
    "compose",
    "invert",
    "rotate",
    "transform_point",
    "wrap_angle",
]

Pose2 = tuple[float, float, float]
"""(x m, y m, yaw rad) of a frame in its parent."""

Twist = tuple[float, float, float]
"""(vx m/s, vy m/s, wz rad/s) in base_link."""


def wrap_angle(angle_rad: float) -> float:
    """The angle in [−π, π]."""
    return math.remainder(angle_rad, 2.0 * math.pi)


def rotate(angle_rad: float, x: float, y: float) -> tuple[float, float]:
    """The vector (x, y) turned counter-clockwise by ``angle_rad``."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return c * x - s * y, s * x + c * y


def compose(a: Pose2, b: Pose2) -> Pose2:
    """a ⊕ b: pose ``b`` (given in the frame of ``a``) in the parent frame of ``a``.

    The yaw is not wrapped, so a continuous yaw stays continuous.
    """
    dx, dy = rotate(a[2], b[0], b[1])
    return (a[0] + dx, a[1] + dy, a[2] + b[2])


def invert(a: Pose2) -> Pose2:
    """⊖a: the parent frame seen from ``a``."""
    x, y = rotate(-a[2], -a[0], -a[1])
    return (x, y, -a[2])


def between(a: Pose2, b: Pose2) -> Pose2:
    """⊖a ⊕ b: pose ``b`` expressed in the frame of ``a`` (both given in the same parent)."""
    dx, dy = rotate(-a[2], b[0] - a[0], b[1] - a[1])
    return (dx, dy, b[2] - a[2])


def transform_point(a: Pose2, x: float, y: float) -> tuple[float, float]:
    """The point (x, y), given in the frame of ``a``, in the parent frame of ``a``."""
    dx, dy = rotate(a[2], x, y)
    return a[0] + dx, a[1] + dy
