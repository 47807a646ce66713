"""``omnical seed003``: seed 003 end to end on the omni-X twin, in one report (written whole)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.options import Overwrite, Seed
from omnical.cli.output import console, say

__all__ = ["seed003"]


def seed003(
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Output directory (report.md at its top).")
    ] = Path("omnical-seed003"),
    seed: Seed = 0,
    overwrite: Overwrite = False,
) -> None:
    """Seed 003 on the omni-X twin: Ziegler–Nichols motor tuning, Table II, its four tests.

    Tunes the twin's wheel-speed PID at 100 rpm, installs it, and runs centred turning, driving
    forward, the square and the triangle closed on the dead-wheel + IMU estimate; writes
    OUT/report.md with the paper's numbers beside the twin's.
    """
    with handled_errors():
        import numpy as np

        from omnical.cli.output import tell
        from omnical.paper import SEED003_PAPER_TABLE2, SEED003_PAPER_TEST_ERRORS
        from omnical.reports.outputs import claim_directory
        from omnical.reports.seed003 import write_seed003
        from omnical.services.seed003 import ERROR_LABELS, run_seed003

        claim_directory(out, overwrite=overwrite, writer="omnical seed003", notify=tell)
        with console().status("omnical seed003") as status:
            result = run_seed003(
                seed=seed, progress=lambda msg: status.update(f"omnical seed003: {msg}")
            )
            files = write_seed003(result, out, overwrite=overwrite, notify=tell)
        tuning = result.tuning
        u, chosen = tuning.ultimate, tuning.chosen
        refined = (
            f" (the classic PID row overshoots {tuning.classic.metrics.overshoot:.0%}: refined)"
            if tuning.refined
            else ""
        )
        say(
            f"wheel PID: Ku {u.ku:.3f}, Pu {u.pu_s * 1e3:.1f} ms; installed {chosen.rule.value} "
            f"(Kp {chosen.pid.kp:.3f}, Ti {chosen.pid.ti_s * 1e3:.1f} ms, "
            f"Td {chosen.pid.td_s * 1e3:.2f} ms), overshoot {chosen.metrics.overshoot:.0%}"
            f"{refined}"
        )
        sp = result.table2_setpoints_rpm[:, None]
        ours = float(np.abs(result.table2_means_rpm - sp).max())
        paper = float(np.abs(np.array(SEED003_PAPER_TABLE2) - sp).max())
        say(f"Table II: largest |error| {ours:.2f} rpm (paper {paper:.2f} rpm)")
        for test in result.tests:
            p_first, p_second = SEED003_PAPER_TEST_ERRORS[test.slug]
            for label, est, gt, pap in zip(
                ERROR_LABELS[test.slug],
                (test.estimate_errors.first, test.estimate_errors.second),
                (test.truth_errors.first, test.truth_errors.second),
                (p_first, p_second),
                strict=True,
            ):
                say(
                    f"{test.name}: {label}: estimate {est:.2f}, ground truth {gt:.2f}, "
                    f"paper {pap:g}"
                )
        say(f"report: {files.report}")
