"""The report of ``omnical fleet`` (factors across the fleet, maintenance alerts) and of
``omnical sweep`` (accuracy against each varied parameter), with their figures.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Final

import numpy as np

from omnical.calibration.drift import ALERT_SIGMAS, Alert, FactorSpread
from omnical.reports.markdown import FigureLink, MarkdownTable, Section, write_markdown_report

__all__ = [
    "LOST",
    "REFERENCE",
    "REFERENCE_TIMES",
    "SweepAccuracy",
    "sweep_accuracy",
    "write_fleet_report",
    "write_sweep_report",
]

_Rows = Sequence[Mapping[str, str]]

_ANSWER_SHARE = 0.9
"""A bin of a varied parameter "reaches" the target when this share of its runs is within it."""


def _g(text: str, digits: int = 5) -> str:
    try:
        value = float(text)
    except ValueError:
        return text
    return "" if math.isnan(value) else f"{value:.{digits}g}"


LOST: Final = "lost"
"""The status of a row the executor lost (``omnical.fleet.table.LOST``, the layer above: a test
holds them equal); ``--resume`` runs it again."""

_LOST_NOTE = "the executor lost them, not their recordings' fault: re-run with --resume"


def _counts(rows: _Rows, unit: str) -> str:
    """``N UNIT: a ok, b error[, c lost (…: re-run with --resume)].``"""
    lost = sum(row["status"] == LOST for row in rows)
    ok = sum(row["status"] == "ok" for row in rows)
    text = f"{len(rows)} {unit}: {ok} ok, {len(rows) - ok - lost} error"
    return text + (f", {lost} lost ({_LOST_NOTE})." if lost else ".")


def _status_section(rows: _Rows) -> Section:
    failed = [row for row in rows if row["status"] != "ok"]
    lines: list[str | MarkdownTable] = [_counts(rows, "recordings")]
    if failed:
        lines.append(
            MarkdownTable(
                ("recording", "status", "reason"),
                tuple(
                    (
                        row["name"],
                        row["status"],
                        f"{row['reason']} (re-run with --resume)"
                        if row["status"] == LOST
                        else row["reason"],
                    )
                    for row in failed
                ),
                caption="Recordings without a result",
            )
        )
    return Section("Recordings", tuple(lines))


def _factor_sections(
    rows: _Rows,
    factors: Sequence[str],
    spreads: Sequence[FactorSpread],
    alerts: Sequence[Alert],
    figures: Path,
    previous: str,
) -> list[Section]:
    from omnical.reports.figures.fleet import plot_factors_per_recording

    spread_table = MarkdownTable(
        ("factor", "recordings", "fleet mean", "fleet std", "median own 1σ", "min", "max"),
        tuple(
            (
                s.factor,
                str(s.count),
                f"{s.mean:.6g}",
                f"{s.std:.3g}",
                f"{s.median_sigma:.3g}",
                f"{s.low:.6g}",
                f"{s.high:.6g}",
            )
            for s in spreads
        ),
        caption="The factors across the fleet",
        note="Scalings are ratios (1 = nominal); cross-talks rad/m.",
    )
    ok = [row for row in rows if row["status"] == "ok"]
    per_recording = MarkdownTable(
        ("recording", *factors),
        tuple(
            (
                row["name"],
                *(f"{_g(row[f], 6)} ± {_g(row[f + '_sigma'], 2)}" for f in factors),
            )
            for row in ok
        ),
        caption="Each recording's factors ± 1σ",
    )
    against = "the fleet (the others' median and robust spread)" + (
        f" and the previous calibration in {previous}" if previous else ""
    )
    if alerts:
        alert_block: MarkdownTable | str = MarkdownTable(
            ("recording", "factor", "value", "against", "reference", "combined 1σ", "z"),
            tuple(
                (
                    a.name,
                    a.factor,
                    f"{a.value:.6g}",
                    a.against,
                    f"{a.reference:.6g}",
                    f"{a.sigma:.3g}",
                    f"{a.z:+.1f}",
                )
                for a in alerts
            ),
            caption=f"Maintenance alerts: more than {ALERT_SIGMAS:g}σ from {against}",
        )
    else:
        alert_block = f"No factor is more than {ALERT_SIGMAS:g}σ from {against}."
    figure = plot_factors_per_recording(ok, factors, alerts, figures / "factors.png")
    return [
        Section("Maintenance alerts", (alert_block,)),
        Section("Factors", (spread_table, per_recording, FigureLink(figure, "factors"))),
    ]


REFERENCE: Final = "reference"
"""The column of the reference a row was measured against (``omnical.fleet.jobs.REFERENCE``,
the layer above: a test holds them equal), and :data:`REFERENCE_TIMES` the rule of its times."""
REFERENCE_TIMES: Final = "reference_times"


def _short(text: str, most: int = 40) -> str:
    """A reference for a figure's label: as it is, or a long path's file name."""
    return text if len(text) <= most else f".../{Path(text).name}"


def _reference_section(ok: _Rows, given: str) -> tuple[Section, str]:
    """What the ok rows were measured against (one line when one reference, with the rule of
    its times, else a row each), and the name for a figure's label."""
    used = {(row.get(REFERENCE, ""), row.get(REFERENCE_TIMES, "")) for row in ok}
    if len(used) == 1:
        ((reference, times),) = used
        line = f"Every recording against {reference}" + (f"; its times: {times}." if times else ".")
        return Section("Reference", (line,)), _short(reference)
    table = MarkdownTable(
        ("recording", "reference", "its times"),
        tuple((row["name"], row.get(REFERENCE, ""), row.get(REFERENCE_TIMES, "")) for row in ok),
        caption=f"Each recording's reference (given: {given})",
    )
    return Section("Reference", (table,)), f"each recording's {_short(given)}"


