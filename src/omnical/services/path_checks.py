"""Safety checks of a path before a robot moves: a polyline, or a task's reference path placed
at the robot's start, must stay inside the beacon coverage and the allowed area by a margin.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from omnical.drivers.safety import Area, PathCheck, check_points
from omnical.estimation.se2 import Pose2, transform_points
from omnical.ips.beacons import BeaconMap

__all__ = [
    "check_polyline",
    "check_task_path",
]


def check_polyline(
    points_map: NDArray[np.float64],
    beacons: BeaconMap,
    *,
    margin_m: float = 0.3,
    allowed: Area | None = None,
    name: str = "the path",
    start_xy_m: tuple[float, float] | None = None,
) -> PathCheck:
    """Check a polyline in the map (its corners, (P, 2)), sampled every 2 cm: it must stay
    ``margin_m`` inside the convex hull of the beacons and inside ``allowed`` if given
    (:func:`~omnical.drivers.safety.check_points`)."""
    ref = np.asarray(points_map, dtype=np.float64).reshape(-1, 2)
    dense = [ref[:1]]
    for a, b in itertools.pairwise(ref):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) / 0.02))
        u = np.linspace(0.0, 1.0, n + 1)[1:, None]
        dense.append(a + u * (b - a))
    return check_points(
        np.concatenate(dense),
        beacons,
        margin_m=margin_m,
        allowed=allowed,
        name=name,
        start_xy_m=start_xy_m,
    )


def check_task_path(
    reference_m: Sequence[Sequence[float]],
    start_pose_map: Pose2,
    beacons: BeaconMap,
    *,
    margin_m: float = 0.3,
    allowed: Area | None = None,
    name: str = "the task",
) -> PathCheck:
    """Check a task's reference path (path frame, start point first) placed at the start pose
    (:func:`check_polyline`)."""
    ref = np.asarray(reference_m, dtype=np.float64).reshape(-1, 2)
    corners = transform_points(np.asarray(start_pose_map, dtype=np.float64), ref)
    return check_polyline(
        corners,
        beacons,
        margin_m=margin_m,
        allowed=allowed,
        name=repr(name),
        start_xy_m=(float(start_pose_map[0]), float(start_pose_map[1])),
    )
