"""The report tables: seed 000 Tables 2 and 4, the §3.2 measures, iterations, tracking metrics.

Each a :class:`~omnical.reports.markdown.MarkdownTable`, the paper's numbers beside omnical's;
:func:`table4` compares the paper's "position" row with ``rmse_per_axis_m``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

from omnical.calibration.measures import MEASURE_SPECS, Measures, MeasureSpec
from omnical.evaluation.metrics import IPS_KEY, ODOMETRY_KEY, TrackingMetrics
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import CROSSTALKS, FACTORS, Factor
from omnical.paper import SEED000_TABLE2, SEED000_TABLE4, Table4Numbers
from omnical.reports.markdown import MarkdownTable

if TYPE_CHECKING:
    from omnical.calibration.campaign import Iteration, Validation

__all__ = [
    "crosstalk_table",
    "factors_table",
    "iterations_table",
    "measures_table",
    "metrics_table",
    "table4",
    "validation_table",
]

_PAPER_TABLE2 = dict(zip(FACTORS, SEED000_TABLE2, strict=True))


def _value(factor: Factor, value: float) -> str:
    if not math.isfinite(value):
        return "—"
    return f"{value:.5f}" if factor.is_scale else f"{value:+.5f}"


def _error(factor: Factor, value: float, truth: float) -> str:
    if factor.is_scale:
        return f"{100.0 * (value / truth - 1.0):+.3f} %"
    return f"{1e3 * (value - truth):+.2f} mrad/m"


def _change(factor: Factor, change: float) -> str:
    return f"{100.0 * change:+.3f} %" if factor.is_scale else f"{1e3 * change:+.2f} mrad/m"


def factors_table(
    factors: CorrectionFactors,
    sigma: Mapping[str, float],
    truth: CorrectionFactors | None = None,
) -> MarkdownTable:
    """Seed 000 Table 2, with ± 1σ, the paper's values and, if known, the truth and the error.

    Args:
        factors: the estimated factors.
        sigma: factor field name → one-sigma uncertainty (``inf``/NaN: not estimated).
        truth: the twin's true factors, for the truth and error columns.
    """
    head = ["Type", "Factor", "± 1σ"]
    if truth is not None:
        head += ["Truth (twin)", "Error"]
    head += ["Seed 000", "Unit of measure"]
    rows = []
    for f in FACTORS:
        value = getattr(factors, f.field)
        s = sigma.get(f.field, math.nan)
        cells = [f.label, _value(f, value), f"{s:.5f}" if math.isfinite(s) else "not estimated"]
        if truth is not None:
            cells += [_value(f, getattr(truth, f.field)), _error(f, value, getattr(truth, f.field))]
        paper = _PAPER_TABLE2[f]
        cells.append(f"{paper:.4f}" if f.is_scale else f"{paper:.5f} (magnitude)")
        cells.append("scaling — no unit" if f.is_scale else "rad m⁻¹")
        rows.append(tuple(cells))
    return MarkdownTable(tuple(head), tuple(rows), align=("l",) * len(head))


def _fmt(value: float) -> str:
    return f"{value:.3g}" if abs(value) < 100 else f"{value:.0f}"


def measures_table(
    before: Measures, after: Measures, specs: Sequence[MeasureSpec] = MEASURE_SPECS
) -> MarkdownTable:
    """The paper's before/after measures (seed 000 §3.2), seed 000's figures beside the twin's."""
    head = (
        "Measure",
        "Unit",
        "Seed 000 before",
        "Twin before",
        "Seed 000 after",
        "Twin after",
        "At least as good as seed 000",
    )
    rows = tuple(
        (
            spec.label,
            spec.unit,
            _fmt(spec.paper_before),
            _fmt(spec.value(before)),
            f"< {_fmt(spec.paper_after)}",
            _fmt(spec.value(after)),
            "yes" if spec.passes(after) else "**no**",
        )
        for spec in specs
    )
    return MarkdownTable(head, rows, align=("l",) * len(head))


def crosstalk_table(before: Measures, after: Measures) -> MarkdownTable:
    """The signed cross-talk the twin really makes per direction, before and after."""
    rows = tuple(
        (
            f.yaml_key,
            f"{1e3 * before.crosstalk_rad_per_m[f.yaml_key]:+.2f}",
            f"{1e3 * after.crosstalk_rad_per_m[f.yaml_key]:+.2f}",
        )
        for f in CROSSTALKS
    )
    note = (
        f"Signed values: heading error {before.heading_error_deg:+.2f}° → "
        f"{after.heading_error_deg:+.2f}° over {after.turns:.2f} turns; longitudinal error "
        f"{100 * before.longitudinal_error_m:+.1f} cm → {100 * after.longitudinal_error_m:+.1f} cm "
        f"over {after.longitudinal_distance_m:.2f} m of odometry (negative: the robot fell "
        f"short); lateral drift over {after.lateral_distance_m:.2f} m of lateral travel."
    )
    return MarkdownTable(
        ("Direction", "Twin before (mrad/m)", "Twin after (mrad/m)"), rows, note=note
    )


