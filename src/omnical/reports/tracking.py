"""Tracking results on paper: the figures of seed 000 Figures 16–17 and seed 001 Figures 9/11,
and what ``omnical evaluate`` leaves (``metrics.json``, figures, ``report.md``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from omnical.errors import RecordingError
from omnical.evaluation.metrics import (
    GROUND_TRUTH_KEY,
    SEED003_KEY,
    SMOOTHED_KEY,
    Tracked,
    TrackingMetrics,
    metrics_json,
    smoothing_summary,
)
from omnical.recording.recording import Recording
from omnical.recording.topics import CMD_VEL, ODOM
from omnical.reports.markdown import FigureLink, Section, write_markdown_report
from omnical.reports.tables import metrics_table

__all__ = [
    "EvaluationFiles",
    "is_the_reference",
    "smoothed_paragraphs",
    "tracking_figures",
    "write_evaluation",
]

SAME_CURVE_M = 1e-6
"""An estimate within this of the reference at every sample is the reference itself."""

_PATH_LINES = (GROUND_TRUTH_KEY, SMOOTHED_KEY, SEED003_KEY)
"""Estimates drawn as lines over the paths (the rest have their own styles), in drawing order."""


def is_the_reference(tracked: Tracked) -> bool:
    """Whether an estimate is the reference itself (the ground truth evaluated against
    ``/ground_truth``): within :data:`SAME_CURVE_M` of it at every sample."""
    return bool(tracked.metrics.max_m <= SAME_CURVE_M)


def tracking_figures(
    tracked: Mapping[str, Tracked],
    recording: Recording,
    folder: Path,
    *,
    stem: str,
    title: str,
    frame: str = "reference frame",
    over_time: Sequence[str] | None = None,
) -> list[Path]:
    """Paths against the reference, x(t) and y(t), and the speeds (when commanded).

    The ground truth is drawn as a line of its own, unless it is the reference
    (:func:`is_the_reference`): then it is drawn and listed once, as the reference.

    Args:
        tracked: estimate name → its association and alignment.
        recording: the run (``/cmd_vel`` and ``/odom`` for the speeds).
        folder: where the PNGs go: ``{stem}path.png``, ``{stem}xy-time.png``,
            ``{stem}speeds.png``.
        stem: file name prefix.
        title: figure title prefix.
        frame: the frame the positions are in, for the axis labels.
        over_time: which estimates to draw over time (None: all).
    """
    from omnical.reports.figures.trajectory import (
        plot_position_time,
        plot_speeds,
        plot_tracking_paths,
    )

    first = next(iter(tracked.values()))
    ref_xy = first.association.reference_xy_m
    # the ground truth is drawn unless it is the reference (evaluated against /ground_truth)
    drawn = {name: t for name, t in tracked.items() if not is_the_reference(t)}
    same = [name for name in tracked if name not in drawn]
    ref_label = "reference" if not same else f"reference = {', '.join(same)}".replace("_", " ")

    def aligned(estimate: str) -> ArrayLike | None:
        return drawn[estimate].alignment.xy_m if estimate in drawn else None

    figures = [
        plot_tracking_paths(
            folder / f"{stem}path.png",
            reference_xy_m=ref_xy,
            odometry_xy_m=aligned("odometry"),
            ips_xy_m=aligned("ips"),
            multilateration_xy_m=aligned("multilateration"),
            lines_xy_m={name: drawn[name].alignment.xy_m for name in _PATH_LINES if name in drawn},
            title=f"{title}: paths against the reference",
            reference_label=ref_label,
            frame=frame,
            alignments={name: t.alignment.mode for name, t in drawn.items()},
        ),
        plot_position_time(
            folder / f"{stem}xy-time.png",
            reference=(first.association.t_s, ref_xy),
            estimates={
                name: (t.association.t_s, t.alignment.xy_m)
                for name, t in drawn.items()
                if over_time is None or name in over_time
            },
            title=f"{title}: x(t) and y(t)",
            reference_label=ref_label,
            frame=frame,
        ),
    ]
    if recording.has(CMD_VEL):
        cmd = recording.topic(CMD_VEL)
        t0 = recording.start_ns
        odom = recording.topic(ODOM) if recording.has(ODOM) else None
        figures.append(
            plot_speeds(
                folder / f"{stem}speeds.png",
                cmd_t_s=cmd.t_s(t0),
                cmd_twist=np.column_stack([cmd["vx_mps"], cmd["vy_mps"], cmd["wz_radps"]]),
                odom_t_s=odom.t_s(t0) if odom is not None else None,
                odom_twist=np.column_stack([odom["vx_mps"], odom["vy_mps"], odom["wz_radps"]])
                if odom is not None
                else None,
                title=f"{title}: speeds",
            )
        )
    return figures


def smoothed_paragraphs(tracked: Mapping[str, Tracked]) -> tuple[str, ...]:
    """What the report says about the estimate it relies on: the smoothed trajectory, if any."""
    sm_tracked = tracked.get(SMOOTHED_KEY)
    if sm_tracked is None or sm_tracked.smoothing is None:
        none = (
            "No smoothed trajectory (it needs `/odom` and at least three trusted IPS fixes): "
            "without ground truth, the multilateration's RMSE includes the fixes' own noise."
        )
        return (none,)
    s = smoothing_summary(sm_tracked)
    m = sm_tracked.metrics
    scales = ", ".join(
        f"{axis} {100 * s[f'scale_{axis}']:+.1f} ± {100 * s[f'scale_{axis}_sigma']:.1f} %"
        for axis in ("x", "y", "yaw")
    )
    details = (
        f"IPS latency found: {1e3 * s['latency_s']:.0f} ± {1e3 * s['latency_sigma_s']:.0f} ms; "
        f"hedgehog lever arm {_arm(s)}. Fixes used: {int(s['fixes_used'])}, down-weighted as "
        f"outliers: {int(s['fixes_downweighted'])}; RMS fix residual "
        f"{s['fix_residual_rms_m']:.4f} m. Odometry corrections found in this run (relative "
        f"scale): {scales}; cross-talk {_crosstalks(s)}."
    )
    check = sm_tracked.smoothing.check
    if not s["converged"] and (check is None or check.passed):
        return (
            (
                f"**The smoother did not converge** (after {int(s['iterations'])} iterations): "
                f"`smoothed` (RMSE {m.rmse_m:.4f} m, its own 1σ {s['sigma_rms_m']:.4f} m) is not "
                "an estimate to quote. Too few fixes, or long stretches without them, leave the "
                "odometry's drift undetermined; quote `multilateration` instead."
            ),
        )
    if check is not None and not check.passed:
        return (
            (
                f"**The smoothed track fails its self-check** ({'; '.join(check.reasons)}): "
                f"`smoothed` (RMSE {m.rmse_m:.4f} m, its own 1σ {s['sigma_rms_m']:.4f} m) is not "
                "an estimate to quote, nor its 1σ. Its model does not explain the fixes as their "
                "covariances say (a lever arm the run could not determine, an odometry that "
                "changes within the run, fixes noisier than they claim); quote `multilateration`."
            ),
            _check_sentence(s),
            details,
        )
    return (
        (
            f"**The estimate to quote is `smoothed`: RMSE {m.rmse_m:.4f} m, with its own "
            f"uncertainty {s['sigma_rms_m']:.4f} m (1σ, RMS over the run).** It fuses the wheel "
            "odometry, the trusted IPS fixes (status ok; degraded ones only when their covariance "
            "agrees with their neighbours), weighted by their covariances, and the gyro where "
            "recorded, in one batch smoother with the seven factors' effect on the odometry, the "
            "hedgehog's lever arm and the IPS latency in the model. Its RMSE is the robot's "
            "tracking error plus, in quadrature, about its own uncertainty; the fixes alone "
            "(`multilateration`) add their 2–3 cm noise instead."
        ),
        _check_sentence(s),
        details,
    )


def _arm(s: Mapping[str, float]) -> str:
    """The lever arm of a smoothing summary, with its 1σ when estimated."""
    x, y = s["hedge_offset_x_m"], s["hedge_offset_y_m"]
    if s["hedge_offset_x_m_sigma"] > 0.0:
        return (
            f"({x:+.3f} ± {s['hedge_offset_x_m_sigma']:.3f}, {y:+.3f} ± "
            f"{s['hedge_offset_y_m_sigma']:.3f}) m (estimated)"
        )
    return f"({x:+.3f}, {y:+.3f}) m (given: the run turns too little to estimate it)"


def _crosstalks(s: Mapping[str, float]) -> str:
    """The cross-talks of a smoothing summary, mrad/m."""
    return ", ".join(
        f"{d} {1e3 * s[f'crosstalk_{d}_rad_per_m']:+.1f} ± "
        f"{1e3 * s[f'crosstalk_{d}_rad_per_m_sigma']:.1f} mrad/m"
        for d in ("forward", "backward", "left", "right")
    )


def _check_sentence(s: Mapping[str, float]) -> str:
    """The self-check of a smoothing summary in words."""
    if "check_passed" not in s:
        return "No self-check was made."
    verdict = "passed" if s["check_passed"] else "failed"
    return (
        f"Self-check ({verdict}): the trusted fixes' residuals normalised by their own "
        f"covariances have χ²/dof {s['check_fix_chi2_per_dof']:.2f} (≈ 1 when the track "
        f"explains them), {100 * s['check_fixes_in_band_95']:.1f} % of them lie inside the "
        f"track's 95 % band; the odometry fits them with its noise ×"
        f"{s['check_odometry_noise_scale']:.2f} of the model's, the fixes' ×"
        f"{s['check_fix_noise_scale']:.2f} of their own (the 1σ use these)."
    )


@dataclass(frozen=True)
class EvaluationFiles:
    """What :func:`write_evaluation` wrote: ``metrics.json``, the figures and ``report.md``."""

    metrics: Path
    figures: tuple[Path, ...]
    report: Path


def write_evaluation(
    tracked: Mapping[str, Tracked],
    recording: Recording,
    out_dir: str | Path,
    *,
    name: str,
    align: str,
    figures: bool = True,
) -> EvaluationFiles:
    """Write ``metrics.json``, the tracking figures (if ``figures``) and ``report.md`` under
    ``out_dir``.

    Raises:
        RecordingError: a file cannot be written.
    """
    out = Path(out_dir)
    results: dict[str, TrackingMetrics] = {k: t.metrics for k, t in tracked.items()}
    try:
        out.mkdir(parents=True, exist_ok=True)
        metrics = out / "metrics.json"
        details = {k: smoothing_summary(t) for k, t in tracked.items() if t.smoothing is not None}
        metrics.write_text(metrics_json(results, details), encoding="utf-8")
    except OSError as err:
        raise RecordingError(f"{out}: cannot write the evaluation: {err.strerror}") from None
    drawn = tracking_figures(tracked, recording, out, stem="", title=name) if figures else []
    report = write_markdown_report(
        out,
        f"Evaluation — {name}",
        [
            Section(
                "Tracking errors",
                (
                    (
                        f"Every estimate against the reference, alignment `{align}` (odometry is "
                        "always aligned at its origin); metres."
                    ),
                    metrics_table(results),
                ),
            ),
            Section("Smoothed trajectory", smoothed_paragraphs(tracked)),
            *([Section("Figures", tuple(FigureLink(f, f.stem) for f in drawn))] if drawn else []),
        ],
    )
    return EvaluationFiles(metrics, tuple(drawn), report)
