"""The paper's before/after measures of seed 000 §3.2, measured on the twin against its truth.

:func:`measure_scripts` (turns, longitudinal, lateral), :func:`measures_from_recordings`: every move
between settled stand-stills, ``/ground_truth`` against ``/odom``; truth measures, never estimates.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from omnical.calibration.procedures.scripts import back_and_forth, hold_step
from omnical.calibration.procedures.segments import Segment, segment_commands, segment_mask, settled
from omnical.errors import CalibrationError
from omnical.estimation.se2 import between_poses
from omnical.paper import SEED000_MEASURES
from omnical.recording.recording import Recording
from omnical.recording.topics import CMD_VEL, GROUND_TRUTH, ODOM

__all__ = [
    "MEASURE_SPECS",
    "LegMeasure",
    "MeasureSpec",
    "Measures",
    "leg_measures",
    "measure_scripts",
    "measures_from_recordings",
]

_Array = NDArray[np.float64]
_TRANSLATIONS = ("forward", "reverse", "left", "right")
_ROTATIONS = ("rotate_ccw", "rotate_cw")
_DIRECTIONS = {
    "forward": (1.0, 0.0),
    "reverse": (-1.0, 0.0),
    "left": (0.0, 1.0),
    "right": (0.0, -1.0),
}


def _check(name: str, value: float, low: float) -> float:
    if not (math.isfinite(value) and value > low):
        msg = f"measure parameter {name} must be a finite number > {low}, got {value}"
        raise CalibrationError(msg)
    return float(value)


def _legs_script(
    axis: str, labels: tuple[str, str], total_m: float, legs: int, speed_mps: float, hold_s: float
) -> list[dict[str, Any]]:
    if isinstance(legs, bool) or not isinstance(legs, int) or legs < 2 or legs % 2:
        msg = f"measure parameter legs must be an even integer ≥ 2, got {legs!r}"
        raise CalibrationError(msg)
    leg_m = _check("total_m", total_m, 0.0) / legs
    speed = _check("speed_mps", speed_mps, 0.0)
    hold = _check("hold_s", hold_s, 1.5)
    return back_and_forth({axis: speed}, {axis: -speed}, leg_m, hold, legs // 2, labels)


def measure_scripts(
    *,
    turns: int = 3,
    rate_radps: float = 1.0,
    total_m: float = 10.0,
    legs: int = 4,
    speed_mps: float = 0.25,
    hold_s: float = 3.0,
) -> dict[str, dict[str, Any]]:
    """The three measurement scripts (mappings for :func:`omnical.experiment.parse_script`).

    Args:
        turns: full turns in place of the ``turns`` script.
        rate_radps: their yaw rate (a step command held for the theoretical time).
        total_m: odometry travel of the ``longitudinal`` and ``lateral`` scripts.
        legs: number of back-and-forth legs they split it into (even).
        speed_mps: cruise speed of the legs.
        hold_s: every stand-still (> 1.5 s: 1 s settles, the rest is averaged).

    Returns:
        ``{"turns": ..., "longitudinal": ..., "lateral": ...}``.

    Raises:
        CalibrationError: a parameter out of range.
    """
    if isinstance(turns, bool) or not isinstance(turns, int) or turns < 1:
        msg = f"measure parameter turns must be an integer ≥ 1, got {turns!r}"
        raise CalibrationError(msg)
    rate = _check("rate_radps", rate_radps, 0.0)
    hold = _check("hold_s", hold_s, 1.5)
    turn_steps = [
        hold_step(hold, "start"),
        {
            "move": {
                "wz_radps": rate,
                "angle_deg": 360.0 * turns,
                "ramp": False,
                "marker": f"turns-{turns}",
            }
        },
        hold_step(hold, "end"),
    ]
    return {
        "turns": {"name": "measure-turns", "steps": turn_steps},
        "longitudinal": {
            "name": "measure-longitudinal",
            "steps": _legs_script(
                "vx_mps", ("forward", "reverse"), total_m, legs, speed_mps, hold_s
            ),
        },
        "lateral": {
            "name": "measure-lateral",
            "steps": _legs_script("vy_mps", ("left", "right"), total_m, legs, speed_mps, hold_s),
        },
    }


@dataclass(frozen=True)
class LegMeasure:
    """One move between two settled stand-stills, in reality and by the odometry.

    Attributes:
        kind: forward, reverse, left, right, rotate_ccw or rotate_cw.
        true_length_m: real path length of the robot centre (0 for a turn in place).
        odom_length_m: path length by the odometry.
        true_yaw_change_rad: real heading change.
        odom_yaw_change_rad: heading change by the odometry.
        end_error_body_m: (2,) real end position − the odometry's, each relative to its own
            start pose of the leg (base_link at the start; zero for a turn in place).
    """

    kind: str
    true_length_m: float
    odom_length_m: float
    true_yaw_change_rad: float
    odom_yaw_change_rad: float
    end_error_body_m: tuple[float, float] = (0.0, 0.0)

    @property
    def sideways_error_m(self) -> float:
        """End error across the direction of travel (+ to the left of it; 0 for a turn)."""
        u = _DIRECTIONS.get(self.kind)
        if u is None:
            return 0.0
        return -u[1] * self.end_error_body_m[0] + u[0] * self.end_error_body_m[1]

    @property
    def crosstalk_rad_per_m(self) -> float:
        """Heading change the odometry missed, per real metre (NaN for a turn in place)."""
        if self.true_length_m <= 0.0:
            return math.nan
        return (self.true_yaw_change_rad - self.odom_yaw_change_rad) / self.true_length_m


def _poses(recording: Recording, topic: str, t0_ns: int) -> tuple[_Array, _Array]:
    table = recording.topic(topic)
    pose = np.column_stack(
        [table["x_m"], table["y_m"], np.unwrap(np.asarray(table["yaw_rad"], dtype=np.float64))]
    ).astype(np.float64)
    return table.t_s(t0_ns), pose


def _mean_pose(t_s: _Array, pose: _Array, window: Segment, what: str) -> _Array:
    inside = segment_mask(t_s, window)
    if not np.any(inside):
        msg = f"no {what} sample in the stand-still at {window.t_start_s:.2f} s"
        raise CalibrationError(msg)
    mean: _Array = pose[inside].mean(axis=0)
    return mean


def _arc_length(a: _Array, b: _Array) -> float:
    chord = float(np.hypot(*(b[:2] - a[:2])))
    return chord / float(np.sinc((b[2] - a[2]) / (2.0 * np.pi)))


def leg_measures(recording: Recording, *, settle_s: float = 1.0) -> list[LegMeasure]:
    """Every move of a twin recording between two settled stand-stills, real and by odometry.

    Args:
        recording: a twin run with ``/cmd_vel``, ``/odom`` and ``/ground_truth``.
        settle_s: time dropped at the start of each stand-still before averaging.

    Returns:
        The legs in time order.

    Raises:
        CalibrationError: a topic is missing.
    """
    for topic in (CMD_VEL, ODOM, GROUND_TRUTH):
        if not recording.has(topic):
            msg = f"recording has no {topic} messages: the twin measures need it"
            raise CalibrationError(msg)
    cmd = recording.topic(CMD_VEL)
    t0 = int(cmd.t_ns[0])
    segments = segment_commands(cmd.t_s(t0), cmd["vx_mps"], cmd["vy_mps"], cmd["wz_radps"])
    gt_t, gt = _poses(recording, GROUND_TRUTH, t0)
    od_t, od = _poses(recording, ODOM, t0)
    truth: dict[int, _Array] = {}
    odom: dict[int, _Array] = {}
    for i, seg in enumerate(segments):
        if seg.kind == "still" and seg.duration_s > settle_s:
            window = settled(seg, settle_s)
            truth[i] = _mean_pose(gt_t, gt, window, "ground truth")
            odom[i] = _mean_pose(od_t, od, window, "odometry")
    legs: list[LegMeasure] = []
    for i, seg in enumerate(segments):
        if seg.kind not in _TRANSLATIONS + _ROTATIONS:
            continue
        if i - 1 not in truth or i + 1 not in truth:
            continue
        ta, tb, oa, ob = truth[i - 1], truth[i + 1], odom[i - 1], odom[i + 1]
        translation = seg.kind in _TRANSLATIONS
        # the end positions, each in the frame of its own start pose
        error = (
            between_poses(ta, tb)[:2] - between_poses(oa, ob)[:2] if translation else np.zeros(2)
        )
        legs.append(
            LegMeasure(
                kind=seg.kind,
                true_length_m=_arc_length(ta, tb) if translation else 0.0,
                odom_length_m=_arc_length(oa, ob) if translation else 0.0,
                true_yaw_change_rad=float(tb[2] - ta[2]),
                odom_yaw_change_rad=float(ob[2] - oa[2]),
                end_error_body_m=(float(error[0]), float(error[1])),
            )
        )
    return legs


@dataclass(frozen=True)
class Measures:
    """The paper's measures on one set of measurement runs.

    Attributes:
        heading_error_deg: real − odometry heading change over the turns, degrees.
        turns: real turns the odometry saw (≈ 3).
        longitudinal_error_m: real − odometry distance over the longitudinal legs, m.
        longitudinal_distance_m: odometry distance of those legs (≈ 10 m).
        lateral_drift_m: sideways end error of the lateral legs (odometry against reality,
            each leg aligned at its start), magnitudes summed, m.
        lateral_distance_m: odometry distance of the lateral legs (≈ 10 m).
        crosstalk_rad_per_m: forward, reverse, left, right → mean cross-talk of those legs.
    """

    heading_error_deg: float
    turns: float
    longitudinal_error_m: float
    longitudinal_distance_m: float
    lateral_drift_m: float
    lateral_distance_m: float
    crosstalk_rad_per_m: Mapping[str, float]

    @property
    def crosstalk_longitudinal_mrad_per_m(self) -> float:
        """Larger magnitude of the forward and reverse cross-talk, mrad/m."""
        c = self.crosstalk_rad_per_m
        return 1e3 * max(abs(c["forward"]), abs(c["reverse"]))

    @property
    def crosstalk_lateral_mrad_per_m(self) -> float:
        """Larger magnitude of the left and right cross-talk, mrad/m."""
        c = self.crosstalk_rad_per_m
        return 1e3 * max(abs(c["left"]), abs(c["right"]))


def _require_legs(legs: list[LegMeasure], kinds: tuple[str, ...], what: str) -> list[LegMeasure]:
    chosen = [leg for leg in legs if leg.kind in kinds]
    if not chosen:
        msg = f"the {what} recording has no {' or '.join(kinds)} move between two stand-stills"
        raise CalibrationError(msg)
    return chosen


def measures_from_recordings(
    turns: Recording, longitudinal: Recording, lateral: Recording, *, settle_s: float = 1.0
) -> Measures:
    """Measure the runs of the three :func:`measure_scripts` against the twin's truth.

    Args:
        turns: run of the ``turns`` script.
        longitudinal: run of the ``longitudinal`` script.
        lateral: run of the ``lateral`` script.
        settle_s: time dropped at the start of each stand-still.

    Returns:
        The measures.

    Raises:
        CalibrationError: a topic is missing, or a run lacks the moves it should have.
    """
    rot = _require_legs(leg_measures(turns, settle_s=settle_s), _ROTATIONS, "turns")
    true_turn = sum(leg.true_yaw_change_rad for leg in rot)
    odom_turn = sum(leg.odom_yaw_change_rad for leg in rot)
    lon = _require_legs(
        leg_measures(longitudinal, settle_s=settle_s), ("forward", "reverse"), "longitudinal"
    )
    lat = _require_legs(leg_measures(lateral, settle_s=settle_s), ("left", "right"), "lateral")
    cross: dict[str, float] = {}
    for kind in _TRANSLATIONS:
        values = [leg.crosstalk_rad_per_m for leg in lon + lat if leg.kind == kind]
        cross[kind] = float(np.mean(values)) if values else math.nan
    return Measures(
        heading_error_deg=math.degrees(true_turn - odom_turn),
        turns=abs(odom_turn) / (2.0 * math.pi),
        longitudinal_error_m=sum(leg.true_length_m - leg.odom_length_m for leg in lon),
        longitudinal_distance_m=sum(leg.odom_length_m for leg in lon),
        lateral_drift_m=sum(abs(leg.sideways_error_m) for leg in lat),
        lateral_distance_m=sum(leg.odom_length_m for leg in lat),
        crosstalk_rad_per_m=cross,
    )


@dataclass(frozen=True)
class MeasureSpec:
    """One row of the before/after table: what seed 000 reports and how to read ours.

    Attributes:
        key: short identifier.
        label: what is measured.
        unit: unit of the values.
        paper_before: seed 000's value before calibration.
        paper_after: seed 000's bound after calibration (ours must be at most this).
        value: reads the magnitude of the measure from :class:`Measures`, in ``unit``.
    """

    key: str
    label: str
    unit: str
    paper_before: float
    paper_after: float
    value: Callable[[Measures], float]

    def passes(self, measures: Measures) -> bool:
        """The measure is at least as good as the paper's after-calibration bound."""
        return abs(self.value(measures)) <= self.paper_after


