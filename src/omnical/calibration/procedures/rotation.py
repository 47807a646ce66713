"""Rotational scaling from turns in place framed by translations (seed 000 §3.2.1, Figure 7).

Heading changes from the IPS arcs' tangents against the odometry's yaw (2π resolved by the
odometry); residual ρ = odometry angle / real angle, total = ``installed.scale_rotational`` × ρ.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from omnical.calibration.procedures.headings import HeadingSolution, solve_headings
from omnical.calibration.procedures.tracks import (
    Estimate,
    MoveArc,
    ProcedureTracks,
    SlipPrior,
    combine_estimates,
)
from omnical.calibration.procedures.translation import Method
from omnical.errors import CalibrationError
from omnical.kinematics.correction import CorrectionFactors

__all__ = ["RotationMeasurement", "RotationResult", "rotation_from_arcs"]

_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class RotationMeasurement:
    """One turn in place between two stand-stills with a translation on either side.

    Attributes:
        recording: index of the recording.
        t_start_s: start of the turn, s from the recording's first command.
        t_end_s: end of the turn.
        commanded_angle_rad: the command's integral over the turn.
        odom_angle_rad: odometry yaw change between the stand-stills.
        real_angle_rad: real heading change (IPS), 2π multiple resolved.
        real_angle_std_rad: its σ.
        scale_residual: odometry angle / real angle.
        scale: total rotational scaling (installed × residual).
        scale_std: its σ.
    """

    recording: int
    t_start_s: float
    t_end_s: float
    commanded_angle_rad: float
    odom_angle_rad: float
    real_angle_rad: float
    real_angle_std_rad: float
    scale_residual: float
    scale: float
    scale_std: float


@dataclass(frozen=True)
class RotationResult:
    """Rotational scaling from one or more turns.

    Attributes:
        installed: the factors the robot ran with.
        measurements: every turn analysed.
        estimate: the combined total rotational scaling with σ.
        residual: the combined residual ρ with σ.
        headings: the heading solution the real angles come from.
        notes: turns that could not be used, and why.
    """

    installed: CorrectionFactors
    measurements: tuple[RotationMeasurement, ...]
    estimate: Estimate
    residual: Estimate
    headings: HeadingSolution
    notes: tuple[str, ...] = field(default=())

    @property
    def factors(self) -> CorrectionFactors:
        """The installed factors with the rotational scaling replaced by its total."""
        return self.installed.with_values(scale_rotational=self.estimate.value)


def rotation_from_arcs(
    tracks: Sequence[ProcedureTracks],
    arcs_per_recording: Sequence[Sequence[MoveArc]],
    installed: CorrectionFactors = CorrectionFactors(),  # noqa: B008 - frozen dataclass
    *,
    method: Method = "chain",
    headings: HeadingSolution | None = None,
    slip: SlipPrior = SlipPrior(),  # noqa: B008 - frozen dataclass
) -> RotationResult:
    """Measure every turn that has a fitted translation right before and right after it.

    Args:
        tracks: the tracks of each recording.
        arcs_per_recording: the arcs of each recording (same order).
        installed: the factors the robot ran with.
        method: heading solution ``"chain"`` or ``"arcs"`` (see analysis_headings).
        headings: a solution already computed from the same arcs (else solved here).
        slip: prior on random slip during the turn, added to each turn's σ.

    Returns:
        The rotation result.

    Raises:
        CalibrationError: no turn framed by two analysed translations.
    """
    if len(tracks) != len(arcs_per_recording):
        msg = f"{len(tracks)} tracks for {len(arcs_per_recording)} lists of arcs"
        raise CalibrationError(msg)
    notes_out: list[str] = []
    if not any(arcs_per_recording):
        msg = "no translation between two usable stand-stills: no heading to measure turns from"
        raise CalibrationError(msg)
    solution = headings or solve_headings(arcs_per_recording, chained=method == "chain", slip=slip)
    measurements: list[RotationMeasurement] = []
    for r, tr in enumerate(tracks):
        for i, seg in enumerate(tr.segments):
            if seg.kind not in ("rotate_ccw", "rotate_cw"):
                continue
            before, after = tr.stills.get(i - 1), tr.stills.get(i + 1)
            where = f"recording {r}: turn at {seg.t_start_s:.2f}–{seg.t_end_s:.2f} s"
            if before is None or after is None:
                notes_out.append(f"{where}: no usable stand-still on both sides")
                continue
            if (r, i - 1) not in solution.nodes or (r, i + 1) not in solution.nodes:
                notes_out.append(f"{where}: no analysed translation on both sides")
                continue
            ips = solution.heading_change(r, i - 1, i + 1)
            odom = float(after.odom_pose[2] - before.odom_pose[2])
            real = ips.value + _TWO_PI * round((odom - ips.value) / _TWO_PI)
            if real == 0.0:
                notes_out.append(f"{where}: no real heading change")
                continue
            rho = odom / real
            rho_std = abs(rho) * math.hypot(
                ips.sigma / abs(real), slip.relative_sigma(seg.duration_s)
            )
            measurements.append(
                RotationMeasurement(
                    recording=r,
                    t_start_s=seg.t_start_s,
                    t_end_s=seg.t_end_s,
                    commanded_angle_rad=seg.commanded_integral[2],
                    odom_angle_rad=odom,
                    real_angle_rad=real,
                    real_angle_std_rad=ips.sigma,
                    scale_residual=rho,
                    scale=installed.scale_rotational * rho,
                    scale_std=installed.scale_rotational * rho_std,
                )
            )
    if not measurements:
        msg = (
            "no turn in place framed by two analysed translations (stand still, translate, "
            "stand still, turn, stand still, translate, stand still)"
        )
        raise CalibrationError(msg)
    residual = combine_estimates(
        [m.scale_residual for m in measurements],
        [m.scale_std / installed.scale_rotational for m in measurements],
    )
    total = Estimate(
        installed.scale_rotational * residual.value,
        installed.scale_rotational * residual.sigma,
        residual.n,
    )
    return RotationResult(
        installed, tuple(measurements), total, residual, solution, tuple(notes_out)
    )
