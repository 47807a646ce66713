"""The campaign report (Markdown): seed 000 Table 2 with uncertainties, before/after, figures.

:func:`campaign_report_text` turns a :class:`~omnical.calibration.campaign.CampaignResult` into
``report.md``:

* the factors as seed 000 Table 2 lists them, with their one-sigma uncertainties, the paper's
  values beside them and, on the twin, the truth and the error;
* the paper's before/after measures (§3.2: heading error after 3 turns, longitudinal error over
  10 m, lateral drift, longitudinal and lateral cross-talk), the paper's figures beside the
  twin's, with a pass mark where ours is at least as good as the paper's after calibration;
* the iterations (totals and changes), the validation residual, the figures in the order of
  seed 000 Figures 8–13, the files, and how to re-run the analysis offline.

The tables are plain functions of their data (:func:`factors_table`, :func:`measures_table`)
so the offline ``omnical calibrate RUN.mcap`` prints the same Table 2.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from omnical.calibration.analysis import FACTOR_NAMES
from omnical.calibration.measures import MEASURE_SPECS, Measures, MeasureSpec
from omnical.errors import ConfigError
from omnical.kinematics.correction import CorrectionFactors

if TYPE_CHECKING:
    from omnical.calibration.campaign import CampaignResult, Iteration, Validation

__all__ = [
    "FACTOR_LABELS",
    "campaign_report_text",
    "factors_table",
    "measures_table",
    "write_report",
]

FACTOR_LABELS: dict[str, str] = {
    "scale_longitudinal": "Longitudinal velocity",
    "scale_lateral": "Lateral velocity",
    "scale_rotational": "Rotational velocity",
    "crosstalk_forward_rad_per_m": "Longitudinal-forward velocity to rotational",
    "crosstalk_reverse_rad_per_m": "Longitudinal-reverse velocity to rotational",
    "crosstalk_left_rad_per_m": "Lateral-left velocity to rotational",
    "crosstalk_right_rad_per_m": "Lateral-right velocity to rotational",
}
"""The row labels of seed 000 Table 2."""

_SHORT = {
    "scale_longitudinal": "k lon",
    "scale_lateral": "k lat",
    "scale_rotational": "k rot",
    "crosstalk_forward_rad_per_m": "c fwd",
    "crosstalk_reverse_rad_per_m": "c rev",
    "crosstalk_left_rad_per_m": "c left",
    "crosstalk_right_rad_per_m": "c right",
}
_PAPER = CorrectionFactors.seed000_table2()


def _is_scale(name: str) -> bool:
    return name.startswith("scale")


def _value(name: str, value: float) -> str:
    if not math.isfinite(value):
        return "—"
    return f"{value:.5f}" if _is_scale(name) else f"{value:+.5f}"


def _sigma(name: str, sigma: float) -> str:
    if not math.isfinite(sigma):
        return "not estimated"
    return f"{sigma:.5f}"


def _error(name: str, value: float, truth: float) -> str:
    if _is_scale(name):
        return f"{100.0 * (value / truth - 1.0):+.3f} %"
    return f"{1e3 * (value - truth):+.2f} mrad/m"


def _change(name: str, change: float) -> str:
    return f"{100.0 * change:+.3f} %" if _is_scale(name) else f"{1e3 * change:+.2f} mrad/m"


def factors_table(
    factors: CorrectionFactors,
    sigma: Mapping[str, float],
    truth: CorrectionFactors | None = None,
) -> str:
    """Seed 000 Table 2 as Markdown, with ± 1σ, the paper's values and, if known, the truth.

    Args:
        factors: the estimated factors.
        sigma: factor field name → one-sigma uncertainty (``inf``/NaN: not estimated).
        truth: the twin's true factors, for the truth and error columns.

    Returns:
        The table (header, separator and seven rows), ending with a newline.
    """
    head = ["Type", "Factor", "± 1σ"]
    if truth is not None:
        head += ["Truth (twin)", "Error"]
    head += ["Seed 000", "Unit of measure"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name in FACTOR_NAMES:
        value = getattr(factors, name)
        cells = [FACTOR_LABELS[name], _value(name, value), _sigma(name, sigma.get(name, math.nan))]
        if truth is not None:
            cells += [_value(name, getattr(truth, name)), _error(name, value, getattr(truth, name))]
        paper = getattr(_PAPER, name)
        cells.append(f"{paper:.4f}" if _is_scale(name) else f"{paper:.5f} (magnitude)")
        cells.append("scaling — no unit" if _is_scale(name) else "rad m⁻¹")
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n"


def _fmt(value: float) -> str:
    return f"{value:.3g}" if abs(value) < 100 else f"{value:.0f}"


def measures_table(
    before: Measures, after: Measures, specs: Sequence[MeasureSpec] = MEASURE_SPECS
) -> str:
    """The paper's before/after measures as Markdown, seed 000's figures beside the twin's.

    Args:
        before: measures uncalibrated.
        after: measures calibrated.
        specs: which measures (default: the five of seed 000 §3.2).

    Returns:
        The table, ending with a newline.
    """
    rows = [
        (
            "| Measure | Unit | Seed 000 before | Twin before | Seed 000 after | Twin after | "
            "At least as good as seed 000 |"
        ),
        "|---|---|---|---|---|---|---|",
    ]
    for spec in specs:
        rows.append(
            f"| {spec.label} | {spec.unit} | {_fmt(spec.paper_before)} | "
            f"{_fmt(spec.value(before))} | < {_fmt(spec.paper_after)} | "
            f"{_fmt(spec.value(after))} | {'yes' if spec.passes(after) else '**no**'} |"
        )
    return "\n".join(rows) + "\n"


def _crosstalk_detail(before: Measures, after: Measures) -> str:
    rows = [
        "| Direction | Twin before (mrad/m) | Twin after (mrad/m) |",
        "|---|---|---|",
    ]
    for kind in ("forward", "reverse", "left", "right"):
        b = 1e3 * before.crosstalk_rad_per_m[kind]
        a = 1e3 * after.crosstalk_rad_per_m[kind]
        rows.append(f"| {kind} | {b:+.2f} | {a:+.2f} |")
    extra = (
        f"\nSigned values: heading error {before.heading_error_deg:+.2f}° → "
        f"{after.heading_error_deg:+.2f}° over {after.turns:.2f} turns; longitudinal error "
        f"{100 * before.longitudinal_error_m:+.1f} cm → {100 * after.longitudinal_error_m:+.1f} cm "
        f"over {after.longitudinal_distance_m:.2f} m of odometry (negative: the robot fell "
        f"short); lateral drift over {after.lateral_distance_m:.2f} m of lateral travel.\n"
    )
    return "\n".join(rows) + "\n" + extra


def _iterations_table(iterations: Sequence[Iteration]) -> str:
    head = ["Iteration", *(_SHORT[n] for n in FACTOR_NAMES), "Within tolerance"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    if iterations:
        first = iterations[0].installed
        cells = ["installed before", *(_value(n, getattr(first, n)) for n in FACTOR_NAMES), ""]
        rows.append("| " + " | ".join(cells) + " |")
    for it in iterations:
        cells = [str(it.index)]
        for name in FACTOR_NAMES:
            cells.append(
                f"{_value(name, getattr(it.factors, name))}<br>({_change(name, it.change[name])})"
            )
        cells.append("yes" if it.converged else "no")
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n"


def _validation_table(validation: Validation) -> str:
    res = validation.residual
    z = validation.z_scores()
    rows = [
        "| Factor | Residual | ± 1σ | Residual / σ |",
        "|---|---|---|---|",
    ]
    for name in FACTOR_NAMES:
        value = getattr(res, name)
        sigma = validation.estimate.sigma[name]
        if _is_scale(name):
            shown = f"{100.0 * (value - 1.0):+.3f} %"
            s = f"{100.0 * sigma / getattr(validation.estimate.installed, name):.3f} %"
        else:
            shown = f"{1e3 * value:+.2f} mrad/m"
            s = f"{1e3 * sigma:.2f} mrad/m"
        zs = f"{z[name]:+.1f}" if math.isfinite(z[name]) else "—"
        rows.append(
            f"| {FACTOR_LABELS[name]} | {shown} | {s if math.isfinite(sigma) else '—'} | {zs} |"
        )
    return "\n".join(rows) + "\n"


_FIGURE_CAPTIONS = (
    ("iter1-rotation", "Rotation procedure, first iteration (as seed 000 Figure 8)."),
    ("iter2-rotation", "Rotation procedure, second iteration (as seed 000 Figure 9)."),
    ("iter1-longitudinal", "Longitudinal procedure, first iteration (as seed 000 Figure 10)."),
    (
        "validation-longitudinal",
        "Longitudinal procedure with the final factors installed (as seed 000 Figure 11).",
    ),
    ("iter1-lateral", "Lateral procedure, first iteration (as seed 000 Figure 12)."),
    (
        "validation-lateral",
        "Lateral procedure with the final factors installed (as seed 000 Figure 13).",
    ),
    ("validation-rotation", "Rotation procedure with the final factors installed."),
)


def _figures_section(files: Mapping[str, Path], out_dir: Path) -> str:
    figures = {k.removeprefix("figure:"): p for k, p in files.items() if k.startswith("figure:")}
    if not figures:
        return ""
    lines = [
        "## Figures",
        "",
        (
            "Black: odometry (of the hedgehog, initialised from the IPS at the first stand-still and "
            "turned along the first move, as seed 000 does); blue points: IPS positions (omnical's "
            "robust multilateration of the raw distances); red: the arcs fitted to each "
            "translation, numbered in the order of travel; orange circles: stand-still averages; "
            "light red square and blue circle: final positions by odometry and by the IPS. Grid "
            "0.5 m."
        ),
        "",
    ]
    shown: set[str] = set()
    order = [name for name, _ in _FIGURE_CAPTIONS] + sorted(figures)
    captions = dict(_FIGURE_CAPTIONS) | {"measures": "The paper's measures before and after."}
    for name in order:
        if name in shown or name not in figures:
            continue
        shown.add(name)
        rel = _relative(figures[name], out_dir)
        caption = captions.get(name) or _caption(name)
        lines += [f"**{name}** — {caption}", "", f"![{name}]({rel})", ""]
    return "\n".join(lines)


def _caption(name: str) -> str:
    stage, _, kind = name.partition("-")
    if stage.startswith("iter") and kind:
        return f"{kind.capitalize()} procedure, iteration {stage.removeprefix('iter')}."
    return name


def _relative(path: Path, base: Path) -> str:
    try:
        return path.relative_to(base).as_posix()
    except ValueError:
        return path.as_posix()


def _tolerance_text(result: CampaignResult) -> str:
    tol = result.tolerance
    return (
        f"{100 * tol.scale_relative:.2g} % for the scalings, "
        f"{1e3 * tol.crosstalk_rad_per_m:.2g} mrad/m for the cross-talks"
    )


def campaign_report_text(result: CampaignResult) -> str:
    """The Markdown report of a campaign (module docstring).

    Args:
        result: what :func:`~omnical.calibration.campaign.run_campaign` found.

    Returns:
        The report text.
    """
    n = len(result.iterations)
    status = (
        f"converged after {n} iteration{'s' if n > 1 else ''}"
        if result.converged
        else f"**did not converge** within {n} iterations (the last factors are reported)"
    )
    lines = [
        f"# Calibration report — {result.robot_name}",
        "",
        (
            f"Seed 000 Figure 7 on the {'digital twin' if result.truth is not None else 'robot'}: "
            f"rotation procedure first, then the longitudinal and lateral procedures, iterated "
            f"until no factor changes by more than {_tolerance_text(result)}; {status}. "
            f"Estimation: `{result.method}`; seed {result.seed}; "
            f"{result.robot_time_s / 60.0:.1f} min of robot time; "
            f"{result.wall_time_s:.1f} s of wall time (before this report was written)."
        ),
        "",
        "## Correction factors (seed 000 Table 2)",
        "",
        (
            "Sign conventions of docs/CONVENTIONS.md: a scaling k > 1 means the robot falls short "
            "of its odometry; a cross-talk is the real yaw per metre, counter-clockwise positive "
            "(seed 000 gives magnitudes only)."
        ),
        "",
        factors_table(result.factors, result.sigma, result.truth),
    ]
    if result.measures_before is not None and result.measures_after is not None:
        lines += [
            "## Before and after calibration (seed 000 §3.2)",
            "",
            (
                "The same measurement scripts run uncalibrated and calibrated on the twin, measured "
                "against its ground truth (used for measuring only, never for estimating): 3 turns "
                "in place; 10 m of odometry travel as four 2.5 m legs forward/reverse; the same "
                "left/right (lateral drift: how far each leg really ends off its line, summed); "
                "cross-talk from the real heading change per real metre of each leg."
            ),
            "",
            measures_table(result.measures_before, result.measures_after),
            _crosstalk_detail(result.measures_before, result.measures_after),
        ]
    lines += [
        "## Iterations",
        "",
        (
            "Totals of each iteration (installed for the next), change from the factors installed "
            "at its start in brackets. Cross-talks in rad/m."
        ),
        "",
        _iterations_table(result.iterations),
    ]
    if result.validation is not None:
        lines += [
            "## Validation",
            "",
            (
                "The three procedures once more with the final factors installed; what they still "
                "measure (the residual) should be zero within its uncertainty."
            ),
            "",
            _validation_table(result.validation),
        ]
    notes = [
        f"iteration {it.index} {stage}: {note}"
        for it in result.iterations
        for stage, est in (("rotation", it.rotation), ("translation", it.translation))
        for note in est.notes
    ]
    if result.validation is not None:
        notes += [f"validation: {note}" for note in result.validation.estimate.notes]
    if notes:
        lines += ["## Notes", "", *(f"- {note}" for note in notes), ""]
    if result.out_dir is not None:
        figures = _figures_section(result.files, result.out_dir)
        if figures:
            lines += [figures]
        lines += _files_section(result)
    return "\n".join(lines).rstrip() + "\n"


def _files_section(result: CampaignResult) -> list[str]:
    assert result.out_dir is not None
    out = result.out_dir
    roles = {
        "factors": "the factors with one-sigma uncertainties",
        "header": "C header for the vehicle-controller firmware",
        "ros_params": "ROS 2 parameters for the Wheeltec driver node",
    }
    lines = ["## Files", ""]
    for role, text in roles.items():
        if role in result.files:
            lines.append(f"- `{_relative(result.files[role], out)}`: {text}")
    bags = {
        k.removeprefix("recording:"): p
        for k, p in result.files.items()
        if k.startswith("recording:")
    }
    if bags:
        lines.append(
            "- `recordings/`: the procedure and validation runs (ROS 2 bags, MCAP); "
            "each carries the factors it ran with on `/omnical/events`"
        )
        lines += [
            "",
            "Re-run the analysis offline, for example on the validation runs:",
            "",
            "```sh",
        ]
        chosen = [p for name, p in bags.items() if name.startswith("validation-")] or list(
            bags.values()
        )
        args = " ".join(_relative(p, out) for p in chosen)
        lines.append(
            f"omnical calibrate {args} --robot {result.robot_name} --out revalidated/factors.yaml"
        )
        lines += ["```", ""]
    return lines


def write_report(path: str | Path, text: str) -> Path:
    """Write the report; returns the path.

    Raises:
        ConfigError: the file cannot be written.
    """
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text, encoding="utf-8")
    except OSError as err:
        msg = f"{p}: cannot write: {err.strerror or err}"
        raise ConfigError(msg) from None
    return p