def write_fleet_report(
    out: Path,
    command: str,
    header: Sequence[str],
    rows: _Rows,
    *,
    factors: Sequence[str] = (),
    spreads: Sequence[FactorSpread] = (),
    alerts: Sequence[Alert] = (),
    previous: str = "",
    reference: str = "",
) -> Path:
    """``out/report.md`` and ``out/figures/``: each recording's figures; for ``calibrate`` the
    factors across the fleet with their 1σ and the maintenance alerts. ``reference``: the one
    the options name (``evaluate``, ``calibrate``); each row's own is said (its column)."""
    from omnical.reports.figures.fleet import plot_column_per_recording

    figures = out / "figures"
    sections = [_status_section(rows)]
    ok = [row for row in rows if row["status"] == "ok"]
    against = ""
    if reference and ok:
        section, against = _reference_section(ok, reference)
        sections.append(section)
    if command == "calibrate" and ok:
        sections += _factor_sections(rows, factors, spreads, alerts, figures, previous)
    elif ok:
        columns = [c for c in header[5:] if c not in (REFERENCE, REFERENCE_TIMES)]
        table = MarkdownTable(
            ("recording", *columns),
            tuple((row["name"], *(_g(row.get(c, "")) for c in columns)) for row in ok),
            caption=f"omnical {command}, per recording",
        )
        shown = [c for c in columns if c.endswith("_rmse_m")] or [
            "usable_fraction",
        ]
        ylabel = f"RMSE against {against or 'the reference'}, m" if against else "fraction"
        figure = plot_column_per_recording(ok, shown, ylabel, figures / f"{command}.png")
        sections.append(Section("Figures", (table, FigureLink(figure, command))))
    title = f"Fleet {command}: {len(rows)} recordings"
    return write_markdown_report(out, title, sections)


def _lost_hint(status: str, reason: str) -> str:
    """A row's reason, with "re-run with --resume" when the executor lost it."""
    return f"{reason} (re-run with --resume)" if status == LOST else reason


class SweepAccuracy:
    """A sweep's accuracy in bins of one varied parameter.

    Attributes:
        parameter: its column.
        bins: (low, high, runs, median error, fraction within the target) per bin.
    """

    def __init__(
        self, parameter: str, bins: Sequence[tuple[float, float, int, float, float]]
    ) -> None:
        self.parameter = parameter
        self.bins = tuple(bins)


