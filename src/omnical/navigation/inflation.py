"""Obstacle inflation by a Euclidean distance transform (seed 001 §4.2.3).

A cell is blocked when an obstacle cell is nearer than the radius plus one cell; the radius is the
footprint's circumscribed one by default, the inscribed one for a robot that keeps its heading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from omnical.errors import ConfigError
from omnical.navigation.grid import OccupancyGrid

__all__ = ["Footprint", "InflatedMap", "inflate"]


@dataclass(frozen=True)
class Footprint:
    """A rectangular footprint centred on base_link (seed 001: "60 cm on every side").

    Attributes:
        length_m: along x of base_link.
        width_m: along y of base_link.
    """

    length_m: float = 0.6
    width_m: float = 0.6

    def __post_init__(self) -> None:
        for name in ("length_m", "width_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                msg = f"footprint {name} must be finite and > 0, got {v}"
                raise ConfigError(msg)

    @property
    def circumscribed_radius_m(self) -> float:
        """Half the diagonal."""
        return 0.5 * math.hypot(self.length_m, self.width_m)

    @property
    def inscribed_radius_m(self) -> float:
        """Half the shorter side."""
        return 0.5 * min(self.length_m, self.width_m)

    def corners(self) -> NDArray[np.float64]:
        """(4, 2) corners in base_link, counter-clockwise from the front left."""
        hx, hy = 0.5 * self.length_m, 0.5 * self.width_m
        return np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])


@dataclass(frozen=True, eq=False)
class InflatedMap:
    """A map and where the robot's centre may not go.

    Attributes:
        grid: the map.
        blocked: (rows, cols) True where the centre of the robot may not be.
        clearance_m: (rows, cols) distance from each cell centre to the nearest obstacle centre.
        radius_m: the inflation radius.
    """

    grid: OccupancyGrid
    blocked: NDArray[np.bool_]
    clearance_m: NDArray[np.float64]
    radius_m: float

    def blocked_at(self, xy_m: NDArray[np.float64]) -> NDArray[np.bool_]:
        """(...,) True where world points are blocked (outside the map counts as blocked)."""
        rc = self.grid.world_to_cell(xy_m)
        inside = self.grid.in_bounds(rc)
        out = np.ones(rc.shape[:-1], dtype=bool)
        out[inside] = self.blocked[rc[inside][:, 0], rc[inside][:, 1]]
        return out


def inflate(
    grid: OccupancyGrid,
    radius_m: float | None = None,
    *,
    footprint: Footprint | None = None,
    radius: Literal["circumscribed", "inscribed"] = "circumscribed",
    unknown_is_obstacle: bool = True,
) -> InflatedMap:
    """Inflate the obstacles of ``grid``.

    Args:
        grid: the map.
        radius_m: inflation radius; None = the footprint's ``radius``.
        footprint: the robot's footprint (default: 0.6 m × 0.6 m).
        radius: which footprint radius, "circumscribed" (default) or "inscribed".
        unknown_is_obstacle: unknown cells block like occupied ones (a planner stays in known
            free space).

    Raises:
        ConfigError: a negative radius or an unknown radius choice.
    """
    if radius_m is None:
        fp = footprint or Footprint()
        if radius == "circumscribed":
            radius_m = fp.circumscribed_radius_m
        elif radius == "inscribed":
            radius_m = fp.inscribed_radius_m
        else:
            msg = f"unknown inflation radius {radius!r}; use circumscribed or inscribed"
            raise ConfigError(msg)
    if not (math.isfinite(radius_m) and radius_m >= 0.0):
        msg = f"inflation radius must be finite and >= 0, got {radius_m}"
        raise ConfigError(msg)
    obstacle = grid.occupied | grid.unknown if unknown_is_obstacle else grid.occupied
    if obstacle.any():
        from scipy import ndimage  # here: a Footprint alone (ros2 twin's start) needs no SciPy

        dist = ndimage.distance_transform_edt(~obstacle) * grid.resolution_m
    else:
        dist = np.full(grid.shape, np.inf)
    clearance = np.asarray(dist, dtype=np.float64)
    blocked = clearance < radius_m + grid.resolution_m
    blocked.setflags(write=False)
    clearance.setflags(write=False)
    return InflatedMap(grid, blocked, clearance, float(radius_m))
