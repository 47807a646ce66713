"""A simulated 2D LiDAR (RPLidar-like) over the twin's ground truth in a floor plan.

:func:`simulate_scans` gives every scan of a run post hoc, :meth:`Lidar.scan` one pose at a time:
exact ray casts with noise, quantisation and dropouts; ranges as REP 117 (docs/DESIGN-NOTES.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError
from omnical.estimation.se2 import compose_poses, interpolate_poses
from omnical.navigation.grid import OccupancyGrid
from omnical.navigation.raycast import cast_rays

__all__ = ["Lidar", "LidarParams", "LidarScans", "simulate_scans"]


@dataclass(frozen=True)
class LidarParams:
    """An RPLidar-A-class 2D scanner (defaults: 360 beams, 12 m, ≈ 1 cm noise, 10 Hz).

    Attributes:
        beams: beams per revolution, evenly spaced from ``angle_min_rad``.
        angle_min_rad: angle of the first beam in the sensor frame.
        range_min_m, range_max_m: valid range interval (shorter returns are -inf, REP 117).
        range_sigma_m: σ of the Gaussian range noise.
        range_resolution_m: quantisation of the reported range (0 = none).
        dropout_probability: probability a beam with a return reports NaN.
        rate_hz: revolutions per second (5.5–10 Hz for an RPLidar A1/A2).
        mount_pose: (x m, y m, yaw rad) of the sensor in base_link.
        frame_id: frame of the scans.
    """

    beams: int = 360
    angle_min_rad: float = -math.pi
    range_min_m: float = 0.15
    range_max_m: float = 12.0
    range_sigma_m: float = 0.01
    range_resolution_m: float = 0.001
    dropout_probability: float = 0.01
    rate_hz: float = 10.0
    mount_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    frame_id: str = "laser"

    def __post_init__(self) -> None:
        if self.beams < 1:
            msg = f"lidar beams must be >= 1, got {self.beams}"
            raise ConfigError(msg)
        if not 0.0 <= self.range_min_m < self.range_max_m or not math.isfinite(self.range_max_m):
            msg = f"lidar range interval must be 0 <= min < max, got {self.range_min_m}, {self.range_max_m}"
            raise ConfigError(msg)
        for name in ("range_sigma_m", "range_resolution_m"):
            if not getattr(self, name) >= 0.0:
                msg = f"lidar {name} must be >= 0, got {getattr(self, name)}"
                raise ConfigError(msg)
        if not 0.0 <= self.dropout_probability < 1.0:
            msg = f"lidar dropout_probability must be in [0, 1), got {self.dropout_probability}"
            raise ConfigError(msg)
        if not (math.isfinite(self.rate_hz) and self.rate_hz > 0.0):
            msg = f"lidar rate_hz must be finite and > 0, got {self.rate_hz}"
            raise ConfigError(msg)

    @classmethod
    def ideal(cls, **changes: object) -> LidarParams:
        """A noiseless LiDAR without dropouts."""
        base = {"range_sigma_m": 0.0, "range_resolution_m": 0.0, "dropout_probability": 0.0}
        return cls(**{**base, **changes})  # type: ignore[arg-type]

    @property
    def angle_increment_rad(self) -> float:
        """Angle between beams."""
        return 2.0 * math.pi / self.beams

    @property
    def angles_rad(self) -> NDArray[np.float64]:
        """(beams,) beam angles in the sensor frame."""
        return np.asarray(
            self.angle_min_rad + self.angle_increment_rad * np.arange(self.beams), dtype=np.float64
        )


@dataclass(frozen=True, eq=False)
class LidarScans:
    """Scans of a run, one row per revolution (``sensor_msgs/LaserScan`` content).

    Attributes:
        t_s: (M,) time of each scan.
        ranges_m: (M, beams) ranges; NaN = dropout, +inf = no return, -inf = too close.
        params: the sensor (beam angles, range limits, mounting pose).
        true_pose: (M, 3) true base_link pose of each scan in the world (for evaluation).
    """

    t_s: NDArray[np.float64]
    ranges_m: NDArray[np.float64]
    params: LidarParams
    true_pose: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    def points_base(self, k: int) -> NDArray[np.float64]:
        """(P, 2) valid returns of scan ``k`` in base_link."""
        return scan_points(self.ranges_m[k], self.params)


def scan_points(ranges_m: ArrayLike, params: LidarParams) -> NDArray[np.float64]:
    """(P, 2) the finite returns of one scan in base_link."""
    r = np.asarray(ranges_m, dtype=np.float64)
    ok = np.isfinite(r)
    mx, my, myaw = params.mount_pose
    c, s = math.cos(myaw), math.sin(myaw)
    sx, sy = r[ok] * np.cos(params.angles_rad[ok]), r[ok] * np.sin(params.angles_rad[ok])
    return np.column_stack([mx + c * sx - s * sy, my + s * sx + c * sy])


class Lidar:
    """The LiDAR in a floor plan, one pose at a time (for closed loops).

    Args:
        world: the floor plan (occupied cells reflect).
        params: the sensor.
        seed: seed of the noise and dropouts.
    """

    def __init__(self, world: OccupancyGrid, params: LidarParams, seed: int = 0) -> None:
        self.world = world
        self.params = params
        self._rng = np.random.default_rng([seed, 0x11DA])
        self._blocked = world.occupied

    def true_ranges(self, poses: ArrayLike) -> NDArray[np.float64]:
        """(M, beams) noiseless ranges from base_link poses (M, 3) in the world."""
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        sensor = compose_poses(p, np.asarray(self.params.mount_pose))
        beams = self.params.beams
        origins = np.repeat(sensor[:, :2], beams, axis=0)
        angles = (sensor[:, 2:3] + self.params.angles_rad[None, :]).ravel()
        r = cast_rays(self.world, origins, angles, self.params.range_max_m, blocked=self._blocked)
        return r.reshape(p.shape[0], beams)

    def measure(self, true_ranges: NDArray[np.float64]) -> NDArray[np.float64]:
        """Add noise, quantisation, dropouts and the range limits to true ranges."""
        p = self.params
        r = np.array(true_ranges, dtype=np.float64)
        hit = np.isfinite(r)
        if p.range_sigma_m > 0.0:
            r[hit] += self._rng.normal(0.0, p.range_sigma_m, int(hit.sum()))
        if p.range_resolution_m > 0.0:
            r[hit] = np.round(r[hit] / p.range_resolution_m) * p.range_resolution_m
        r[hit & (r > p.range_max_m)] = np.inf
        r[hit & (r < p.range_min_m)] = -np.inf
        if p.dropout_probability > 0.0:
            drop = self._rng.random(r.shape) < p.dropout_probability
            r[drop & hit] = np.nan
        return r

    def scan(self, pose: ArrayLike) -> NDArray[np.float64]:
        """(beams,) one measured scan from a base_link pose (x, y, yaw) in the world."""
        return np.asarray(self.measure(self.true_ranges(pose))[0], dtype=np.float64)


def simulate_scans(
    t_s: ArrayLike,
    true_poses: ArrayLike,
    world: OccupancyGrid,
    params: LidarParams | None = None,
    *,
    seed: int = 0,
) -> LidarScans:
    """Every scan of a run, from the true base_link trajectory (e.g. the twin's ground truth).

    Scans start at the first time and follow at ``params.rate_hz``.
    """
    lp = params or LidarParams()
    t = np.asarray(t_s, dtype=np.float64)
    if t.shape[0] < 1:
        msg = "simulate_scans: empty trajectory"
        raise ConfigError(msg)
    times = np.arange(t[0], t[-1] + 1e-9, 1.0 / lp.rate_hz)
    poses = interpolate_poses(t, true_poses, times)
    lidar = Lidar(world, lp, seed)
    ranges = lidar.measure(lidar.true_ranges(poses))
    return LidarScans(times, ranges, lp, poses)
