"""Before a real robot moves: does the path stay inside the beacon coverage and the allowed area?

:func:`check_path` dead-reckons a script's commanded twist from the start pose
(:func:`~omnical.calibration.procedures.nominal_path`) and measures how far it stays inside the
convex hull of the beacons (:func:`~omnical.calibration.procedures.hull_margin_m`) and inside the
user's rectangle. :func:`shrink_to_fit` asks a procedure factory for smaller and smaller versions
until one fits, or refuses with the reason.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from omnical.calibration.procedures import hull_margin_m, nominal_path
from omnical.errors import LimitError
from omnical.experiment.script import MotionScript
from omnical.ips.beacons import BeaconMap

__all__ = ["Area", "PathCheck", "check_path", "shrink_to_fit"]


@dataclass(frozen=True)
class Area:
    """An axis-aligned rectangle of the map the robot may use, m."""

    x_min: float
    y_min: float
    x_max: float
    y_max: float

    def margin_m(self, xy: np.ndarray) -> float:
        """Smallest distance of the points to the rectangle's border (negative: outside)."""
        d = np.minimum.reduce(
            [
                xy[:, 0] - self.x_min,
                self.x_max - xy[:, 0],
                xy[:, 1] - self.y_min,
                self.y_max - xy[:, 1],
            ]
        )
        return float(np.min(d))


@dataclass(frozen=True)
class PathCheck:
    """The verdict on a path.

    Attributes:
        ok: inside both with the margin.
        coverage_margin_m: smallest distance inside the beacons' hull (negative: leaves it).
        area_margin_m: smallest distance inside the allowed area (None: no area given).
        reason: why not, in one line ("" if ok).
    """

    ok: bool
    coverage_margin_m: float
    area_margin_m: float | None
    reason: str


def check_path(
    script: MotionScript,
    start_pose_map: Sequence[float],
    beacons: BeaconMap,
    *,
    margin_m: float = 0.3,
    allowed: Area | None = None,
) -> PathCheck:
    """Check the nominal path of ``script`` from ``start_pose_map`` (x, y, yaw)."""
    path = nominal_path(script, tuple(start_pose_map), step_s=0.02)
    cover = hull_margin_m(path[:, :2], beacons)
    area = allowed.margin_m(path[:, :2]) if allowed is not None else None
    reasons = []
    if cover < margin_m:
        reasons.append(
            f"the path of {script.name!r} comes {cover:+.2f} m from the edge of the beacon "
            f"coverage (needs ≥ {margin_m:.2f} m inside)"
        )
    if area is not None and area < margin_m:
        reasons.append(
            f"the path of {script.name!r} comes {area:+.2f} m from the edge of the allowed area "
            f"(needs ≥ {margin_m:.2f} m inside)"
        )
    return PathCheck(not reasons, cover, area, "; ".join(reasons))


def shrink_to_fit(
    make: Callable[[float], MotionScript],
    start_pose_map: Sequence[float],
    beacons: BeaconMap,
    *,
    margin_m: float = 0.3,
    allowed: Area | None = None,
    min_scale: float = 0.25,
) -> tuple[MotionScript, float]:
    """The largest version of a procedure (``make(scale)``, scale ≤ 1) whose path fits.

    Raises:
        LimitError: even ``make(min_scale)`` does not fit; the message gives the reason.
    """
    full = make(1.0)
    verdict = check_path(full, start_pose_map, beacons, margin_m=margin_m, allowed=allowed)
    if verdict.ok:
        return full, 1.0
    lo, hi = min_scale, 1.0
    small = check_path(make(lo), start_pose_map, beacons, margin_m=margin_m, allowed=allowed)
    if not small.ok:
        msg = f"refused: even at {lo:.0%} of its size, {small.reason}"
        raise LimitError(msg)
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        if check_path(make(mid), start_pose_map, beacons, margin_m=margin_m, allowed=allowed).ok:
            lo = mid
        else:
            hi = mid
    return make(lo), lo
