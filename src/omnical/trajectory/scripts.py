"""Open-loop scripts: a reference turned into feed-forward body-twist commands (seed 000 Eq. 6).

Held from one command time to the next, ``"exact"`` (SE(2) log of each period's motion) or
``"midpoint"``; :func:`check_twist_limits` refuses commands beyond the robot's limits.
"""

from __future__ import annotations

import math
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError, LimitError
from omnical.estimation.se2 import between_poses, rotate_xy
from omnical.trajectory.references import Reference

__all__ = [
    "TwistLimits",
    "body_twists_between",
    "check_twist_limits",
    "feedforward_commands",
    "integrate_body_twists",
]

FloatArray = NDArray[np.float64]


class TwistLimits(Protocol):
    """Speed and acceleration bounds of a base (``omnical.robot.Limits`` fits)."""

    @property
    def max_vx_mps(self) -> float:
        """Largest |vx|."""

    @property
    def max_vy_mps(self) -> float:
        """Largest |vy|."""

    @property
    def max_wz_radps(self) -> float:
        """Largest |wz|."""

    @property
    def max_ax_mps2(self) -> float:
        """Largest |d vx / dt|."""

    @property
    def max_ay_mps2(self) -> float:
        """Largest |d vy / dt|."""

    @property
    def max_alpha_radps2(self) -> float:
        """Largest |d wz / dt|."""


