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
from omnical.cli.options import (
    Align,
    EstimateMethod,
    HedgeZ,
    LocateMethodOption,
    NoSelfCalibration,
    Overwrite,
    Robot,
    SigmaM,
)
from omnical.cli.reference_options import (
    DeadWheelTopic,
    FactorsFile,
    Odometry,
    Reference,
    ReferenceChild,
    ReferenceFile,
    ReferenceSigma,
    ReferenceTopic,
    WheelTopic,
)

if TYPE_CHECKING:
    from omnical.fleet.jobs import FleetOptions

__all__ = ["Chunk", "ExecutorOption", "Resume", "app", "failures", "kept"]

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
        "worker, at most 4 campaigns each; serial: one at a time).",
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
    Path | None,
    typer.Option(help="Beacon map YAML (default: each recording's); may hold {stem}, {parent}."),
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
    from omnical.cli.output import say, tell
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
            on_stop=kept,
            notify=tell,
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
    method: LocateMethodOption = LocateMethod.ROBUST.value,
    beacons: BeaconsOption = None,
    hedge_z: HedgeZ = None,
    sigma_m: SigmaM = None,
    no_self_calibration: NoSelfCalibration = False,
    plot: Annotated[
        bool,
        typer.Option(
            "--plot", help="Also recordings/NAME/fixes.png: the fixes over the beacon map."
        ),
    ] = False,
    allow_poor: Annotated[
        bool,
        typer.Option("--allow-poor", help="A row even when fewer than half the fixes are usable."),
    ] = False,
    executor: ExecutorOption = "local",
    chunk: Chunk = 0,
    resume: Resume = False,
    overwrite: Overwrite = False,
) -> None:
    """Multilaterate every recording (as omnical locate): recordings/NAME/fixes.csv, one row
    each with the fix counts by status, the median residual and the median fix 1σ.

    Fixes locate finds not plausible (--hedge-z or --sigma-m the ranges contradict, where it
    exits 3) are written too, and the recording's row is an error with locate's reason; so
    are fixes of which fewer than half are usable, unless --allow-poor. In
    --beacons, {stem} is the bag's file (or folder) name without .mcap / .bag and {parent}
    its directory: --beacons '{parent}/beacons.yaml' is each recording's own.
    """
    with handled_errors():
        from omnical.choices import parse_choice
        from omnical.fleet.jobs import FleetOptions

        chosen = parse_choice(LocateMethod, method, "--method")
        options = FleetOptions(
            "locate",
            method=chosen.value,
            beacons=_user_file(beacons, "--beacons"),
            hedge_z_m=hedge_z,
            sigma_m=sigma_m,
            self_calibrate=not no_self_calibration,
            plot=plot,
            allow_poor=allow_poor,
        )
        _run(bags, options, executor, out, chunk, resume, overwrite)


@app.command()
def evaluate(
    bags: Bags,
    out: OutDir,
    reference: Reference = "ground_truth",
    reference_topic: ReferenceTopic = None,
    reference_child: ReferenceChild = None,
    reference_file: ReferenceFile = None,
    wheel_topic: WheelTopic = None,
    odometry: Odometry = None,
    dead_wheel_topic: DeadWheelTopic = "/dead_wheels",
    align: Align = AlignMode.SE2.value,
    robot: Robot = "rosy-mecanum",
    factors: FactorsFile = None,
    executor: ExecutorOption = "local",
    chunk: Chunk = 0,
    resume: Resume = False,
    overwrite: Overwrite = False,
) -> None:
    """Evaluate every recording (as omnical evaluate, with its options): recordings/NAME/
    (metrics.json, report.md, figures), one row each with the RMSE, max and final error of
    every estimate and the smoothed track's own 1σ.

    The reference is each recording's /ground_truth unless --reference, --reference-topic or
    --reference-file names another; the one used and the rule its times were read by are each
    row's reference and reference_times, and in report.md. In a file's path (--reference,
    --reference-file, --factors) {stem} is the bag's file (or folder) name without .mcap /
    .bag (not the table's NAME, which may have directories before it) and {parent} its
    directory: --reference-file '{parent}/{stem}.tum' is each recording's own.
    """
    with handled_errors():
        from omnical.choices import parse_choice
        from omnical.evaluation.reference_input import BUILTIN_REFERENCES
        from omnical.fleet.jobs import FleetOptions

        chosen = parse_choice(AlignMode, align, "--align")
        if reference not in ("ground_truth", *BUILTIN_REFERENCES):
            reference = _user_file(Path(reference), "--reference")
        options = FleetOptions(
            "evaluate",
            robot=robot,
            align=chosen.value,
            reference=reference,
            factors=_user_file(factors, "--factors"),
        )
        options = _with_sources(
            options, reference_topic, reference_child, reference_file, odometry, wheel_topic,
            dead_wheel_topic,
        )  # fmt: skip
        _run(bags, _with_robot(options), executor, out, chunk, resume, overwrite)