def iterations_table(iterations: Sequence[Iteration]) -> MarkdownTable:
    """Totals of each iteration with the change from the factors installed at its start."""
    head = ("Iteration", *(f.short for f in FACTORS), "Within tolerance")
    rows: list[tuple[str, ...]] = []
    if iterations:
        first = iterations[0].installed
        rows.append(
            ("installed before", *(_value(f, getattr(first, f.field)) for f in FACTORS), "")
        )
    for it in iterations:
        cells = [str(it.index)]
        for f in FACTORS:
            total = _value(f, getattr(it.factors, f.field))
            cells.append(f"{total}<br>({_change(f, it.change[f.field])})")
        cells.append("yes" if it.converged else "no")
        rows.append(tuple(cells))
    return MarkdownTable(head, tuple(rows), align=("l",) * len(head))


def validation_table(validation: Validation) -> MarkdownTable:
    """What the validation runs still measure, with ± 1σ and the ratio."""
    res = validation.residual
    z = validation.z_scores()
    rows = []
    for f in FACTORS:
        value = getattr(res, f.field)
        sigma = validation.estimate.sigma[f.field]
        if f.is_scale:
            shown = f"{100.0 * (value - 1.0):+.3f} %"
            s = f"{100.0 * sigma / getattr(validation.estimate.installed, f.field):.3f} %"
        else:
            shown = f"{1e3 * value:+.2f} mrad/m"
            s = f"{1e3 * sigma:.2f} mrad/m"
        zs = f"{z[f.field]:+.1f}" if math.isfinite(z[f.field]) else "—"
        rows.append((f.label, shown, s if math.isfinite(sigma) else "—", zs))
    return MarkdownTable(
        ("Factor", "Residual", "± 1σ", "Residual / σ"), tuple(rows), align=("l",) * 4
    )


def metrics_table(results: Mapping[str, TrackingMetrics]) -> MarkdownTable:
    """Every measure of every estimate (Euclidean position RMSE, per axis, max, final), m."""
    rows = tuple(
        (
            name,
            *(f"{v:.4f}" for v in (m.rmse_m, m.rmse_x_m, m.rmse_y_m, m.max_m, m.final_m)),
        )
        for name, m in results.items()
    )
    return MarkdownTable(
        ("estimate", "RMSE position (m)", "RMSE x (m)", "RMSE y (m)", "max (m)", "final (m)"), rows
    )


def _m(value: float | None) -> str:
    return "—" if value is None else f"{value:.4f}"


def table4(
    metrics_before: Mapping[str, TrackingMetrics] | None,
    metrics_after: Mapping[str, TrackingMetrics] | None,
    paper: Table4Numbers | None = SEED000_TABLE4,
    *,
    ips_key: str = IPS_KEY,
) -> MarkdownTable:
    """Seed 000 Table 4, omnical's RMSE beside the paper's, uncalibrated vs calibrated.

    Rows: position as Table 4 defines it (sqrt((x² + y²) / 2)), x, y, and the Euclidean
    position RMSE (evo's APE; the paper's value derived as sqrt(x² + y²), in parentheses).
    Columns: for uncalibrated then calibrated kinematics, odometry and IPS, each "omnical" and,
    when ``paper`` is given, "paper".

    Args:
        metrics_before: estimate name → metrics with uncalibrated kinematics (None: "—").
        metrics_after: the same with calibrated kinematics (None: "—").
        paper: the paper's numbers (default :data:`omnical.paper.SEED000_TABLE4`); None leaves them out.
        ips_key: which estimate fills the IPS columns (``ips`` = the vendor's fixes;
            ``multilateration`` for omnical's).
    """
    header = ["RMSE (m)"]
    Column = tuple[bool, TrackingMetrics | None, tuple[float, float, float] | None]
    columns: list[Column] = []  # (is the paper's, omnical's metrics, the paper's numbers)
    for phase, results in (("uncalibrated", metrics_before), ("calibrated", metrics_after)):
        for key, paper_key, label in (
            (ODOMETRY_KEY, ODOMETRY_KEY, "odometry"),
            (ips_key, IPS_KEY, "IPS"),
        ):
            header.append(f"{phase} {label}")
            columns.append((False, None if results is None else results.get(key), None))
            if paper is not None:
                header.append(f"{phase} {label} (paper)")
                columns.append((True, None, paper.get(phase, {}).get(paper_key)))

    def row(label: str, ours_of: str, paper_of: int | None) -> tuple[str, ...]:
        cells = [label]
        for is_paper, ours, theirs in columns:
            if not is_paper:
                cells.append(_m(None if ours is None else float(getattr(ours, ours_of))))
            elif theirs is None:
                cells.append("—")
            elif paper_of is None:
                cells.append(f"({(theirs[1] ** 2 + theirs[2] ** 2) ** 0.5:.4f})")
            else:
                cells.append(_m(theirs[paper_of]))
        return tuple(cells)

    rows = (
        row("position (Table 4: √((x²+y²)/2))", "rmse_per_axis_m", 0),
        row("x", "rmse_x_m", 1),
        row("y", "rmse_y_m", 2),
        row("position, Euclidean (evo APE)", "rmse_m", None),
    )
    note = (
        "Seed 000 Table 4's position row equals √((x²+y²)/2) of its x and y rows in every "
        "column; the Euclidean RMSE √(x²+y²) is evo's APE translation RMSE. Paper values in "
        "parentheses are derived from its x and y rows."
    )
    if paper is None:
        note = "The Euclidean RMSE √(x²+y²) is evo's APE translation RMSE."
    return MarkdownTable(
        tuple(header),
        rows,
        caption="Root-mean-squared trajectory tracking deviation (seed 000 Table 4)",
        note=note,
    )
