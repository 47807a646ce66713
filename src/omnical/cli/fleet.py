"""``omnical fleet locate|evaluate|calibrate BAG...``: one single command over many recordings,
on local processes or a Dask cluster (``--executor``); ``DIR/fleet.csv``, ``DIR/report.md``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, TypeAlias

import typer

from omnical.choices import AlignMode, EstimationMethod, LocateMethod
from omnical.cli.errors import EXIT_NO_RESULT, handled_errors
from omnical.cli.help_layout import App
from omnical.cli.options import Overwrite, Robot, choice_metavar

if TYPE_CHECKING:
    from omnical.fleet.jobs import FleetOptions

__all__ = ["Chunk", "ExecutorOption", "Resume", "app", "failures"]

app = App(
    name="fleet",
    help="Run locate, evaluate or calibrate estimate on many recordings at once, one row each "
    "in DIR/fleet.csv, on local processes or a Dask cluster.",
    no_args_is_help=True,
    rich_markup_mode="markdown",
    pretty_exceptions_enable=False,
    add_completion=False,
)

Bags: TypeAlias = Annotated[
    list[Path], typer.Argument(metavar="BAG...", help="Recordings (bags), one row each.")
]
OutDir: TypeAlias = Annotated[
    Path,
    typer.Option(
        "--out", "-o", help="Directory: fleet.csv, report.md, figures/, recordings/NAME/."
    ),
]
ExecutorOption: TypeAlias = Annotated[
    str,
    typer.Option(
        "--executor",
        help="serial, local (a process per core), local:N, dask-local:N (a Dask cluster on this "
        "machine) or dask://HOST:PORT (a running Dask scheduler; needs omnical[cluster]).",
    ),
]
Chunk: TypeAlias = Annotated[
    int,
    typer.Option(
        min=0,
        help="Jobs per task sent to a worker (0: one recording; campaigns: about 8 tasks per "
        "worker, at most 4 campaigns each).",
    ),
]
Resume: TypeAlias = Annotated[
    bool,
    typer.Option(
        "--resume", help="Continue a run killed in DIR: the rows there are kept, not redone."
    ),
]
Previous: TypeAlias = Annotated[
    Path | None,
    typer.Option(
        help="An earlier fleet calibrate DIR (or its fleet.csv): factors more than 3σ from it "
        "are maintenance alerts."
    ),
]
BeaconsOption: TypeAlias = Annotated[
    Path | None, typer.Option(help="Beacon map YAML (default: each recording's).")
]


def _run(
    bags: list[Path],
    options: FleetOptions,
    executor: str,
    out: Path,
    chunk: int,
    resume: bool,
    overwrite: bool,
    previous: Path | None = None,
) -> None:
    from omnical.cli.output import say
    from omnical.cli.progress import count_progress
    from omnical.fleet.executors import parse_executor
    from omnical.fleet.recordings import run_fleet

    spec = parse_executor(executor)
    with count_progress(f"fleet {options.command} ({spec})", "recordings") as (start, advance):
        result = run_fleet(
            bags,
            options,
            spec,
            out,
            chunk=chunk,
            resume=resume,
            overwrite=overwrite,
            previous=previous,
            on_start=start,
            on_rows=advance,
        )
    failed = [row for row in result.rows if row["status"] != "ok"]
    for row in failed:
        say(f"{row['name']}: {row['status']}: {row['reason']}")
    resumed = f" ({result.done_before} done before the resume)" if result.done_before else ""
    say(
        f"wrote {result.table}: {len(result.rows)} recordings, {len(result.rows) - len(failed)} "
        f"ok, {failures(failed)}{resumed}"
    )
    if options.command == "calibrate":
        say(f"maintenance alerts: {result.alerts}")
    say(f"wrote {result.report}")
    if result.rows and len(failed) == len(result.rows):
        typer.echo("omnical: no recording gave a result (every row failed: see above)", err=True)
        raise typer.Exit(EXIT_NO_RESULT)


@app.command()
def locate(
    bags: Bags,
    out: OutDir,
    method: Annotated[
        str, typer.Option(metavar=choice_metavar(LocateMethod), help="robust, lsq or grid.")
    ] = LocateMethod.ROBUST.value,
    beacons: BeaconsOption = None,
    hedge_z: Annotated[float | None, typer.Option(help="Hedgehog height, m.")] = None,
    sigma_m: Annotated[float | None, typer.Option(help="Fix the range noise σ, m.")] = None,
    no_self_calibration: Annotated[
        bool, typer.Option("--no-self-calibration", help="Use the ranges as they are.")
    ] = False,
    executor: ExecutorOption = "local",
    chunk: Chunk = 0,
    resume: Resume = False,
    overwrite: Overwrite = False,
) -> None:
    """Multilaterate every recording (as omnical locate): recordings/NAME/fixes.csv, one row
    each with the fix counts by status, the median residual and the median fix 1σ."""
    with handled_errors():
        from omnical.choices import parse_choice
        from omnical.fleet.jobs import FleetOptions

        chosen = parse_choice(LocateMethod, method, "--method")
        options = FleetOptions(
            "locate",
            method=chosen.value,
            beacons=str(beacons.absolute()) if beacons else "",
            hedge_z_m=hedge_z,
            sigma_m=sigma_m,
            self_calibrate=not no_self_calibration,
        )
        _run(bags, options, executor, out, chunk, resume, overwrite)


@app.command()
def evaluate(
    bags: Bags,
    out: OutDir,
    align: Annotated[
        str, typer.Option(metavar=choice_metavar(AlignMode), help="none, origin or se2.")
    ] = AlignMode.SE2.value,
    robot: Robot = "rosy-mecanum",
    executor: ExecutorOption = "local",
    chunk: Chunk = 0,
    resume: Resume = False,
    overwrite: Overwrite = False,
) -> None:
    """Evaluate every recording against its /ground_truth (as omnical evaluate):
    recordings/NAME/ (metrics.json, report.md, figures), one row each with the RMSE, max and
    final error of every estimate and the smoothed track's own 1σ."""
    with handled_errors():
        from omnical.choices import parse_choice
        from omnical.fleet.jobs import FleetOptions

        chosen = parse_choice(AlignMode, align, "--align")
        options = FleetOptions("evaluate", robot=_robot_arg(robot), align=chosen.value)
        _run(bags, options, executor, out, chunk, resume, overwrite)


