"""The calibration procedures of seed 000 §3.2 as motion scripts (Figure 7).

:func:`rotation_procedure`, :func:`longitudinal_procedure`, :func:`lateral_procedure` return script
mappings; :func:`nominal_path` and :func:`hull_margin_m` check that one fits the beacon map.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError
from omnical.experiment.script import MotionScript
from omnical.ips.beacons import BeaconMap
from omnical.kinematics.correction import CorrectionFactors, crosstalk_yaw_rate

__all__ = [
    "back_and_forth",
    "hold_step",
    "hull_equations",
    "hull_margin_m",
    "hull_margins_m",
    "lateral_procedure",
    "longitudinal_procedure",
    "nominal_path",
    "rotation_procedure",
]

_MIN_HOLD_S = 3.0


def _positive(name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0.0):
        msg = f"procedure parameter {name} must be a finite number > 0, got {value}"
        raise ConfigError(msg)
    return float(value)


def hold_step(duration_s: float, marker: str) -> dict[str, Any]:
    """A script's stand-still step with its marker."""
    return {"hold": {"duration_s": duration_s, "marker": marker}}


def _checkhold_step(hold_s: float) -> float:
    if not (math.isfinite(hold_s) and hold_s >= _MIN_HOLD_S):
        msg = (
            f"procedure parameter hold_s must be ≥ {_MIN_HOLD_S} s (1 s settles, the rest "
            f"averages the IPS), got {hold_s}"
        )
        raise ConfigError(msg)
    return float(hold_s)


def _check_repeats(repeats: int) -> int:
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        msg = f"procedure parameter repeats must be an integer ≥ 1, got {repeats!r}"
        raise ConfigError(msg)
    return repeats


def rotation_procedure(
    *,
    distance_m: float = 2.5,
    speed_mps: float = 0.3,
    turns: int = 3,
    rate_radps: float = 1.0,
    hold_s: float = 4.0,
    approach_left_m: float = 1.0,
    name: str = "rotation-procedure",
) -> dict[str, Any]:
    """Seed 000 §3.2.1: heading from a forward translation, N turns, heading from the reverse.

    Args:
        distance_m: length of the forward and of the reverse translation.
        speed_mps: their cruise speed (trapezoidal ramps at the robot's limits).
        turns: number of full turns in place (≥ 1); more turns average out the heading errors.
        rate_radps: yaw rate of the turns, + counter-clockwise; the turn is a step command held
            for the theoretical time 2π·turns/|rate| (the firmware ramps it symmetrically).
        hold_s: every stand-still (≥ 3 s: about 1 s settles, the rest averages the IPS).
        approach_left_m: a lateral move left first (with stand-stills), so that the reverse
            translation stays inside the map whichever way the turns miss; 0 to leave it out.
        name: script name.

    Returns:
        The script mapping (``name``, ``steps``).

    Raises:
        ConfigError: a parameter out of range.
    """
    distance = _positive("distance_m", distance_m)
    speed = _positive("speed_mps", speed_mps)
    if isinstance(turns, bool) or not isinstance(turns, int) or turns < 1:
        msg = f"procedure parameter turns must be an integer ≥ 1, got {turns!r}"
        raise ConfigError(msg)
    if not (math.isfinite(rate_radps) and rate_radps != 0.0):
        msg = f"procedure parameter rate_radps must be finite and non-zero, got {rate_radps}"
        raise ConfigError(msg)
    hold = _checkhold_step(hold_s)
    if not (math.isfinite(approach_left_m) and approach_left_m >= 0.0):
        msg = f"procedure parameter approach_left_m must be ≥ 0, got {approach_left_m}"
        raise ConfigError(msg)
    steps: list[dict[str, Any]] = []
    if approach_left_m > 0.0:
        steps += [
            hold_step(hold, "approach-start"),
            {"move": {"vy_mps": speed, "distance_m": approach_left_m, "marker": "approach"}},
        ]
    steps += [
        hold_step(hold, "start"),
        {"move": {"vx_mps": speed, "distance_m": distance, "marker": "heading-before"}},
        hold_step(hold, "before-turns"),
        {
            "move": {
                "wz_radps": rate_radps,
                "angle_deg": 360.0 * turns,
                "ramp": False,
                "marker": f"turns-{turns}",
            }
        },
        hold_step(hold, "after-turns"),
        {"move": {"vx_mps": -speed, "distance_m": distance, "marker": "heading-after"}},
        hold_step(hold, "end"),
    ]
    return {"name": name, "steps": steps}


