"""What ``omnical calibrate`` prints: the factors table, the campaign's measures, the files.

Imported by the calibrate commands only when they run (rich tables, the calibration library).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

from rich.table import Table

from omnical.calibration.campaign import CampaignResult, FactorEstimate
from omnical.calibration.measures import MEASURE_SPECS
from omnical.choices import EstimationMethod
from omnical.cli.output import console, say
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import FACTORS

__all__ = ["factors_table", "print_campaign", "print_estimate"]


def factors_table(
    title: str,
    factors: CorrectionFactors,
    sigma: Mapping[str, float],
    truth: CorrectionFactors | None = None,
    held: Mapping[str, str] | None = None,
) -> Table:
    """One row per factor: value, 1σ (``held`` for a held factor), on a twin the truth and error."""
    table = Table(title=title)
    table.add_column("factor")
    table.add_column("value", justify="right")
    table.add_column("± 1σ", justify="right")
    if truth is not None:
        table.add_column("truth (twin)", justify="right")
        table.add_column("error", justify="right")
    for factor in FACTORS:
        value = getattr(factors, factor.field)
        s = sigma.get(factor.field, math.nan)
        unit = f" {factor.unit}" if factor.unit else ""
        row = [
            factor.key,
            f"{value:.5f}{unit}" if factor.is_scale else f"{value:+.5f}{unit}",
            "held"
            if held and factor.field in held
            else (f"{s:.5f}" if math.isfinite(s) else "not estimated"),
        ]
        if truth is not None:
            t = getattr(truth, factor.field)
            row.append(f"{t:.5f}" if factor.is_scale else f"{t:+.5f}")
            error = factor.change(t, value)
            row.append(f"{100 * error:+.3f} %" if factor.is_scale else f"{1e3 * error:+.2f} mrad/m")
        table.add_row(*row)
    return table


def print_campaign(
    result: CampaignResult, written: Sequence[str], *, command_wall_s: float | None = None
) -> None:
    """The factors, convergence, the before → after measures, ``written`` and the times.

    ``command_wall_s``: the command's wall time, running and writing (the recordings, report
    and figures); the campaign's own (``result.wall_time_s``) leaves the writing out.
    """
    out = console()
    title = f"{result.robot_name}: correction factors"
    out.print(factors_table(title, result.factors, result.sigma, result.truth))
    n = len(result.iterations)
    state = "converged" if result.converged else "[bold red]not converged[/bold red]"
    out.print(f"{n} iteration{'s' if n > 1 else ''}, {state}")
    before, after = result.measures_before, result.measures_after
    if before is not None and after is not None:
        table = Table(title="before → after calibration (seed 000 §3.2)")
        table.add_column("measure")
        table.add_column("seed 000", justify="right")
        table.add_column("twin", justify="right")
        table.add_column("", justify="left")
        for spec in MEASURE_SPECS:
            table.add_row(
                f"{spec.label} ({spec.unit})",
                f"{spec.paper_before:.3g} → < {spec.paper_after:.3g}",
                f"{spec.value(before):.3g} → {spec.value(after):.3g}",
                "ok" if spec.passes(after) else "[bold red]worse than seed 000[/bold red]",
            )
        out.print(table)
    for line in written:
        say(line)
    times = f"robot time {result.robot_time_s / 60.0:.1f} min, "
    if command_wall_s is None:
        times += f"wall time {result.wall_time_s:.1f} s (the campaign)"
    else:
        times += (
            f"wall time {command_wall_s:.1f} s (the campaign {result.wall_time_s:.1f} s, "
            f"writing the files {max(command_wall_s - result.wall_time_s, 0.0):.1f} s)"
        )
    out.print(times)


def print_estimate(
    robot_name: str, result: FactorEstimate, method: EstimationMethod, written: Sequence[Path]
) -> None:
    """The factors with their σ, what was installed, the hedgehog offset (joint), notes, files."""
    out = console()
    title = f"{robot_name}: correction factors"
    out.print(factors_table(title, result.factors, result.sigma, held=result.held))
    if result.installed != CorrectionFactors():
        installed = result.installed.as_dict()
        out.print(
            "installed during the recordings (the totals include them): "
            + ", ".join(f"{f.key} {installed[f.field]:.5g}" for f in FACTORS)
        )
    if method is EstimationMethod.JOINT:
        x, y = result.hedge_offset_xy_m
        out.print(f"hedgehog offset in base_link: x {x:+.3f} m, y {y:+.3f} m")
    for note in result.notes:
        say(f"note: {note}")
    if result.held:
        n = len(result.held)
        say(
            f"held {n} factor{'s' if n > 1 else ''} at the installed value (not supported by the "
            "recordings; marked so in the files):"
        )
        by_field = {f.field: f for f in FACTORS}
        for name, reason in result.held.items():
            say(f"  held {by_field[name].key}: {reason}")
    for path in written:
        say(f"wrote {path}")