@app.command()
def calibrate(
    bags: Bags,
    out: OutDir,
    robot: Robot = "rosy-mecanum",
    method: Annotated[
        str | None,
        typer.Option(
            metavar=choice_metavar(EstimationMethod),
            help="procedures or joint; default procedures for a recording with /cmd_vel, "
            "else joint.",
        ),
    ] = None,
    installed: Annotated[
        Path | None,
        typer.Option(help="factors.yaml the recordings ran with (default: what they say)."),
    ] = None,
    beacons: BeaconsOption = None,
    previous: Previous = None,
    executor: ExecutorOption = "local",
    chunk: Chunk = 0,
    resume: Resume = False,
    overwrite: Overwrite = False,
) -> None:
    """Estimate the factors of every recording alone (as omnical calibrate estimate):
    recordings/NAME/factors.yaml (+ .h, .wheeltec.yaml), one row each with the seven factors
    and their 1σ; report.md flags factors more than 3σ from the fleet or from --previous."""
    with handled_errors():
        from omnical.choices import parse_choice
        from omnical.fleet.jobs import FleetOptions

        chosen = "" if method is None else parse_choice(EstimationMethod, method, "--method").value
        options = FleetOptions(
            "calibrate",
            robot=_robot_arg(robot),
            method=chosen,
            beacons=str(beacons.absolute()) if beacons else "",
            installed=str(installed.absolute()) if installed else "",
        )
        _run(bags, options, executor, out, chunk, resume, overwrite, previous)


def failures(failed: list[dict[str, str]]) -> str:
    """``N error``, and ``, M lost (the executor's: --resume runs them again)`` if any."""
    from omnical.fleet.table import LOST

    lost = sum(row["status"] == LOST for row in failed)
    text = f"{len(failed) - lost} error"
    return f"{text}, {lost} lost (the executor's: --resume runs them again)" if lost else text


def _robot_arg(robot: str) -> str:
    """A robot preset as it is, a robot file as an absolute path (workers may run elsewhere);
    loaded here once so a bad one is one error, not a row per recording."""
    from omnical.cli.robot_target import load_said_robot

    load_said_robot(robot)
    path = Path(robot)
    return str(path.absolute()) if path.suffix in {".yaml", ".yml"} else robot