def back_and_forth(
    twist_out: dict[str, float],
    twist_back: dict[str, float],
    distance: float,
    hold: float,
    repeats: int,
    labels: tuple[str, str],
) -> list[dict[str, Any]]:
    """Script steps: a stand-still, then ``repeats`` times out and back by ``distance`` m, a
    stand-still after each move (markers ``out-k``, ``out-end-k``, ``back-k``, ``back-end-k``
    with the ``labels``)."""
    steps = [hold_step(hold, "start")]
    for k in range(repeats):
        steps += _leg(twist_out, distance, labels[0], k + 1, hold)
        steps += _leg(twist_back, distance, labels[1], k + 1, hold)
    return steps


def _leg(
    twist: dict[str, float], distance: float, label: str, k: int, hold: float
) -> list[dict[str, Any]]:
    """A move by ``distance`` m marked ``label-k`` and the stand-still after it (``label-end-k``)."""
    move = {"move": {**twist, "distance_m": distance, "marker": f"{label}-{k}"}}
    return [move, hold_step(hold, f"{label}-end-{k}")]


def longitudinal_procedure(
    *,
    distance_m: float = 3.5,
    speed_mps: float = 0.25,
    hold_s: float = 4.0,
    repeats: int = 2,
    name: str = "longitudinal-procedure",
) -> dict[str, Any]:
    """Seed 000 §3.2.2–3.2.3: forward then reverse, stand-stills at the ends, ``repeats`` times.

    Args:
        distance_m: length of each move (3–4 m fit seed 000's map from the twin's start).
        speed_mps: cruise speed.
        hold_s: every stand-still (≥ 3 s).
        repeats: number of forward/reverse pairs.
        name: script name.

    Returns:
        The script mapping (``name``, ``steps``).

    Raises:
        ConfigError: a parameter out of range.
    """
    distance = _positive("distance_m", distance_m)
    speed = _positive("speed_mps", speed_mps)
    steps = back_and_forth(
        {"vx_mps": speed},
        {"vx_mps": -speed},
        distance,
        _checkhold_step(hold_s),
        _check_repeats(repeats),
        ("forward", "reverse"),
    )
    return {"name": name, "steps": steps}


def lateral_procedure(
    *,
    distance_m: float = 3.0,
    speed_mps: float = 0.25,
    hold_s: float = 4.0,
    repeats: int = 2,
    reference_m: float = 3.5,
    name: str = "lateral-procedure",
) -> dict[str, Any]:
    """Seed 000 §3.2.3 (Figure 12): left then right, stand-stills at the ends, ``repeats`` times.

    With ``reference_m`` > 0 every lateral move is framed by longitudinal moves (a forward /
    reverse pair, then forward, left, reverse, right ``repeats`` times); 0: the paper's plain
    left/right pairs.

    Args:
        distance_m: length of each lateral move (2.5–3 m fit seed 000's map from the twin's
            start).
        speed_mps: cruise speed of every move.
        hold_s: every stand-still (≥ 3 s).
        repeats: number of left/right pairs.
        reference_m: length of the longitudinal reference moves; 0 leaves them out.
        name: script name.

    Returns:
        The script mapping (``name``, ``steps``).

    Raises:
        ConfigError: a parameter out of range.
    """
    distance = _positive("distance_m", distance_m)
    speed = _positive("speed_mps", speed_mps)
    hold = _checkhold_step(hold_s)
    n = _check_repeats(repeats)
    if not (math.isfinite(reference_m) and reference_m >= 0.0):
        msg = f"procedure parameter reference_m must be ≥ 0, got {reference_m}"
        raise ConfigError(msg)
    if reference_m == 0.0:
        steps = back_and_forth(
            {"vy_mps": speed}, {"vy_mps": -speed}, distance, hold, n, ("left", "right")
        )
        return {"name": name, "steps": steps}
    moves = (
        ({"vx_mps": speed}, reference_m, "reference-forward"),
        ({"vy_mps": speed}, distance, "left"),
        ({"vx_mps": -speed}, reference_m, "reference-reverse"),
        ({"vy_mps": -speed}, distance, "right"),
    )
    steps = [hold_step(hold, "start")]
    for twist, length, label in (moves[0], moves[2]):
        steps += _leg(twist, length, label, 0, hold)
    for k in range(n):
        for twist, length, label in moves:
            steps += _leg(twist, length, label, k + 1, hold)
    steps += [_leg(*moves[0], n + 1, hold)[0], hold_step(hold, "end")]
    return {"name": name, "steps": steps}