def sweep_accuracy(
    rows: _Rows, parameter: str, error: str, target: float, max_bins: int = 6
) -> SweepAccuracy:
    """The ok runs' ``error`` (absolute) in bins of ``parameter``: its distinct values when
    few, else quantile bins."""
    p = np.array([float(r[parameter]) for r in rows if r["status"] == "ok"])
    e = np.abs(np.array([float(r[error]) for r in rows if r["status"] == "ok"]))
    keep = np.isfinite(p) & np.isfinite(e)
    p, e = p[keep], e[keep]
    bins = []
    distinct = np.unique(p)
    if len(distinct) <= max_bins:
        groups = [(v, v, p == v) for v in distinct]
    else:
        edges = np.quantile(p, np.linspace(0.0, 1.0, max_bins + 1))
        index = np.clip(np.searchsorted(edges, p, side="right") - 1, 0, max_bins - 1)
        groups = [(edges[b], edges[b + 1], index == b) for b in range(max_bins)]
    for low, high, mask in groups:
        if mask.any():
            within = float(np.mean(e[mask] <= target))
            bins.append(
                (float(low), float(high), int(mask.sum()), float(np.median(e[mask])), within)
            )
    return SweepAccuracy(parameter, bins)


def write_sweep_report(
    out: Path,
    rows: _Rows,
    varied: Sequence[str],
    *,
    error: str,
    error_label: str,
    target: float,
    spec_text: str,
) -> Path:
    """``out/report.md`` and ``out/figures/``: the accuracy of the recovered factors against each
    varied parameter (a table of bins and a figure each)."""
    from omnical.reports.figures.fleet import plot_sweep_accuracy

    ok = [row for row in rows if row["status"] == "ok"]
    overall = np.abs(np.array([float(r[error]) for r in ok])) if ok else np.zeros(0)
    overall = overall[np.isfinite(overall)]
    summary = (
        _counts(rows, "runs")
        + " "
        + (
            f"{error_label}: median {np.median(overall):.3g}, 90th percentile "
            f"{np.quantile(overall, 0.9):.3g}; {100 * np.mean(overall <= target):.1f} % of the "
            f"runs within {target:g}."
            if overall.size
            else ""
        )
    )
    sections = [Section("Runs", (summary, f"The spec:\n\n```yaml\n{spec_text.rstrip()}\n```"))]
    failed = [r for r in rows if r["status"] != "ok"]
    if failed:
        reasons: dict[tuple[str, str], int] = {}
        for r in failed:
            key = (r["status"], r["reason"])
            reasons[key] = reasons.get(key, 0) + 1
        sections.append(
            Section(
                "Runs without a result",
                (
                    MarkdownTable(
                        ("status", "reason", "runs"),
                        tuple(
                            (status, _lost_hint(status, reason), str(n))
                            for (status, reason), n in sorted(
                                reasons.items(), key=lambda kv: -kv[1]
                            )
                        ),
                    ),
                ),
            )
        )
    for parameter in varied:
        if not ok:
            break
        acc = sweep_accuracy(ok, parameter, error, target)
        table = MarkdownTable(
            (parameter, "runs", f"median {error_label}", f"within {target:g}"),
            tuple(
                (
                    f"{lo:.4g}" if lo == hi else f"{lo:.4g} – {hi:.4g}",
                    str(n),
                    f"{med:.3g}",
                    f"{100 * frac:.0f} %",
                )
                for lo, hi, n, med, frac in acc.bins
            ),
        )
        figure = plot_sweep_accuracy(
            [float(r[parameter]) for r in ok],
            [float(r[error]) for r in ok],
            parameter_label=parameter,
            error_label=error_label,
            target=target,
            path=out / "figures" / f"{parameter.replace('.', '_')}.png",
        )
        good = [
            f"{lo:.4g}" if lo == hi else f"{lo:.4g} – {hi:.4g}"
            for lo, hi, _, _, frac in acc.bins
            if frac >= _ANSWER_SHARE
        ]
        answer = (
            f"At least {100 * _ANSWER_SHARE:.0f} % of the runs within {target:g} for "
            f"{parameter} {', '.join(good)}."
            if good
            else f"In no bin of {parameter} are {100 * _ANSWER_SHARE:.0f} % of the runs within "
            f"{target:g}."
        )
        sections.append(
            Section(f"Against {parameter}", (answer, table, FigureLink(figure, parameter)))
        )
    return write_markdown_report(out, f"Sweep: {len(rows)} twin campaigns", sections)
