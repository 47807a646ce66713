"""Translation scalings and cross-talks from a recording (seed 000 §3.2.2–3.2.3).

Scaling = odometry length / IPS arc length between settled stand-stills; cross-talk
c = κ_real + (s/ρ)·(c_installed − κ_odom), the total for any installed factors.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from omnical.calibration.procedures.headings import HeadingSolution, solve_headings
from omnical.calibration.procedures.tracks import (
    Estimate,
    MoveArc,
    SlipPrior,
    TranslationKind,
    combine_estimates,
)
from omnical.errors import CalibrationError
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import Factor

__all__ = [
    "Method",
    "TranslationResult",
    "TranslationSegment",
    "translation_from_arcs",
]

Method = Literal["chain", "arcs"]
"""How cross-talks are combined: heading continuity across stand-stills, or arcs alone."""

SCALE_FIELD: dict[TranslationKind, str] = {
    "forward": Factor.SCALE_LONGITUDINAL.field,
    "reverse": Factor.SCALE_LONGITUDINAL.field,
    "left": Factor.SCALE_LATERAL.field,
    "right": Factor.SCALE_LATERAL.field,
}
"""The scaling each translation direction measures."""
CROSSTALK_FIELD: dict[TranslationKind, str] = {
    "forward": Factor.CROSSTALK_FORWARD.field,
    "reverse": Factor.CROSSTALK_REVERSE.field,
    "left": Factor.CROSSTALK_LEFT.field,
    "right": Factor.CROSSTALK_RIGHT.field,
}
"""The cross-talk of each translation direction."""


@dataclass(frozen=True)
class TranslationSegment:
    """What one translation measures (totals include the installed factors).

    Attributes:
        recording: index of the recording it comes from.
        kind: forward, reverse, left or right.
        t_start_s: start of the move, s from the recording's first command.
        t_end_s: end of the move.
        arc: the IPS arc and odometry of the move (geometry, fit, stand-stills).
        scale_residual: odometry length / real length.
        scale: total scaling of its axis (installed × residual).
        scale_std: σ of ``scale`` from the stand-still averages and the slip prior.
        crosstalk_arc_rad_per_m: total cross-talk from this arc's curvature alone.
        crosstalk_arc_std_rad_per_m: its σ.
    """

    recording: int
    kind: TranslationKind
    t_start_s: float
    t_end_s: float
    arc: MoveArc
    scale_residual: float
    scale: float
    scale_std: float
    crosstalk_arc_rad_per_m: float
    crosstalk_arc_std_rad_per_m: float


@dataclass(frozen=True)
class TranslationResult:
    """Translation factors measured from one or more recordings.

    Attributes:
        installed: the factors the robot ran with.
        segments: every translation analysed, in recording and time order.
        estimates: CorrectionFactors field name → total factor with σ, for the fields measured.
        headings: the heading solution the cross-talks come from.
        method: ``"chain"`` or ``"arcs"``.
    """

    installed: CorrectionFactors
    segments: tuple[TranslationSegment, ...]
    estimates: Mapping[str, Estimate]
    headings: HeadingSolution
    method: Method

    @property
    def factors(self) -> CorrectionFactors:
        """The installed factors with every measured field replaced by its total."""
        return self.installed.with_values(**{k: e.value for k, e in self.estimates.items()})


def _crosstalk_total(
    kappa_real: float, scale_residual: float, kappa_odom: float, installed_c: float, rho: float
) -> float:
    return kappa_real + scale_residual / rho * (installed_c - kappa_odom)


def translation_from_arcs(
    arcs_per_recording: Sequence[Sequence[MoveArc]],
    installed: CorrectionFactors = CorrectionFactors(),  # noqa: B008 - frozen dataclass
    *,
    rotational_residual: float = 1.0,
    method: Method = "chain",
    headings: HeadingSolution | None = None,
    slip: SlipPrior = SlipPrior(),  # noqa: B008 - frozen dataclass
) -> TranslationResult:
    """Turn fitted arcs into translation factors (docs/DESIGN-NOTES.md).

    Args:
        arcs_per_recording: the arcs of each recording, in time order.
        installed: the factors the robot ran with.
        rotational_residual: ρ = k_rot,true / k_rot,installed if known (rotation analysis);
            it only weighs the installed cross-talk compensation.
        method: ``"chain"`` (heading continuity) or ``"arcs"`` (curvatures alone).
        headings: a solution already computed from the same arcs (else solved here).
        slip: prior on random slip, added to each move's scaling σ.

    Returns:
        The per-segment measurements and the combined totals.

    Raises:
        CalibrationError: no arcs, or a non-positive ``rotational_residual``.
    """
    if not (math.isfinite(rotational_residual) and rotational_residual > 0.0):
        msg = f"rotational_residual must be > 0, got {rotational_residual}"
        raise CalibrationError(msg)
    if not any(arcs_per_recording):
        msg = "no translation between two usable stand-stills: nothing to analyse"
        raise CalibrationError(msg)
    solution = headings or solve_headings(arcs_per_recording, chained=method == "chain", slip=slip)
    rho = rotational_residual
    segments: list[TranslationSegment] = []
    for r, arcs in enumerate(arcs_per_recording):
        for arc in arcs:
            s = arc.odom_length_m / arc.length_m
            k_inst = getattr(installed, SCALE_FIELD[arc.kind])
            c_inst = getattr(installed, CROSSTALK_FIELD[arc.kind])
            kappa_odom = arc.odom_yaw_change_rad / arc.odom_length_m
            segments.append(
                TranslationSegment(
                    recording=r,
                    kind=arc.kind,
                    t_start_s=arc.segment.t_start_s,
                    t_end_s=arc.segment.t_end_s,
                    arc=arc,
                    scale_residual=s,
                    scale=k_inst * s,
                    scale_std=k_inst
                    * s
                    * math.hypot(
                        arc.length_std_m / arc.length_m,
                        slip.relative_sigma(arc.segment.duration_s),
                    ),
                    crosstalk_arc_rad_per_m=_crosstalk_total(
                        arc.curvature_per_m, s, kappa_odom, c_inst, rho
                    ),
                    crosstalk_arc_std_rad_per_m=arc.curvature_std_per_m,
                )
            )
    estimates: dict[str, Estimate] = {}
    for axis in (Factor.SCALE_LONGITUDINAL.field, Factor.SCALE_LATERAL.field):
        chosen = [g for g in segments if SCALE_FIELD[g.kind] == axis]
        if chosen:
            estimates[axis] = combine_estimates(
                [g.scale for g in chosen], [g.scale_std for g in chosen]
            )
    for kind in solution.kinds:
        chosen = [g for g in segments if g.kind == kind]
        kappa = solution.crosstalk(kind)
        s_mean = float(np.mean([g.scale_residual for g in chosen]))
        kappa_odom = float(
            np.mean([g.arc.odom_yaw_change_rad / g.arc.odom_length_m for g in chosen])
        )
        c_inst = getattr(installed, CROSSTALK_FIELD[kind])
        total = _crosstalk_total(kappa.value, s_mean, kappa_odom, c_inst, rho)
        estimates[CROSSTALK_FIELD[kind]] = Estimate(total, kappa.sigma, len(chosen))
    return TranslationResult(installed, tuple(segments), estimates, solution, method)
