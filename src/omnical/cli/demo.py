"""``omnical demo``: seed 000's story on the rosy-mecanum twin, in one report (written whole)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.options import Overwrite, Seed
from omnical.cli.output import console, say

if TYPE_CHECKING:
    from omnical.reports.demo import DemoFiles
    from omnical.services.demo import DemoResult

__all__ = ["demo"]


def demo(
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Output directory (report.md at its top).")
    ] = Path("omnical-out"),
    seed: Seed = 0,
    overwrite: Overwrite = False,
    navigation: Annotated[
        bool,
        typer.Option(
            help="Include the navigation chapter: mapping, SLAM, three goals (half the time)."
        ),
    ] = True,
) -> None:
    """Calibrate the rosy-mecanum twin and show what it buys, in OUT/report.md.

    The Lissajous of seed 000 open loop on the uncalibrated twin, the calibration campaign,
    the same Lissajous calibrated (measured by ground truth and by the sensors alone),
    seed 001's closed-loop paths, seed 003's motor tuning and four tests on the omni-X twin,
    and navigation on lab-8x6 (mapping, SLAM, three goals). Prints the headline numbers.
    """
    with handled_errors():
        _print_demo(*_run_and_write_demo(out, seed, overwrite, navigation))


def _run_and_write_demo(
    out: Path, seed: int, overwrite: bool, navigation: bool
) -> tuple[DemoResult, DemoFiles]:
    """The calls of ``omnical demo`` into the library: run the demo, write its report."""
    from omnical.cli.output import tell
    from omnical.reports.demo import write_demo
    from omnical.reports.outputs import claim_directory
    from omnical.services.demo import run_demo

    claim_directory(out, overwrite=overwrite, writer="omnical demo", notify=tell)

    with console().status("omnical demo") as status:

        def progress(msg: str) -> None:
            status.update(f"omnical demo: {msg}")

        result = run_demo(seed=seed, progress=progress, with_navigation=navigation)
        files = write_demo(result, out, on_progress=progress, overwrite=overwrite, notify=tell)
        return result, files


def _print_demo(result: DemoResult, files: DemoFiles) -> None:
    from rich.table import Table

    from omnical.evaluation.metrics import GROUND_TRUTH_KEY
    from omnical.paper import SEED000_IMPROVEMENT, SEED000_TABLE4

    before, after = result.before, result.after
    table = Table(title="open-loop Lissajous on the rosy-mecanum twin (Euclidean RMSE, m)")
    table.add_column("estimate")
    table.add_column("uncalibrated", justify="right")
    table.add_column("calibrated", justify="right")
    for name in before:
        if name in after:
            table.add_row(name, f"{before[name].rmse_m:.4f}", f"{after[name].rmse_m:.4f}")
    out = console()
    out.print(table)
    # beside the paper's numbers, the paper's convention: per axis, sqrt((x² + y²) / 2)
    gt_b, gt_a = before[GROUND_TRUTH_KEY], after[GROUND_TRUTH_KEY]
    paper_b = SEED000_TABLE4["uncalibrated"]["ips"][0]
    paper_a = SEED000_TABLE4["calibrated"]["ips"][0]
    out.print(
        f"ground truth: {result.improvement:.1f}x lower RMSE after calibration "
        f"(seed 000: {SEED000_IMPROVEMENT:.1f}x)"
    )
    out.print(
        f"  per axis as seed 000 Table 4: {gt_b.rmse_per_axis_m:.4f} -> "
        f"{gt_a.rmse_per_axis_m:.4f} m (seed 000's IPS: {paper_b:.4f} -> {paper_a:.4f} m); "
        f"Euclidean {gt_b.rmse_m:.4f} -> {gt_a.rmse_m:.4f} m"
    )
    measured = result.measured_improvement
    if measured is not None:
        out.print(f"measured from the sensors alone (smoothed IPS + odometry): {measured:.1f}x")
    for path in result.paths:
        error_cm = path.final_vs_ground_truth_m * 100
        out.print(f"closed loop, {path.name}: final error {error_cm:.1f} cm (ground truth)")
    tuning = result.seed003.tuning
    out.print(
        f"seed 003 on the omni-X twin: Ku {tuning.ultimate.ku:.1f}, Pu "
        f"{tuning.ultimate.pu_s * 1e3:.0f} ms, installed {tuning.chosen.rule.value}"
    )
    for test in result.seed003.tests:
        e, t = test.estimate_errors, test.truth_errors
        out.print(
            f"  {test.name}: estimate {e.first:.2f} / {e.second:.2f}, "
            f"ground truth {t.first:.2f} / {t.second:.2f}"
        )
    if result.navigation is not None:
        legs = result.navigation.navigation.legs
        worst = max((leg.goal_error_m for leg in legs), default=float("nan"))
        out.print(
            f"navigation on {result.navigation.world_name}: {len(legs)} goals, worst "
            f"{worst * 100:.1f} cm, collision: {result.navigation.navigation.collision or 'none'}"
        )
    say(f"report: {files.report}")
