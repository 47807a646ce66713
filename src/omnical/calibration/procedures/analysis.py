"""The seven correction factors from the calibration procedures of seed 000 §3.2 (Figure 7).

:func:`analyse_procedures` takes the procedures' recordings (any number, any order) and the
``installed`` factors and returns the totals (installed composed with the residual) with 1σ.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from omnical.calibration.procedures.headings import solve_headings
from omnical.calibration.procedures.rotation import RotationResult, rotation_from_arcs
from omnical.calibration.procedures.tracks import (
    ODOM_YAW_DEADBAND_RADPS,
    SlipPrior,
    tracks_and_arcs,
)
from omnical.calibration.procedures.translation import (
    Method,
    TranslationResult,
    translation_from_arcs,
)
from omnical.errors import CalibrationError
from omnical.ips.beacons import BeaconMap
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import FACTORS, Factor
from omnical.recording.recording import Recording

__all__ = ["ProcedureEstimate", "analyse_procedures"]

FACTOR_NAMES: tuple[str, ...] = tuple(f.field for f in FACTORS)
"""CorrectionFactors field names of the seven factors, in field order."""


@dataclass(frozen=True)
class ProcedureEstimate:
    """The seven factors measured by the procedures.

    Attributes:
        factors: total factors (what to install next); a factor no recording measured keeps
            its installed value.
        sigma: CorrectionFactors field name → one-sigma uncertainty of the total (``inf`` for a
            factor not measured).
        installed: the factors the robot ran with during the recordings.
        rotation: the rotation analysis, if any recording had a framed turn.
        translation: the translation analysis.
        notes: moves that could not be used, and why; the held factors.
        held: factor field name → why the recordings do not support it (``not observable:
            …`` or ``inconsistent: …``); it keeps its installed value, with σ ``inf``.
    """

    factors: CorrectionFactors
    sigma: Mapping[str, float]
    installed: CorrectionFactors
    rotation: RotationResult | None
    translation: TranslationResult
    notes: tuple[str, ...] = ()
    held: Mapping[str, str] = field(default_factory=dict)

    @property
    def residual(self) -> CorrectionFactors:
        """Residual factors: ``installed.composed_with(residual) == factors``."""
        scales = self.factors.scales / self.installed.scales
        cross = self.factors.crosstalks_rad_per_m - self.installed.crosstalks_rad_per_m
        return CorrectionFactors.from_vector([*scales, *cross])

    @property
    def measured(self) -> tuple[str, ...]:
        """Names of the factors the recordings measured."""
        return tuple(k for k in FACTOR_NAMES if math.isfinite(self.sigma[k]))


def analyse_procedures(
    recordings: Recording | Sequence[Recording],
    installed: CorrectionFactors = CorrectionFactors(),  # noqa: B008 - frozen dataclass
    *,
    method: Method = "chain",
    hedge_offset_m: Sequence[float] | None = None,
    beacons: BeaconMap | None = None,
    settle_s: float = 1.0,
    slip: SlipPrior = SlipPrior(),  # noqa: B008 - frozen dataclass
    odom_yaw_deadband_radps: float = ODOM_YAW_DEADBAND_RADPS,
) -> ProcedureEstimate:
    """All correction factors the recordings can give, with their uncertainties.

    Args:
        recordings: runs of the procedures (one or several, any mix).
        installed: the factors the robot ran with in every recording.
        method: ``"chain"`` (heading continuity across stand-stills, default) or ``"arcs"``
            (seed 000's per-arc curvatures).
        hedge_offset_m: hedgehog (x, y[, z]) in base_link (the robot description's
            ``hedge_offset_m``); None assumes it at the centre.
        beacons: beacon map (default: each recording's ``/beacons_pos_a``).
        settle_s: time dropped at the start of each stand-still.
        slip: prior on random slip, added to the σ of every scaling (see
            :class:`~omnical.calibration.procedures.tracks.SlipPrior`).
        odom_yaw_deadband_radps: odometry yaw rates up to this are no rotation
            (:func:`~omnical.calibration.procedures.tracks.resolved_odometry`; the robot's
            :func:`~omnical.calibration.procedures.tracks.yaw_deadband_radps`).

    Returns:
        Totals, σ, the analyses behind them and notes.

    Raises:
        CalibrationError: a topic is missing, or no translation can be analysed.
    """
    tracks, arcs_all, notes = tracks_and_arcs(
        recordings, hedge_offset_m, beacons=beacons, settle_s=settle_s,
        odom_yaw_deadband_radps=odom_yaw_deadband_radps,
    )  # fmt: skip
    if not any(arcs_all):
        msg = "no translation between two usable stand-stills in the recordings"
        raise CalibrationError(msg)
    headings = solve_headings(arcs_all, chained=method == "chain", slip=slip)
    rotation: RotationResult | None = None
    has_turns = any(s.kind in ("rotate_ccw", "rotate_cw") for tr in tracks for s in tr.segments)
    if has_turns:
        try:
            rotation = rotation_from_arcs(
                tracks, arcs_all, installed, method=method, headings=headings, slip=slip
            )
        except CalibrationError as err:
            notes.append(f"rotation: {err}")
    rho = rotation.residual.value if rotation is not None else 1.0
    translation = translation_from_arcs(
        arcs_all,
        installed,
        rotational_residual=rho,
        method=method,
        headings=headings,
        slip=slip,
    )
    values = dict(installed.as_dict())
    sigma = dict.fromkeys(FACTOR_NAMES, math.inf)
    for name, est in translation.estimates.items():
        values[name], sigma[name] = est.value, est.sigma
    if rotation is not None:
        notes += list(rotation.notes)
        values[Factor.SCALE_ROTATIONAL.field] = rotation.estimate.value
        sigma[Factor.SCALE_ROTATIONAL.field] = rotation.estimate.sigma
    held = _held_factors(translation, rotation, sigma, has_turns)
    for name, reason in held.items():
        values[name], sigma[name] = getattr(installed, name), math.inf
        notes.append(f"{name}: {reason}; held at {values[name]:.6g} (the installed value)")
    return ProcedureEstimate(
        factors=CorrectionFactors(**values),
        sigma=sigma,
        installed=installed,
        rotation=rotation,
        translation=translation,
        notes=tuple(notes),
        held=held,
    )


MIN_MOVE_TRAVEL_M = 0.5
"""Least analysed travel (m) in a direction for its cross-talk, per axis for its scaling."""
MAX_SIGMA = {"scale": 0.01, "crosstalk": 0.01}
"""Largest one-sigma uncertainty (relative for a scaling, rad/m) of a factor that counts as
measured: the joint estimator's limits."""

_DIRECTIONS = {
    Factor.SCALE_LONGITUDINAL.field: ("forward", "reverse"),
    Factor.SCALE_LATERAL.field: ("left", "right"),
    Factor.CROSSTALK_FORWARD.field: ("forward",),
    Factor.CROSSTALK_REVERSE.field: ("reverse",),
    Factor.CROSSTALK_LEFT.field: ("left",),
    Factor.CROSSTALK_RIGHT.field: ("right",),
}


def _held_factors(
    translation: TranslationResult,
    rotation: RotationResult | None,
    sigma: Mapping[str, float],
    has_turns: bool,
) -> dict[str, str]:
    """Factor → why the recordings do not support it (then it keeps its installed value).

    Not measured (no move of its kind analysed, no turn); too little travel
    (< :data:`MIN_MOVE_TRAVEL_M`); or a σ beyond :data:`MAX_SIGMA`.
    """
    held: dict[str, str] = {}
    for factor in FACTORS:
        name = factor.field
        s = sigma[name]
        if name == Factor.SCALE_ROTATIONAL.field:
            if rotation is None:
                held[name] = (
                    "not observable: no turn was analysed"
                    if not has_turns
                    else "not observable: the turns could not be analysed"
                )
            elif not s / rotation.estimate.value <= MAX_SIGMA["scale"]:
                held[name] = (
                    f"not observable: its one sigma, {s:.3g}, exceeds {MAX_SIGMA['scale']:g}"
                )
            continue
        kinds = _DIRECTIONS[name]
        moves = [g for g in translation.segments if g.kind in kinds]
        travel = sum(g.arc.length_m for g in moves)
        if not math.isfinite(s):
            held[name] = f"not observable: no {' or '.join(kinds)} move was analysed"
            continue
        if travel < MIN_MOVE_TRAVEL_M:
            held[name] = (
                f"not observable: only {travel:.2f} m of {' and '.join(kinds)} travel analysed"
            )
            continue
        value = translation.estimates[name].value
        relative = s / value if factor.is_scale else s
        if not relative <= MAX_SIGMA[factor.kind.value]:
            held[name] = (
                f"not observable: its one sigma, {relative:.3g}, "
                f"exceeds {MAX_SIGMA[factor.kind.value]:g}"
            )
            continue
    return held
