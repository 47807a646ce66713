"""``omnical sweep SPEC.yaml --runs N --seed S``: Monte-Carlo calibration campaigns on the twin,
one row per run in ``DIR/sweep.csv``, accuracy against each varied parameter in ``DIR/report.md``.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Annotated

import typer

from omnical.cli.errors import EXIT_NO_RESULT, handled_errors
from omnical.cli.fleet import Chunk, ExecutorOption, Resume, failures, kept
from omnical.cli.options import Overwrite, Seed

__all__ = ["sweep"]


def sweep(
    spec: Annotated[
        Path,
        typer.Argument(
            metavar="SPEC.yaml",
            help="robot, twin, method, iterations, target and parameters (each a number or "
            "uniform / loguniform / normal / choice).",
        ),
    ],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Directory: sweep.csv, report.md, figures/.")
    ],
    runs: Annotated[int, typer.Option(min=1, max=10_000_000, help="Number of campaigns.")] = 100,
    seed: Seed = 0,
    executor: ExecutorOption = "local",
    chunk: Chunk = 0,
    resume: Resume = False,
    overwrite: Overwrite = False,
) -> None:
    """Run N calibration campaigns on the twin, each with parameters drawn from the spec's
    distributions (run i from SeedSequence(S).spawn(N)[i]: the same table whatever the
    executor), and report the accuracy of the recovered factors against each varied one.

    Varied parameters: true_factors.scale.{longitudinal,lateral,rotational},
    true_factors.crosstalk.{forward,reverse,left,right}, ips.distance_noise_m,
    ips.nlos_probability, ips.latency_s, room_scale (× seed 000's room), iterations,
    slip_sigma, procedure.rotation.{distance_m,turns},
    procedure.{longitudinal,lateral}.{distance_m,repeats}. A sweep in which every run failed
    exits 3, its table and report written.
    """
    with handled_errors():
        from omnical.cli.output import say, tell
        from omnical.cli.progress import count_progress
        from omnical.fleet.executors import parse_executor
        from omnical.fleet.sweep import load_sweep_spec, run_sweep

        chosen = parse_executor(executor)
        parsed = load_sweep_spec(spec)
        with count_progress(f"sweep ({chosen})", "campaigns") as (start, advance):
            result = run_sweep(
                parsed,
                runs,
                seed,
                chosen,
                out,
                chunk=chunk,
                resume=resume,
                overwrite=overwrite,
                on_start=start,
                on_rows=advance,
                on_stop=kept,
                notify=tell,
            )
        failed = [row for row in result.rows if row["status"] != "ok"]
        resumed = f" ({result.done_before} done before the resume)" if result.done_before else ""
        say(
            f"wrote {result.table}: {len(result.rows)} campaigns, {len(result.rows) - len(failed)} "
            f"ok, {failures(failed)}{resumed}"
        )
        say(f"wrote {result.report}")
    if result.rows and len(failed) == len(result.rows):  # as a fleet: no result, exit 3
        reasons = Counter(f"{row['status']}: {row['reason']}" for row in failed)
        for reason, count in reasons.most_common(3):
            say(f"{count} run{'s' if count != 1 else ''}: {reason}")
        msg = f"omnical: no campaign gave a result (every run failed: see {result.report})"
        typer.echo(msg, err=True)
        raise typer.Exit(EXIT_NO_RESULT)
