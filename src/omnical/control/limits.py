"""Velocity saturation and acceleration limiting of body-twist commands (seed 000 §2.3).

:func:`limit_command` saturates (direction of travel kept), then limits the change; from a
feasible previous command the output never exceeds the bounds of :class:`CommandLimits`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from omnical.errors import ConfigError, LimitError
from omnical.estimation.se2 import Twist
from omnical.robot.description import Limits

__all__ = [
    "DEFAULT_COMMAND_LIMITS",
    "CommandLimits",
    "limit_acceleration",
    "limit_command",
    "saturate_twist",
]


@dataclass(frozen=True)
class CommandLimits:
    """Bounds on a body-twist command (base_link, SI units); ``math.inf`` = unbounded.

    Attributes:
        max_vx_mps, max_vy_mps, max_wz_radps: per-axis velocity saturation.
        max_speed_mps: bound on the translational speed √(vx² + vy²).
        max_ax_mps2, max_ay_mps2, max_alpha_radps2: per-axis acceleration bounds.
        max_accel_mps2: bound on the norm of the translational acceleration.

    Raises:
        ConfigError: on construction, for a bound that is not > 0 (NaN included).
    """

    max_vx_mps: float = math.inf
    max_vy_mps: float = math.inf
    max_wz_radps: float = math.inf
    max_speed_mps: float = math.inf
    max_ax_mps2: float = math.inf
    max_ay_mps2: float = math.inf
    max_alpha_radps2: float = math.inf
    max_accel_mps2: float = math.inf

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not value > 0.0:
                msg = f"command limit {f.name} must be > 0 (math.inf for none), got {value}"
                raise ConfigError(msg)

    @classmethod
    def from_robot(cls, limits: Limits, *, max_speed_mps: float | None = None) -> CommandLimits:
        """The limits of a robot description; the speed bound defaults to max(vx, vy) bounds."""
        speed = (
            max(limits.max_vx_mps, limits.max_vy_mps) if max_speed_mps is None else max_speed_mps
        )
        return cls(
            max_vx_mps=limits.max_vx_mps,
            max_vy_mps=limits.max_vy_mps,
            max_wz_radps=limits.max_wz_radps,
            max_speed_mps=speed,
            max_ax_mps2=limits.max_ax_mps2,
            max_ay_mps2=limits.max_ay_mps2,
            max_alpha_radps2=limits.max_alpha_radps2,
        )

    def tightened(self, other: CommandLimits) -> CommandLimits:
        """The element-wise smaller of two sets of limits."""
        return CommandLimits(
            *(min(getattr(self, f.name), getattr(other, f.name)) for f in fields(self))
        )

    def check(self, twist: Twist, *, tolerance: float = 1e-9) -> None:
        """Refuse a twist beyond the velocity bounds.

        Raises:
            LimitError: naming the first bound exceeded.
        """
        vx, vy, wz = twist
        for name, value, bound in (
            ("vx", abs(vx), self.max_vx_mps),
            ("vy", abs(vy), self.max_vy_mps),
            ("wz", abs(wz), self.max_wz_radps),
            ("speed", math.hypot(vx, vy), self.max_speed_mps),
        ):
            if value > bound * (1.0 + tolerance):
                msg = f"twist {twist}: {name} {value:.6g} exceeds its limit {bound:.6g}"
                raise LimitError(msg)


#: Conservative limits for closed-loop experiments indoors: 0.3 m/s, 1 rad/s, 0.3 m/s², 1 rad/s².
DEFAULT_COMMAND_LIMITS = CommandLimits(
    max_vx_mps=0.3,
    max_vy_mps=0.3,
    max_wz_radps=1.0,
    max_speed_mps=0.3,
    max_ax_mps2=0.3,
    max_ay_mps2=0.3,
    max_alpha_radps2=1.0,
    max_accel_mps2=0.3,
)


def _clamp(value: float, bound: float) -> float:
    return max(-bound, min(bound, value))


def _check_twist(label: str, twist: Twist) -> None:
    if len(twist) != 3 or not all(math.isfinite(v) for v in twist):
        msg = f"{label} must be 3 finite numbers (vx, vy, wz), got {twist}"
        raise ConfigError(msg)


def saturate_twist(limits: CommandLimits, twist: Twist) -> Twist:
    """Velocity saturation: each axis to its bound, then the translational speed.

    Args:
        limits: the bounds.
        twist: (vx m/s, vy m/s, wz rad/s) in base_link.

    Returns:
        The saturated twist; (vx, vy) are scaled together for the speed bound.

    Raises:
        ConfigError: a twist that is not 3 finite numbers.
    """
    _check_twist("twist", twist)
    vx = _clamp(twist[0], limits.max_vx_mps)
    vy = _clamp(twist[1], limits.max_vy_mps)
    wz = _clamp(twist[2], limits.max_wz_radps)
    speed = math.hypot(vx, vy)
    if speed > limits.max_speed_mps:
        scale = limits.max_speed_mps / speed
        vx, vy = vx * scale, vy * scale
    return (vx, vy, wz)


def limit_acceleration(
    limits: CommandLimits, previous: Twist, command: Twist, dt_s: float
) -> Twist:
    """Acceleration limiting: move from ``previous`` towards ``command`` by at most a·``dt_s``.

    Args:
        limits: the bounds (only the acceleration bounds are used).
        previous: the command sent at the previous tick.
        command: the command wanted now.
        dt_s: time since the previous tick (> 0).

    Returns:
        The limited command: the translational change scaled as one vector to meet the per-axis
        and norm bounds, the yaw-rate change clamped.

    Raises:
        ConfigError: a non-positive time step or a twist that is not 3 finite numbers.
    """
    if not (math.isfinite(dt_s) and dt_s > 0.0):
        msg = f"acceleration limiting needs a finite time step > 0, got {dt_s}"
        raise ConfigError(msg)
    _check_twist("previous command", previous)
    _check_twist("command", command)
    dvx, dvy = command[0] - previous[0], command[1] - previous[1]
    scale = 1.0
    for change, bound in (
        (abs(dvx), limits.max_ax_mps2 * dt_s),
        (abs(dvy), limits.max_ay_mps2 * dt_s),
        (math.hypot(dvx, dvy), limits.max_accel_mps2 * dt_s),
    ):
        if change > bound:
            scale = min(scale, bound / change)
    dwz = _clamp(command[2] - previous[2], limits.max_alpha_radps2 * dt_s)
    return (previous[0] + scale * dvx, previous[1] + scale * dvy, previous[2] + dwz)


def limit_command(limits: CommandLimits, previous: Twist, command: Twist, dt_s: float) -> Twist:
    """Velocity saturation, then acceleration limiting (the command output stage of seed 000 §2.3).

    Args:
        limits: the bounds.
        previous: the command sent at the previous tick (assumed within the velocity bounds).
        command: the controller's command.
        dt_s: time since the previous tick (> 0).

    Returns:
        The command to send.

    Raises:
        ConfigError: a non-positive time step or a twist that is not 3 finite numbers.
    """
    return limit_acceleration(limits, previous, saturate_twist(limits, command), dt_s)