def _v_matrix_terms(theta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """a = sin θ / θ and b = (1 − cos θ) / θ of the SE(2) exponential, exact at θ = 0."""
    a = np.sinc(theta / np.pi)
    b = 0.5 * theta * np.sinc(theta / (2.0 * np.pi)) ** 2
    return a, b


def integrate_body_twists(
    t_s: ArrayLike, body_twists: ArrayLike, pose0: ArrayLike = (0.0, 0.0, 0.0)
) -> FloatArray:
    """Poses reached by holding each body twist until the next time (exact SE(2) integration).

    Args:
        t_s: (K,) command times, increasing.
        body_twists: (K, 3) vx m/s, vy m/s, wz rad/s held over [t_k, t_k+1); the last is unused.
        pose0: (3,) x m, y m, yaw rad at ``t_s[0]``.

    Returns:
        (K, 3) poses at ``t_s`` (yaw continuous).

    Raises:
        ConfigError: shapes that do not match or times that decrease.
    """
    t = np.asarray(t_s, dtype=np.float64)
    xi = np.asarray(body_twists, dtype=np.float64)
    p0 = np.asarray(pose0, dtype=np.float64)
    if t.ndim != 1 or xi.shape != (t.size, 3) or p0.shape != (3,):
        msg = f"expected t_s (K,), body_twists (K, 3), pose0 (3,); got {t.shape}, {xi.shape}, {p0.shape}"
        raise ConfigError(msg)
    dt = np.diff(t)
    if np.any(dt < 0.0):
        msg = "command times must not decrease"
        raise ConfigError(msg)
    theta = xi[:-1, 2] * dt
    a, b = _v_matrix_terms(theta)
    dx_body = (a * xi[:-1, 0] - b * xi[:-1, 1]) * dt
    dy_body = (b * xi[:-1, 0] + a * xi[:-1, 1]) * dt
    yaw = p0[2] + np.concatenate([[0.0], np.cumsum(theta)])
    step_xy = rotate_xy(yaw[:-1], np.column_stack([dx_body, dy_body]))
    xy = p0[:2] + np.vstack([np.zeros((1, 2)), np.cumsum(step_xy, axis=0)])
    return np.column_stack([xy, yaw])


def body_twists_between(t_s: ArrayLike, poses: ArrayLike) -> FloatArray:
    """Constant body twists that carry each pose onto the next (SE(2) log of the relative pose / Δt).

    The inverse of :func:`integrate_body_twists`.

    Args:
        t_s: (K,) strictly increasing times.
        poses: (K, 3) x m, y m, yaw rad (yaw continuous: steps are not wrapped).

    Returns:
        (K − 1, 3) vx m/s, vy m/s, wz rad/s, one per interval.

    Raises:
        ConfigError: shapes that do not match or times that do not increase.
    """
    t = np.asarray(t_s, dtype=np.float64)
    p = np.asarray(poses, dtype=np.float64)
    if t.ndim != 1 or p.shape != (t.size, 3):
        msg = f"expected t_s (K,) and poses (K, 3), got {t.shape} and {p.shape}"
        raise ConfigError(msg)
    dt = np.diff(t)
    if np.any(dt <= 0.0):
        msg = "times must increase strictly"
        raise ConfigError(msg)
    ux, uy, theta = between_poses(p[:-1], p[1:]).T
    a, b = _v_matrix_terms(theta)
    det = a * a + b * b
    rho_x = (a * ux + b * uy) / det
    rho_y = (-b * ux + a * uy) / det
    return np.stack([rho_x / dt, rho_y / dt, theta / dt], axis=-1)


def feedforward_commands(
    reference: Reference,
    rate_hz: float,
    *,
    method: Literal["exact", "midpoint"] = "exact",
    limits: TwistLimits | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Feed-forward body-twist commands that play ``reference`` open loop.

    Args:
        reference: the trajectory, starting at t = 0.
        rate_hz: command rate.
        method: ``"exact"`` (SE(2) interval twist) or ``"midpoint"`` (Eq. 6 at mid-period).
        limits: if given, the commands are checked with :func:`check_twist_limits`.

    Returns:
        ``(t_s, twists)``: (K + 1,) times k / rate_hz covering the reference and (K + 1, 3)
        twists held from each time to the next, the last one zero.

    Raises:
        ConfigError: a non-positive rate or an unknown method.
        LimitError: a command beyond ``limits``.
    """
    if not (math.isfinite(rate_hz) and rate_hz > 0.0):
        msg = f"command rate must be finite and > 0, got {rate_hz}"
        raise ConfigError(msg)
    n = max(1, math.ceil(reference.duration_s * rate_hz - 1e-9))
    t = np.arange(n + 1) / rate_hz
    if method == "exact":
        poses, _ = reference.at(np.minimum(t, reference.duration_s))
        twists = body_twists_between(t, poses)
    elif method == "midpoint":
        _, twists = reference.at(t[:-1] + 0.5 / rate_hz)
    else:
        msg = f"unknown feed-forward method {method!r} (use 'exact' or 'midpoint')"
        raise ConfigError(msg)
    commands = np.vstack([twists, np.zeros((1, 3))])
    if limits is not None:
        check_twist_limits(t, commands, limits)
    return t, commands


_NAMES = (
    ("vx", "m/s", "max_vx_mps"),
    ("vy", "m/s", "max_vy_mps"),
    ("wz", "rad/s", "max_wz_radps"),
    ("ax", "m/s²", "max_ax_mps2"),
    ("ay", "m/s²", "max_ay_mps2"),
    ("alpha", "rad/s²", "max_alpha_radps2"),
)


def check_twist_limits(
    t_s: ArrayLike,
    body_twists: ArrayLike,
    limits: TwistLimits,
    *,
    initial_twist: ArrayLike = (0.0, 0.0, 0.0),
    rtol: float = 1e-9,
) -> None:
    """Refuse a held-twist command sequence beyond the robot's limits.

    Acceleration k is (command k − command k − 1) / (t_k − t_k−1); command 0 starts from
    ``initial_twist``.

    Args:
        t_s: (K,) increasing command times, K ≥ 2.
        body_twists: (K, 3) vx m/s, vy m/s, wz rad/s.
        limits: the bounds (``omnical.robot.Limits`` or alike).
        initial_twist: (3,) twist before the first command.
        rtol: relative slack on each bound (round-off).

    Raises:
        ConfigError: shapes that do not match, fewer than 2 commands, times that do not increase.
        LimitError: the first command (in time) that exceeds a bound, naming quantity and bound.
    """
    t = np.asarray(t_s, dtype=np.float64)
    xi = np.asarray(body_twists, dtype=np.float64)
    if t.ndim != 1 or t.size < 2 or xi.shape != (t.size, 3):
        msg = f"expected t_s (K,) with K >= 2 and body_twists (K, 3), got {t.shape} and {xi.shape}"
        raise ConfigError(msg)
    dt = np.diff(t)
    if np.any(dt <= 0.0):
        msg = "command times must increase strictly"
        raise ConfigError(msg)
    before = np.vstack([np.asarray(initial_twist, dtype=np.float64).reshape(1, 3), xi[:-1]])
    accel = (xi - before) / np.concatenate([dt[:1], dt])[:, None]
    values = np.hstack([xi, accel])
    bounds = np.array([getattr(limits, attr) for _, _, attr in _NAMES], dtype=np.float64)
    over = np.abs(values) > bounds * (1.0 + rtol) + 1e-12
    if not over.any():
        return
    k, q = np.argwhere(over)[0]
    name, unit, attr = _NAMES[q]
    msg = (
        f"command {k} at t = {t[k]:.3f} s: {name} = {values[k, q]:.4g} {unit} "
        f"exceeds {attr} = {bounds[q]:.4g}"
    )
    raise LimitError(msg)