def nominal_path(
    script: MotionScript,
    start_pose_map: Sequence[float] = (1.5, 1.2, 0.0),
    *,
    true_factors: CorrectionFactors | None = None,
    step_s: float = 0.01,
) -> NDArray[np.float64]:
    """Dead-reckon the commanded twist of a script into poses in the map (no dynamics, no noise).

    Args:
        script: a compiled script.
        start_pose_map: (x m, y m, yaw rad) of base_link at the start.
        true_factors: if given, the motion of an uncompensated robot with these true factors
            (it travels 1/k of the command and turns c rad per metre); else the command itself.
        step_s: integration step.

    Returns:
        (N, 3) poses x, y, yaw at every step, the start included.

    Raises:
        ConfigError: a start pose that is not 3 finite numbers, or a step that is not > 0.
    """
    pose = np.asarray(start_pose_map, dtype=np.float64)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        msg = f"start_pose_map must be 3 finite numbers (x, y, yaw), got {start_pose_map!r}"
        raise ConfigError(msg)
    dt = _positive("step_s", step_s)
    t = np.arange(0.0, script.duration_s + dt, dt)
    twist = np.array([script.twist_at(float(ti)) for ti in t])
    if true_factors is not None:
        twist = twist / true_factors.scales
        twist[:, 2] += crosstalk_yaw_rate(true_factors, twist[:, 0], twist[:, 1])
    yaw = pose[2] + np.concatenate([[0.0], np.cumsum(twist[:-1, 2] * dt)])
    mid = yaw[:-1] + 0.5 * twist[:-1, 2] * dt
    c, s = np.cos(mid), np.sin(mid)
    dx = (twist[:-1, 0] * c - twist[:-1, 1] * s) * dt
    dy = (twist[:-1, 0] * s + twist[:-1, 1] * c) * dt
    x = pose[0] + np.concatenate([[0.0], np.cumsum(dx)])
    y = pose[1] + np.concatenate([[0.0], np.cumsum(dy)])
    return np.column_stack([x, y, yaw])


def hull_margin_m(points_xy_m: ArrayLike, beacons: BeaconMap) -> float:
    """How far a path stays inside the convex hull of the beacons (negative: it leaves it).

    Args:
        points_xy_m: (N, 2) or (N, 3) positions in the map (only x, y are used).
        beacons: the beacon map (at least 3 beacons not on one line).

    Returns:
        The smallest distance in m from a point to the hull's boundary, + inside.

    Raises:
        ConfigError: fewer than 3 beacons or collinear beacons, or bad points.
    """
    return float(np.min(hull_margins_m(points_xy_m, beacons)))


def hull_margins_m(points_xy_m: ArrayLike, beacons: BeaconMap) -> NDArray[np.float64]:
    """(N,) each point's distance inside the beacons' convex hull, m (negative: outside).

    Raises:
        ConfigError: as :func:`hull_margin_m`.
    """
    p = np.asarray(points_xy_m, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] < 2 or not np.all(np.isfinite(p[:, :2])):
        msg = f"points_xy_m must be finite (N, 2), got shape {p.shape}"
        raise ConfigError(msg)
    equations = hull_equations(beacons)
    signed = p[:, :2] @ equations[:, :2].T + equations[:, 2]
    return np.asarray(-np.max(signed, axis=1), dtype=np.float64)


def hull_equations(beacons: BeaconMap) -> NDArray[np.float64]:
    """(F, 3) the beacons' convex hull in the map plane as ``n·x + d ≤ 0`` inside, ``|n| = 1``.

    Raises:
        ConfigError: fewer than 3 beacons or collinear beacons.
    """
    b = beacons.positions_m[:, :2]
    if len(b) < 3:
        msg = f"a hull needs at least 3 beacons, the map has {len(b)}"
        raise ConfigError(msg)
    from scipy.spatial import ConvexHull, QhullError  # 0.2 s to import: only this needs it

    try:
        hull = ConvexHull(b)
    except QhullError as err:  # collinear or coincident beacons
        msg = "the beacons lie on one line: they span no area"
        raise ConfigError(msg) from err
    return np.asarray(hull.equations, dtype=np.float64)
