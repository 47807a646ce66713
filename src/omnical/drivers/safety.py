"""Before a real robot moves: does the path stay inside the beacon coverage and the allowed area?

:func:`check_points` (a path), :func:`check_path` (a script's dead-reckoned path) and
:func:`shrink_to_fit` (smaller procedures until one fits) refuse saying where and why.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from omnical.calibration.procedures.scripts import hull_equations, hull_margins_m, nominal_path
from omnical.errors import LimitError
from omnical.experiment.script import MotionScript
from omnical.ips.beacons import BeaconMap

__all__ = ["Area", "PathCheck", "check_path", "check_points", "fitting_start", "shrink_to_fit"]

_EXACTLY_M = 1e-9
"""A path exactly at the margin fits (its rounding must not refuse it)."""


@dataclass(frozen=True)
class Area:
    """An axis-aligned rectangle of the map the robot may use, m."""

    x_min: float
    y_min: float
    x_max: float
    y_max: float

    def margin_m(self, xy: np.ndarray) -> float:
        """Smallest distance of the points to the rectangle's border (negative: outside)."""
        return float(np.min(self.margins_m(xy)))

    def margins_m(self, xy: np.ndarray) -> NDArray[np.float64]:
        """(N,) each point's distance to the rectangle's border (negative: outside)."""
        d = np.minimum.reduce(
            [
                xy[:, 0] - self.x_min,
                self.x_max - xy[:, 0],
                xy[:, 1] - self.y_min,
                self.y_max - xy[:, 1],
            ]
        )
        return np.asarray(d, dtype=np.float64)


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
    return check_points(
        path[:, :2],
        beacons,
        margin_m=margin_m,
        allowed=allowed,
        name=repr(script.name),
        start_xy_m=(float(start_pose_map[0]), float(start_pose_map[1])),
    )


def check_points(
    path_xy_m: NDArray[np.float64],
    beacons: BeaconMap,
    *,
    margin_m: float = 0.3,
    allowed: Area | None = None,
    name: str = "the path",
    start_xy_m: tuple[float, float] | None = None,
) -> PathCheck:
    """Check a dense path (N, 2) in the map against the coverage and ``allowed``.

    A refusal names the point where the path comes closest to (or furthest over) each edge and,
    with ``start_xy_m``, the nearest start from which the same path would fit.
    """
    xy = np.asarray(path_xy_m, dtype=np.float64).reshape(-1, 2)
    inside = hull_margins_m(xy, beacons)
    cover = float(np.min(inside))
    area = allowed.margin_m(xy) if allowed is not None else None
    reasons = []
    if not cover >= margin_m - _EXACTLY_M:  # NaN anywhere refuses
        wx, wy = xy[int(np.argmin(inside))]
        reasons.append(
            f"the path of {name} comes {cover:+.2f} m from the edge of the beacon coverage at "
            f"({wx:.2f}, {wy:.2f}) m (needs ≥ {margin_m:.2f} m inside)"
        )
    if area is not None and allowed is not None and not area >= margin_m - _EXACTLY_M:
        wx, wy = xy[int(np.argmin(allowed.margins_m(xy)))]
        reasons.append(
            f"the path of {name} comes {area:+.2f} m from the edge of the allowed area at "
            f"({wx:.2f}, {wy:.2f}) m (needs ≥ {margin_m:.2f} m inside)"
        )
    if reasons and start_xy_m is not None:
        start = np.asarray(start_xy_m, dtype=np.float64)
        fits = fitting_start(xy, start_xy_m, beacons, margin_m=margin_m, allowed=allowed)
        if fits is None:
            reasons.append("it fits from no start: make it smaller or widen the coverage")
        else:
            away = float(np.hypot(*(np.asarray(fits) - start)))
            reasons.append(
                f"it would fit from a start at ({fits[0]:.2f}, {fits[1]:.2f}) m, "
                f"{away:.2f} m from here, same heading"
            )
    return PathCheck(not reasons, cover, area, "; ".join(reasons))


def fitting_start(
    path_xy_m: NDArray[np.float64],
    start_xy_m: tuple[float, float],
    beacons: BeaconMap,
    *,
    margin_m: float,
    allowed: Area | None = None,
    step_m: float = 0.05,
) -> tuple[float, float] | None:
    """The start nearest ``start_xy_m`` from which the path (N, 2), started at ``start_xy_m``
    and moved whole, stays ``margin_m`` inside the coverage and ``allowed``; None if none does.

    A moved path's margin to each hull edge is the edge's worst point moved: the search over
    starts (a ``step_m`` grid over the beacons' extent) needs one dot product per edge.
    """
    here = np.asarray(start_xy_m, dtype=np.float64)
    rel = np.asarray(path_xy_m, dtype=np.float64).reshape(-1, 2) - here
    eq = hull_equations(beacons)
    worst = np.max(rel @ eq[:, :2].T, axis=0) + eq[:, 2]  # (F,) each edge's worst point
    b = beacons.positions_m[:, :2]  # the grid: steps from here, over the beacons' extent
    lo_k = np.floor((b.min(axis=0) - here) / step_m)
    hi_k = np.ceil((b.max(axis=0) - here) / step_m)
    xs = here[0] + step_m * np.arange(lo_k[0], hi_k[0] + 1)
    ys = here[1] + step_m * np.arange(lo_k[1], hi_k[1] + 1)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    margin_m -= _EXACTLY_M
    ok = np.min(-(grid @ eq[:, :2].T + worst), axis=1) >= margin_m
    if allowed is not None:
        lo, hi = rel.min(axis=0), rel.max(axis=0)
        ok &= (grid[:, 0] + lo[0] - allowed.x_min >= margin_m) & (
            allowed.x_max - grid[:, 0] - hi[0] >= margin_m
        )
        ok &= (grid[:, 1] + lo[1] - allowed.y_min >= margin_m) & (
            allowed.y_max - grid[:, 1] - hi[1] >= margin_m
        )
    if not ok.any():
        return None
    best = grid[ok][int(np.argmin(np.hypot(*(grid[ok] - here).T)))]
    return float(best[0]), float(best[1])


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
