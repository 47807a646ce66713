"""The joint estimator's kinematic model: raw odometry increments → hedgehog track.

Pure functions on arrays: increments, installed compensation undone, a truth applied, the
integrated hedgehog at the fix times; slip knots, motion content (docs/joint-calibration.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.estimation.se2 import transform_points
from omnical.kinematics.correction import (
    CorrectionFactors,
    compensate_twist,
    counter_compensate_twist,
)

__all__ = [
    "MotionContent",
    "hedge_track",
    "interpolate_track",
    "motion_content",
    "process_knots",
    "raw_increments",
    "real_increments",
    "real_increments_jacobian",
]

_Array = NDArray[np.float64]


def raw_increments(body: ArrayLike, installed: CorrectionFactors) -> _Array:
    """Undo the installed counter-compensation: the increments the nominal kinematics measured."""
    return compensate_twist(body, installed)


def real_increments(raw: ArrayLike, factors: CorrectionFactors) -> _Array:
    """The increments a plant with truth ``factors`` really makes for raw wheel increments."""
    return counter_compensate_twist(raw, factors)


def real_increments_jacobian(raw: ArrayLike, factors: CorrectionFactors) -> _Array:
    """(7, M, 3) ∂ :func:`real_increments` / ∂ factor, factors in field order.

    The plant divides by the scalings, then turns c rad per metre really travelled in each
    direction: ∂/∂k_x = (−x/k_x, 0, (c_fwd [x > 0] − c_rev [x < 0]) (−x/k_x)) with x the
    real dx (likewise for y), ∂/∂k_θ = (0, 0, −θ/k_θ) with θ the real dθ before cross-talk,
    ∂/∂c = (0, 0, distance in that direction).
    """
    r = np.asarray(raw, dtype=np.float64)
    kx, ky, kt = factors.scales
    c = factors.crosstalks_rad_per_m
    x, y, t = r[:, 0] / kx, r[:, 1] / ky, r[:, 2] / kt
    out = np.zeros((7, r.shape[0], 3))
    out[0, :, 0] = -x / kx
    out[0, :, 2] = np.where(x > 0.0, c[0], np.where(x < 0.0, -c[1], 0.0)) * (-x / kx)
    out[1, :, 1] = -y / ky
    out[1, :, 2] = np.where(y > 0.0, c[2], np.where(y < 0.0, -c[3], 0.0)) * (-y / ky)
    out[2, :, 2] = -t / kt
    out[3, :, 2] = np.maximum(x, 0.0)
    out[4, :, 2] = np.maximum(-x, 0.0)
    out[5, :, 2] = np.maximum(y, 0.0)
    out[6, :, 2] = np.maximum(-y, 0.0)
    return out


def hedge_track(poses: ArrayLike, offset_xy_m: ArrayLike) -> _Array:
    """(N, 2) hedgehog positions for poses (N, 3) and a mounting offset (x, y) in base_link."""
    return transform_points(poses, offset_xy_m)


def interpolate_track(t_s: ArrayLike, track_xy: ArrayLike, at_s: ArrayLike) -> _Array:
    """Linear interpolation of a (N, 2) track sampled at ``t_s`` (increasing) at times ``at_s``."""
    t = np.asarray(t_s, dtype=np.float64)
    xy = np.asarray(track_xy, dtype=np.float64)
    q = np.asarray(at_s, dtype=np.float64)
    return np.column_stack([np.interp(q, t, xy[:, 0]), np.interp(q, t, xy[:, 1])])


@dataclass(frozen=True)
class MotionContent:
    """How much of each motion a recording holds, as the odometry reported it.

    Attributes:
        forward_m, reverse_m, left_m, right_m: distance travelled with positive/negative body
            x and y (a diagonal move counts in both of its directions), m.
        rotation_rad: total absolute rotation, rad.
        path_m: total path length, m.
    """

    forward_m: float
    reverse_m: float
    left_m: float
    right_m: float
    rotation_rad: float
    path_m: float

    def __add__(self, other: MotionContent) -> MotionContent:
        """Content of two recordings together."""
        return MotionContent(
            self.forward_m + other.forward_m,
            self.reverse_m + other.reverse_m,
            self.left_m + other.left_m,
            self.right_m + other.right_m,
            self.rotation_rad + other.rotation_rad,
            self.path_m + other.path_m,
        )


def motion_content(
    increments: ArrayLike,
    dt_s: ArrayLike,
    *,
    min_speed_mps: float = 0.02,
    min_rate_radps: float = 0.02,
) -> MotionContent:
    """Distances per direction and total rotation of (M, 3) body increments.

    Components slower than ``min_speed_mps`` or ``min_rate_radps`` are left out (stand-still
    jitter, the cross-talk's yaw during translations).

    Args:
        increments: (M, 3) body-frame dx, dy, dθ.
        dt_s: (M,) duration of each increment, s.
        min_speed_mps: slowest translation speed counted, m/s.
        min_rate_radps: slowest yaw rate counted, rad/s.
    """
    inc = np.asarray(increments, dtype=np.float64)
    dt = np.maximum(np.asarray(dt_s, dtype=np.float64), 1e-9)
    dx = np.where(np.abs(inc[:, 0]) >= min_speed_mps * dt, inc[:, 0], 0.0)
    dy = np.where(np.abs(inc[:, 1]) >= min_speed_mps * dt, inc[:, 1], 0.0)
    dth = np.where(np.abs(inc[:, 2]) >= min_rate_radps * dt, inc[:, 2], 0.0)
    return MotionContent(
        forward_m=float(np.sum(np.maximum(dx, 0.0))),
        reverse_m=float(np.sum(np.maximum(-dx, 0.0))),
        left_m=float(np.sum(np.maximum(dy, 0.0))),
        right_m=float(np.sum(np.maximum(-dy, 0.0))),
        rotation_rad=float(np.sum(np.abs(dth))),
        path_m=float(np.sum(np.hypot(dx, dy))),
    )


def process_knots(
    increments: ArrayLike,
    *,
    heading_noise_rad_per_sqrt_rad: float,
    heading_noise_rad_per_sqrt_m: float,
    position_noise_m_per_sqrt_m: float,
    cross_noise_m_per_sqrt_m: float,
    spacing_m: float = 1.0,
    spacing_rad: float = 1.0,
    min_travel_m: float = 0.05,
) -> tuple[NDArray[np.intp], NDArray[np.intp], _Array, _Array, _Array]:
    """Where the odometry's random errors (slip) are modelled, and their prior σ there.

    The motion is cut into chunks of about ``spacing_m`` or ``spacing_rad``; each gets one
    perturbation per component (along, across, dθ) at its middle increment, prior variance
    ``σ_p² s``, ``σ_c² s``, ``σ_r² |θ| + σ_t² s`` (s, θ: the chunk's travel and rotation).
    Chunks travelling less than ``min_travel_m`` get no position perturbation.

    Args:
        increments: (M, 3) body increments as the odometry reports them.
        heading_noise_rad_per_sqrt_rad: σ_r, heading noise per square root of radian turned.
        heading_noise_rad_per_sqrt_m: σ_t, heading noise per square root of metre travelled.
        position_noise_m_per_sqrt_m: σ_p, position noise along the travel per square root of
            metre.
        cross_noise_m_per_sqrt_m: σ_c, position noise across the travel per square root of
            metre.
        spacing_m: travel per chunk, m.
        spacing_rad: rotation per chunk, rad.
        min_travel_m: least travel of a chunk for position perturbations, m.

    Returns:
        (K,) increment index, (K,) component (0 = along, 1 = across, 2 = dθ), (K,) prior σ of
        each perturbation (m or rad, all > 0), (K,) body-frame direction of "along" (rad) and
        (K,) the share of each prior variance that is slip along the motion (σ_p², σ_r²; the
        rest, σ_c², σ_t², is across), ordered by index then component.
    """
    inc = np.asarray(increments, dtype=np.float64)
    dist = np.hypot(inc[:, 0], inc[:, 1])
    rot = np.abs(inc[:, 2])
    var_h = heading_noise_rad_per_sqrt_rad**2 * rot + heading_noise_rad_per_sqrt_m**2 * dist
    measure = dist / spacing_m + rot / spacing_rad
    total = np.concatenate([[0.0], np.cumsum(measure)])
    var_r = heading_noise_rad_per_sqrt_rad**2 * rot
    empty = (
        np.zeros(0, dtype=np.intp),
        np.zeros(0, dtype=np.intp),
        np.zeros(0),
        np.zeros(0),
        np.zeros(0),
    )
    if not total[-1] > 0.0:
        return empty
    moving = np.flatnonzero(measure > 0.0)
    chunk = np.floor(total[moving] + 0.5 * measure[moving]).astype(np.int64)
    starts = np.flatnonzero(np.concatenate([[True], np.diff(chunk) != 0]))
    stops = np.concatenate([starts[1:], [moving.size]])
    index: list[int] = []
    comp: list[int] = []
    sigma: list[float] = []
    direction: list[float] = []
    share: list[float] = []
    for a, b in zip(starts, stops, strict=True):
        members = moving[a:b]
        acc = np.cumsum(measure[members])
        k = int(members[min(int(np.searchsorted(acc, 0.5 * acc[-1])), members.size - 1)])
        travel = float(np.sum(dist[members]))
        if travel >= min_travel_m:
            along = math.atan2(float(np.sum(inc[members, 1])), float(np.sum(inc[members, 0])))
            for c, density in ((0, position_noise_m_per_sqrt_m), (1, cross_noise_m_per_sqrt_m)):
                if density > 0.0:
                    index.append(k)
                    comp.append(c)
                    sigma.append(density * math.sqrt(travel))
                    direction.append(along)
                    share.append(1.0 if c == 0 else 0.0)
        vh = float(np.sum(var_h[members]))
        if vh > 0.0:
            index.append(k)
            comp.append(2)
            sigma.append(math.sqrt(vh))
            direction.append(0.0)
            share.append(min(float(np.sum(var_r[members])) / vh, 1.0))
    if not index:
        return empty
    return (
        np.array(index, dtype=np.intp),
        np.array(comp, dtype=np.intp),
        np.array(sigma),
        np.array(direction),
        np.array(share),
    )