@app.command()
def calibrate(
    bags: Bags,
    out: OutDir,
    robot: Robot = "rosy-mecanum",
    method: EstimateMethod = None,
    installed: Annotated[
        Path | None,
        typer.Option(
            help="factors.yaml the recordings ran with (default: what they say); may hold "
            "{stem}, {parent}."
        ),
    ] = None,
    beacons: BeaconsOption = None,
    reference_topic: ReferenceTopic = None,
    reference_child: ReferenceChild = None,
    reference_file: ReferenceFile = None,
    reference_sigma: ReferenceSigma = 0.002,
    wheel_topic: WheelTopic = None,
    odometry: Odometry = None,
    dead_wheel_topic: DeadWheelTopic = "/dead_wheels",
    previous: Previous = None,
    executor: ExecutorOption = "local",
    chunk: Chunk = 0,
    resume: Resume = False,
    overwrite: Overwrite = False,
) -> None:
    """Estimate the factors of every recording alone (as omnical calibrate estimate, with its
    options): recordings/NAME/factors.yaml (+ .h, .wheeltec.yaml), one row each with the seven
    factors and their 1σ; report.md flags factors more than 3σ from the fleet or from --previous.

    The reference is the IPS unless --reference-topic or --reference-file names another (each
    row's reference and reference_times say which, and the rule its times were read by). In a
    file's path (--reference-file, --installed, --beacons) {stem} is the bag's file (or folder)
    name without .mcap / .bag (not the table's NAME, which may have directories before it) and
    {parent} its directory: --installed '{parent}/installed.yaml' is each recording's own.
    """
    with handled_errors():
        from omnical.choices import OdometrySource, parse_choice
        from omnical.fleet.jobs import FleetOptions
        from omnical.services.sources import check_installed

        chosen = "" if method is None else parse_choice(EstimationMethod, method, "--method").value
        options = FleetOptions(
            "calibrate",
            robot=robot,
            method=chosen,
            beacons=_user_file(beacons, "--beacons"),
            installed=_user_file(installed, "--installed"),
            reference_sigma_m=reference_sigma,
        )
        options = _with_sources(
            options, reference_topic, reference_child, reference_file, odometry, wheel_topic,
            dead_wheel_topic,
        )  # fmt: skip
        check_installed(installed, OdometrySource(options.odometry))
        _run(bags, _with_robot(options), executor, out, chunk, resume, overwrite, previous)


def kept(table: Path, rows: int, continues: str = "--resume continues") -> None:
    """On a stop: the rows kept, where, and how to go on (before "omnical: interrupted")."""
    from omnical.cli.output import tell

    tell(f"{rows} row{'s' if rows != 1 else ''} kept in {table}; {continues}")


def failures(failed: list[dict[str, str]]) -> str:
    """``N error``, and ``, M lost (the executor's: --resume runs them again)`` if any."""
    from omnical.fleet.table import LOST

    lost = sum(row["status"] == LOST for row in failed)
    text = f"{len(failed) - lost} error"
    return f"{text}, {lost} lost (the executor's: --resume runs them again)" if lost else text


def _with_robot(options: FleetOptions) -> FleetOptions:
    """``options`` with the robot a preset as it is, a robot file as an absolute path (workers
    may run elsewhere); loaded here once, and the options that depend on it checked, so a bad
    one is one error, not a row per recording.

    Raises:
        ConfigError: no such robot, or an option it cannot take (``--odometry seed003``
            without dead wheels).
    """
    from dataclasses import replace

    from omnical.cli.robot_target import load_said_robot
    from omnical.fleet.jobs import check_robot_options

    check_robot_options(options, load_said_robot(options.robot))
    path = Path(options.robot)
    if path.suffix in {".yaml", ".yml"}:
        return replace(options, robot=str(path.resolve()))
    return options


def _user_file(path: Path | None, option: str) -> str:
    """A file option as an absolute path ("" when not given), checked here unless it holds
    ``{stem}`` / ``{parent}`` (each recording's own, read by its job).

    Raises:
        ConfigError: no such file.
    """
    from omnical.errors import ConfigError

    if path is None:
        return ""
    if str(path).startswith("{parent}"):  # the recording's directory: absolute already
        return str(path)
    if not any(key in str(path) for key in ("{stem}", "{parent}")) and not path.is_file():
        raise ConfigError(f"{option} {path}: no such file")
    return str(path.resolve())


def _with_sources(
    options: FleetOptions,
    topic: str | None,
    child: str | None,
    file: Path | None,
    odometry: str | None,
    wheel_topic: str | None,
    dead_wheel_topic: str,
) -> FleetOptions:
    """``options`` with the reference and odometry options, checked as the single commands
    check them (:meth:`omnical.services.sources.Sources.of`).

    Raises:
        ChoiceError, ConfigError: two references, an unknown odometry, or one that does not go
            with ``--wheel-topic``; a reference file that is not there.
    """
    from dataclasses import replace

    from omnical.services.sources import Sources

    given = [options.reference] if options.reference != "ground_truth" else []
    source = Sources.of(odometry, wheel_topic, dead_wheel_topic, topic, child, file, *given)
    return replace(
        options,
        reference_topic=topic or "",
        reference_child=child or "",
        reference_file=_user_file(file, "--reference-file"),
        odometry=source.odometry.value,
        wheel_topic=wheel_topic or "",
        dead_wheel_topic=dead_wheel_topic,
    )
