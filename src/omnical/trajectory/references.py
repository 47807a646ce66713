"""Reference trajectories: the test paths of the seeds as time-parameterised poses and twists.

:func:`lissajous` (seed 000 Eq. 5), :func:`circle`, :func:`polygon`, :func:`waypoints`: poses of
``base_link`` in ``map`` (yaw continuous) and body twists, starting and ending at rest.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError
from omnical.estimation.se2 import rotate_xy, wrap_angle
from omnical.trajectory.profiles import phase_profile, profile_duration

__all__ = [
    "SEED001_SQUARE_M",
    "SEED003_SQUARE_M",
    "SEED003_TRIANGLE_M",
    "Reference",
    "circle",
    "lissajous",
    "polygon",
    "waypoints",
]

FloatArray = NDArray[np.float64]
PoseTwistFn = Callable[[FloatArray], tuple[FloatArray, FloatArray]]

#: Seed 001 §4.2.2: a square with 1 m sides (counter-clockwise; the paper states no sense).
SEED001_SQUARE_M: tuple[tuple[float, float], ...] = ((0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0))
#: Seed 003 §IV.B.3a: X = {0, 120, 120, 0, 0} cm, Y = {0, 0, −120, −120, 0} cm.
SEED003_SQUARE_M: tuple[tuple[float, float], ...] = (
    (0.0, 0.0),
    (1.2, 0.0),
    (1.2, -1.2),
    (0.0, -1.2),
)
#: Seed 003 §IV.B.3b: X = {0, 120, 60, 0} cm, Y = {0, 0, 60, 0} cm.
SEED003_TRIANGLE_M: tuple[tuple[float, float], ...] = ((0.0, 0.0), (1.2, 0.0), (0.6, 0.6))


@dataclass(frozen=True, eq=False)
class Reference:
    """A reference trajectory, sampled and evaluable at any time.

    Attributes:
        name: label ("lissajous", "circle", "polygon", ...).
        t_s: (N,) sample times from 0 to the end, spaced ``dt_s`` (the last interval may be shorter).
        poses: (N, 3) x m, y m, yaw rad of ``base_link`` in ``map``.
        body_twists: (N, 3) vx m/s, vy m/s, wz rad/s in ``base_link``.
        evaluate: times (M,) → (poses (M, 3), body twists (M, 3)); at rest before 0 and after the end.
    """

    name: str
    t_s: FloatArray
    poses: FloatArray
    body_twists: FloatArray
    evaluate: PoseTwistFn = field(repr=False)

    @property
    def duration_s(self) -> float:
        """Time from the start to the end of the motion."""
        return float(self.t_s[-1])

    def at(self, t_s: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Poses (M, 3) and body twists (M, 3) at times ``t_s`` (M,)."""
        return self.evaluate(np.atleast_1d(np.asarray(t_s, dtype=np.float64)))

    def resampled(self, dt_s: float) -> Reference:
        """The same reference sampled every ``dt_s`` seconds."""
        return _sampled(self.name, self.duration_s, self.evaluate, dt_s)


def _time_grid(duration_s: float, dt_s: float) -> FloatArray:
    if not (math.isfinite(dt_s) and dt_s > 0.0):
        msg = f"sample period dt_s must be finite and > 0, got {dt_s}"
        raise ConfigError(msg)
    t = np.arange(0.0, duration_s, dt_s)
    if t.size == 0 or duration_s - t[-1] > 1e-9 * max(1.0, duration_s):
        t = np.append(t, duration_s)
    else:
        t[-1] = duration_s
    return t


def _sampled(name: str, duration_s: float, evaluate: PoseTwistFn, dt_s: float) -> Reference:
    t = _time_grid(duration_s, dt_s)
    poses, twists = evaluate(t)
    return Reference(name, t, poses, twists, evaluate)