MEASURE_SPECS: tuple[MeasureSpec, ...] = (
    MeasureSpec(
        "heading",
        "heading error after 3 turns",
        "°",
        *SEED000_MEASURES["heading"],
        lambda m: abs(m.heading_error_deg),
    ),
    MeasureSpec(
        "longitudinal",
        "longitudinal error over 10 m",
        "cm",
        *SEED000_MEASURES["longitudinal"],
        lambda m: 100.0 * abs(m.longitudinal_error_m),
    ),
    MeasureSpec(
        "lateral",
        "lateral drift over 10 m",
        "cm",
        *SEED000_MEASURES["lateral"],
        lambda m: 100.0 * m.lateral_drift_m,
    ),
    MeasureSpec(
        "crosstalk_longitudinal",
        "longitudinal cross-talk",
        "mrad/m",
        *SEED000_MEASURES["crosstalk_longitudinal"],
        lambda m: m.crosstalk_longitudinal_mrad_per_m,
    ),
    MeasureSpec(
        "crosstalk_lateral",
        "lateral cross-talk",
        "mrad/m",
        *SEED000_MEASURES["crosstalk_lateral"],
        lambda m: m.crosstalk_lateral_mrad_per_m,
    ),
)
"""The five measures of seed 000 §3.2 with the paper's before and after values."""
