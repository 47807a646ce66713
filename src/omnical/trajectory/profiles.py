"""Trapezoidal timing profiles: the phase law of seed 000 §4.2.

Accelerate to the rate limit, cruise, decelerate to stop exactly at the end (triangular when short);
rad for a phase, m for a distance, times in seconds from the start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError

__all__ = ["ProfileTiming", "phase_profile", "profile_duration", "profile_timing"]


@dataclass(frozen=True)
class ProfileTiming:
    """Timing of one trapezoidal (or triangular) profile.

    Attributes:
        accel: |φ̈| during the ramps (A).
        max_rate: requested cruise rate (Ω).
        phi_end: total travel.
        peak_rate: rate actually reached: Ω, or √(A φ_end) for a triangular profile.
        ramp_s: duration of each ramp.
        cruise_s: duration at ``peak_rate`` (0 when triangular).
    """

    accel: float
    max_rate: float
    phi_end: float
    peak_rate: float
    ramp_s: float
    cruise_s: float

    @property
    def duration_s(self) -> float:
        """Total duration: two ramps and the cruise."""
        return 2.0 * self.ramp_s + self.cruise_s

    @property
    def triangular(self) -> bool:
        """True when φ_end is too short to reach Ω."""
        return self.peak_rate < self.max_rate


def _check(accel: NDArray[np.float64], rate: NDArray[np.float64], end: NDArray[np.float64]) -> None:
    if not (np.all(np.isfinite(accel)) and np.all(accel > 0.0)):
        msg = f"profile acceleration must be finite and > 0, got {accel}"
        raise ConfigError(msg)
    if not (np.all(np.isfinite(rate)) and np.all(rate > 0.0)):
        msg = f"profile rate must be finite and > 0, got {rate}"
        raise ConfigError(msg)
    if not (np.all(np.isfinite(end)) and np.all(end >= 0.0)):
        msg = f"profile travel must be finite and >= 0, got {end}"
        raise ConfigError(msg)


def profile_timing(accel: float, max_rate: float, phi_end: float) -> ProfileTiming:
    """Ramp and cruise durations of the trapezoid that travels ``phi_end``.

    Args:
        accel: A > 0, the ramp acceleration.
        max_rate: Ω > 0, the cruise rate.
        phi_end: travel ≥ 0 (2π for the Lissajous curve).

    Raises:
        ConfigError: a non-finite or non-positive acceleration or rate, or a negative travel.
    """
    _check(np.asarray(accel, float), np.asarray(max_rate, float), np.asarray(phi_end, float))
    if phi_end >= max_rate * max_rate / accel:
        ramp_s = max_rate / accel
        cruise_s = (phi_end - max_rate * max_rate / accel) / max_rate
        return ProfileTiming(accel, max_rate, phi_end, max_rate, ramp_s, cruise_s)
    peak = math.sqrt(accel * phi_end)
    return ProfileTiming(accel, max_rate, phi_end, peak, peak / accel, 0.0)


def profile_duration(accel: float, max_rate: float, phi_end: float) -> float:
    """Total duration (s) of the profile: 2Ω/A + (φ_end − Ω²/A)/Ω, or 2√(φ_end/A) if triangular."""
    return profile_timing(accel, max_rate, phi_end).duration_s


def phase_profile(
    t_s: ArrayLike, accel: ArrayLike, max_rate: ArrayLike, phi_end: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Evaluate the trapezoidal phase law (seed 000 §4.2) at times ``t_s``.

    Arguments broadcast (many profiles in one call); at rest at 0 before t = 0 and at
    ``phi_end`` after the end.

    Args:
        t_s: times since the start of the profile, any shape.
        accel: A > 0, ramp acceleration (rad/s² for a phase, m/s² for a distance).
        max_rate: Ω > 0, cruise rate.
        phi_end: travel ≥ 0.

    Returns:
        ``(phi, phi_dot, phi_ddot)``, each of the broadcast shape.

    Raises:
        ConfigError: a non-finite or non-positive acceleration or rate, or a negative travel.
    """
    t, a, w, d = np.broadcast_arrays(
        *(np.asarray(v, dtype=np.float64) for v in (t_s, accel, max_rate, phi_end))
    )
    _check(a, w, d)
    peak = np.minimum(w, np.sqrt(a * d))
    ramp = peak / a
    cruise = np.where(peak < w, 0.0, (d - w * w / a) / w)
    total = 2.0 * ramp + cruise
    t_left = total - t
    in_up = (t >= 0.0) & (t < ramp)
    in_cruise = (t >= ramp) & (t < ramp + cruise)
    in_down = (t >= ramp + cruise) & (t < total)
    after = t >= total
    phi = np.select(
        [in_up, in_cruise, in_down, after],
        [
            0.5 * a * t * t,
            0.5 * a * ramp * ramp + peak * (t - ramp),
            d - 0.5 * a * t_left * t_left,
            d,
        ],
        0.0,
    )
    phi_dot = np.select([in_up, in_cruise, in_down], [a * t, peak, a * t_left], 0.0)
    phi_ddot = np.select([in_up, in_down], [a, -a], 0.0)
    return phi, phi_dot, phi_ddot