def _pack(
    xy_map: FloatArray, yaw: FloatArray, v_map: FloatArray, wz: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Poses (N, 3) and body twists (N, 3) from map positions (N, 2), velocities (N, 2), yaw, wz."""
    return np.column_stack([xy_map, yaw]), np.column_stack([rotate_xy(-yaw, v_map), wz])


def lissajous(
    *,
    scale_m: float = 1.0,
    phase_accel_radps2: float = 0.03,
    phase_rate_radps: float = 0.09,
    heading_offset_rad: float = math.pi / 2,
    origin_m: tuple[float, float] = (0.0, 0.0),
    rotation_rad: float = 0.0,
    dt_s: float = 0.02,
) -> Reference:
    """The Lissajous curve of seed 000 §4.2 (Eq. 5–6) with the trapezoidal phase law.

    Path frame: x = S sin 2φ, y = S cos φ, φ ∈ [0, 2π], starting and ending at (0, S); velocity
    S φ̇ (2 cos 2φ, −sin φ) (Eq. 6); constant yaw ``rotation_rad + heading_offset_rad``, wz = 0.

    Args:
        scale_m: S.
        phase_accel_radps2: A, the phase acceleration of the ramps.
        phase_rate_radps: Ω, the cruise phase rate.
        heading_offset_rad: robot yaw relative to the path frame (π/2: rotated 90° CCW as in seed 000).
        origin_m: path-frame origin in ``map``.
        rotation_rad: path-frame rotation in ``map``.
        dt_s: sample period of the returned arrays.

    Raises:
        ConfigError: a non-positive scale, acceleration, rate or sample period.
    """
    if not (math.isfinite(scale_m) and scale_m > 0.0):
        msg = f"Lissajous scale S must be finite and > 0, got {scale_m}"
        raise ConfigError(msg)
    phi_end = 2.0 * math.pi
    duration = profile_duration(phase_accel_radps2, phase_rate_radps, phi_end)
    yaw = rotation_rad + heading_offset_rad

    def evaluate(t: FloatArray) -> tuple[FloatArray, FloatArray]:
        phi, phi_dot, _ = phase_profile(t, phase_accel_radps2, phase_rate_radps, phi_end)
        xy_path = scale_m * np.column_stack([np.sin(2.0 * phi), np.cos(phi)])
        v_path = (
            scale_m * phi_dot[:, None] * np.column_stack([2.0 * np.cos(2.0 * phi), -np.sin(phi)])
        )
        xy = rotate_xy(rotation_rad, xy_path) + np.asarray(origin_m)
        return _pack(
            xy, np.full_like(phi, yaw), rotate_xy(rotation_rad, v_path), np.zeros_like(phi)
        )

    return _sampled("lissajous", duration, evaluate, dt_s)


def circle(
    *,
    radius_m: float = 1.0,
    speed_mps: float = 0.1,
    accel_mps2: float = 0.05,
    center_m: tuple[float, float] = (0.0, 0.0),
    start_angle_rad: float = -math.pi / 2,
    turns: float = 1.0,
    clockwise: bool = False,
    heading_rad: float = 0.0,
    face_tangent: bool = False,
    dt_s: float = 0.02,
) -> Reference:
    """A circle (seed 001 §4.2.1: radius 1 m, counter-clockwise, at most 0.1 m/s).

    The arc length follows the trapezoidal law (A = ``accel_mps2``, Ω = ``speed_mps``).

    Args:
        radius_m: circle radius.
        speed_mps: cruise speed along the circle.
        accel_mps2: tangential acceleration of the ramps.
        center_m: circle centre in ``map``.
        start_angle_rad: polar angle of the start point about the centre.
        turns: number of turns (> 0).
        clockwise: direction of travel.
        heading_rad: constant yaw in ``map``, or yaw relative to the tangent with ``face_tangent``.
        face_tangent: turn the robot with the path.
        dt_s: sample period of the returned arrays.

    Raises:
        ConfigError: a non-positive radius, speed, acceleration, number of turns or sample period.
    """
    if not (math.isfinite(radius_m) and radius_m > 0.0):
        msg = f"circle radius must be finite and > 0, got {radius_m}"
        raise ConfigError(msg)
    if not (math.isfinite(turns) and turns > 0.0):
        msg = f"circle turns must be finite and > 0, got {turns}"
        raise ConfigError(msg)
    sense = -1.0 if clockwise else 1.0
    angle_end = 2.0 * math.pi * turns
    accel, rate = accel_mps2 / radius_m, speed_mps / radius_m
    duration = profile_duration(accel, rate, angle_end)

    def evaluate(t: FloatArray) -> tuple[FloatArray, FloatArray]:
        alpha, alpha_dot, _ = phase_profile(t, accel, rate, angle_end)
        theta = start_angle_rad + sense * alpha
        radial = np.column_stack([np.cos(theta), np.sin(theta)])
        xy = np.asarray(center_m) + radius_m * radial
        v = (radius_m * sense * alpha_dot)[:, None] * np.column_stack([-radial[:, 1], radial[:, 0]])
        if face_tangent:
            yaw = theta + sense * math.pi / 2 + heading_rad
            wz = sense * alpha_dot
        else:
            yaw, wz = np.full_like(theta, heading_rad), np.zeros_like(theta)
        return _pack(xy, yaw, v, wz)

    return _sampled("circle", duration, evaluate, dt_s)


def _positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0.0):
        msg = f"{name} must be finite and > 0, got {value}"
        raise ConfigError(msg)


def _legs(
    poses: FloatArray, speed: float, accel: float, yaw_rate: float, yaw_accel: float, dwell_s: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, float]:
    """Progress-profile rates, accelerations, travels (0 or 1) and start times of each leg."""
    n = poses.shape[0] - 1
    rates, accels, travels, starts = np.ones(n), np.ones(n), np.zeros(n), np.zeros(n)
    t = 0.0
    for j in range(n):
        length = math.hypot(*(poses[j + 1, :2] - poses[j, :2]))
        turn = abs(poses[j + 1, 2] - poses[j, 2])
        caps = [(speed / length, accel / length)] if length > 0.0 else []
        caps += [(yaw_rate / turn, yaw_accel / turn)] if turn > 0.0 else []
        starts[j] = t
        if caps:
            rates[j], accels[j], travels[j] = min(c[0] for c in caps), min(c[1] for c in caps), 1.0
            t += profile_duration(accels[j], rates[j], 1.0) + (dwell_s if j < n - 1 else 0.0)
    return rates, accels, travels, starts, t


def waypoints(
    points: Sequence[Sequence[float]],
    *,
    speed_mps: float = 0.1,
    accel_mps2: float = 0.1,
    yaw_rate_radps: float = 0.5,
    yaw_accel_radps2: float = 0.5,
    dwell_s: float = 0.0,
    heading_rad: float = 0.0,
    name: str = "waypoints",
    dt_s: float = 0.02,
) -> Reference:
    """Straight legs through way-points, at rest at each one.

    Each leg moves along the straight line while the yaw turns (the shorter way) to the next
    point's yaw, one trapezoidal progress law bounding speed, yaw rate and both accelerations.
    A point given as (x, y) keeps the previous yaw (``heading_rad`` at the start).

    Args:
        points: (x m, y m) or (x m, y m, yaw rad) per way-point, at least two; the first is the start.
        speed_mps: cruise speed on a leg.
        accel_mps2: acceleration of the speed ramps.
        yaw_rate_radps: cruise yaw rate on a leg that turns.
        yaw_accel_radps2: yaw acceleration of those ramps.
        dwell_s: standing time at each intermediate way-point.
        heading_rad: yaw at the start when the first point has none.
        name: label of the reference.
        dt_s: sample period of the returned arrays.

    Raises:
        ConfigError: fewer than two points, a point without 2 or 3 coordinates, non-positive rates.
    """
    for label, value in (
        ("speed_mps", speed_mps),
        ("accel_mps2", accel_mps2),
        ("yaw_rate_radps", yaw_rate_radps),
        ("yaw_accel_radps2", yaw_accel_radps2),
    ):
        _positive(label, value)
    if not (math.isfinite(dwell_s) and dwell_s >= 0.0):
        msg = f"dwell_s must be finite and >= 0, got {dwell_s}"
        raise ConfigError(msg)
    if len(points) < 2:
        msg = f"a way-point path needs at least 2 points, got {len(points)}"
        raise ConfigError(msg)
    poses = np.zeros((len(points), 3))
    yaw = heading_rad
    for i, p in enumerate(points):
        if len(p) not in (2, 3) or not all(math.isfinite(v) for v in p):
            msg = f"way-point {i}: expected finite (x, y) or (x, y, yaw), got {tuple(p)}"
            raise ConfigError(msg)
        if len(p) == 3:
            yaw = p[2] if i == 0 else yaw + wrap_angle(p[2] - yaw)
        poses[i] = (p[0], p[1], yaw)
    rates, accels, travels, starts, duration = _legs(
        poses, speed_mps, accel_mps2, yaw_rate_radps, yaw_accel_radps2, dwell_s
    )
    delta = np.diff(poses, axis=0)

    def evaluate(t: FloatArray) -> tuple[FloatArray, FloatArray]:
        j = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
        s, s_dot, _ = phase_profile(t - starts[j], accels[j], rates[j], travels[j])
        p = poses[j] + s[:, None] * delta[j]
        v = s_dot[:, None] * delta[j]
        return _pack(p[:, :2], p[:, 2], v[:, :2], v[:, 2])

    return _sampled(name, duration, evaluate, dt_s)


def polygon(
    vertices: Sequence[Sequence[float]],
    *,
    speed_mps: float = 0.1,
    accel_mps2: float = 0.1,
    dwell_s: float = 1.0,
    heading_rad: float = 0.0,
    closed: bool = True,
    face_travel: bool = False,
    yaw_rate_radps: float = 0.5,
    yaw_accel_radps2: float = 0.5,
    dt_s: float = 0.02,
) -> Reference:
    """A polygon of straight legs (seed 001 square 1 m, seed 003 square 1.2 m and triangle).

    By default the robot keeps the yaw ``heading_rad`` and translates; with ``face_travel`` it
    turns in place at each vertex to face the next leg (seed 001's way-point controller).

    Args:
        vertices: (x m, y m) per vertex, at least two; the first is the start.
        speed_mps: cruise speed on a leg.
        accel_mps2: acceleration of the speed ramps.
        dwell_s: standing time at each vertex between legs (and around each turn).
        heading_rad: constant yaw, or yaw relative to the direction of travel with ``face_travel``.
        closed: return to the first vertex at the end.
        face_travel: turn to face each leg before driving it.
        yaw_rate_radps: cruise yaw rate of the turns.
        yaw_accel_radps2: yaw acceleration of the turns.
        dt_s: sample period of the returned arrays.

    Raises:
        ConfigError: fewer than two vertices, a vertex that is not (x, y), non-positive rates.
    """
    verts = [tuple(float(c) for c in v) for v in vertices]
    if any(len(v) != 2 for v in verts):
        msg = f"polygon vertices must be (x, y) pairs, got {verts}"
        raise ConfigError(msg)
    if closed and len(verts) >= 2 and verts[-1] != verts[0]:
        verts.append(verts[0])
    points: list[Sequence[float]] = list(verts)
    if face_travel and len(verts) >= 2:
        points = []
        for a, b in itertools.pairwise(verts):
            yaw = math.atan2(b[1] - a[1], b[0] - a[0]) + heading_rad
            points += [(a[0], a[1], yaw), (b[0], b[1], yaw)]
    return waypoints(
        points,
        speed_mps=speed_mps,
        accel_mps2=accel_mps2,
        yaw_rate_radps=yaw_rate_radps,
        yaw_accel_radps2=yaw_accel_radps2,
        dwell_s=dwell_s,
        heading_rad=heading_rad,
        name="polygon",
        dt_s=dt_s,
    )
