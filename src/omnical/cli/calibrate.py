"""``omnical calibrate``: the campaign on the twin, or the offline analysis of recordings.

* ``omnical calibrate --robot PRESET|FILE [--twin default|ideal|FILE] --out DIR`` runs seed
  000's flowchart on the digital twin (:func:`omnical.calibration.campaign.run_campaign`) and
  writes ``DIR/factors.yaml``, ``DIR/omnical_factors.h``, ``DIR/wheeltec_params.yaml``,
  ``DIR/report.md``, ``DIR/figures/*.png`` and ``DIR/recordings/*.mcap``.
* ``omnical calibrate RUN.mcap [RUN2 ...] --out factors.yaml [--method procedures|joint]``
  estimates the factors from recordings (:func:`omnical.calibration.campaign.estimate_factors`)
  and writes ``factors.yaml`` with the header and the ROS parameters beside it.

:func:`register` adds the command to a typer app (``omnical.cli.main`` calls it); the bodies
are :func:`run_campaign_command` and :func:`run_offline_command`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import (
    BarColumn,
    Progress,
    ProgressColumn,
    SpinnerColumn,
    Task,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
)
from rich.table import Table as RichTable
from rich.text import Text

from omnical.calibration.analysis import FACTOR_NAMES
from omnical.calibration.campaign import (
    CampaignProgress,
    CampaignResult,
    EstimationMethod,
    ProgressFn,
    Tolerance,
    estimate_factors,
    run_campaign,
)
from omnical.calibration.export import write_c_header, write_wheeltec_params
from omnical.calibration.factors_io import read_factors, write_factors
from omnical.calibration.measures import MEASURE_SPECS
from omnical.cli.errors import user_errors
from omnical.errors import ConfigError
from omnical.ips.beacons import load_beacon_map
from omnical.kinematics.correction import CorrectionFactors
from omnical.recording.bag import read_bag
from omnical.robot.loader import load_robot
from omnical.twin.params import load_twin

__all__ = ["calibrate", "register", "run_campaign_command", "run_offline_command"]

console = Console(highlight=False)

_KEY = {
    name: ("scale." + name.removeprefix("scale_"))
    if name.startswith("scale")
    else "crosstalk." + name.removeprefix("crosstalk_").removesuffix("_rad_per_m")
    for name in FACTOR_NAMES
}
_METHODS: dict[str, EstimationMethod] = {"procedures": "procedures", "joint": "joint"}


def _method(name: str) -> EstimationMethod:
    if name not in _METHODS:
        msg = f"--method: unknown method {name!r}; choose procedures or joint"
        raise ConfigError(msg)
    return _METHODS[name]


class _RobotTimeColumn(ProgressColumn):
    """``done/total s robot time`` for a run, nothing for a step that is not a run."""

    def render(self, task: Task) -> Text:
        if task.total is None:
            return Text("")
        return Text(f"{task.completed:>5.0f}/{task.total:<5.0f} s robot time")


class _Display:
    """Turns campaign progress events into one rich progress line per step."""

    def __init__(self, progress: Progress) -> None:
        self._progress = progress
        self._task: TaskID | None = None
        self._step = ""
        self._total_s = 0.0

    def __call__(self, event: CampaignProgress) -> None:
        if event.step != self._step:
            self._finish()
            self._step = event.step
            self._total_s = event.total_s
            total = event.total_s if event.total_s > 0.0 else None
            self._task = self._progress.add_task(event.step, total=total)
        if self._task is not None and event.total_s > 0.0:
            self._progress.update(self._task, completed=event.done_s, total=event.total_s)

    def _finish(self) -> None:
        if self._task is None:
            return
        if self._total_s > 0.0:
            self._progress.console.print(
                f"[green]✓[/green] {self._step} ({self._total_s:.0f} s robot time)"
            )
        self._progress.remove_task(self._task)
        self._task = None

    def close(self) -> None:
        self._finish()


@contextmanager
def _campaign_progress() -> Iterator[ProgressFn]:
    with Progress(
        SpinnerColumn(),
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        _RobotTimeColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=True,
    ) as progress:
        display = _Display(progress)
        try:
            yield display
        finally:
            display.close()


def _factors_table(
    title: str,
    factors: CorrectionFactors,
    sigma: Mapping[str, float],
    truth: CorrectionFactors | None = None,
) -> RichTable:
    table = RichTable(title=title)
    table.add_column("factor")
    table.add_column("value", justify="right")
    table.add_column("± 1σ", justify="right")
    if truth is not None:
        table.add_column("truth (twin)", justify="right")
        table.add_column("error", justify="right")
    for name in FACTOR_NAMES:
        scale = name.startswith("scale")
        value = getattr(factors, name)
        s = sigma.get(name, math.nan)
        unit = "" if scale else " rad/m"
        row = [
            _KEY[name],
            f"{value:.5f}{unit}" if scale else f"{value:+.5f}{unit}",
            f"{s:.5f}" if math.isfinite(s) else "not estimated",
        ]
        if truth is not None:
            t = getattr(truth, name)
            row.append(f"{t:.5f}" if scale else f"{t:+.5f}")
            row.append(
                f"{100 * (value / t - 1):+.3f} %" if scale else f"{1e3 * (value - t):+.2f} mrad/m"
            )
        table.add_row(*row)
    return table


def _print_campaign(result: CampaignResult) -> None:
    console.print(
        _factors_table(
            f"{result.robot_name}: correction factors", result.factors, result.sigma, result.truth
        )
    )
    n = len(result.iterations)
    state = "converged" if result.converged else "[bold red]not converged[/bold red]"
    console.print(f"{n} iteration{'s' if n > 1 else ''}, {state}")
    before, after = result.measures_before, result.measures_after
    if before is not None and after is not None:
        table = RichTable(title="before → after calibration (seed 000 §3.2)")
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
        console.print(table)
    for role in ("factors", "header", "ros_params", "report"):
        if role in result.files:
            console.print(f"wrote {result.files[role]}")
    n_fig = sum(1 for k in result.files if k.startswith("figure:"))
    n_bag = sum(1 for k in result.files if k.startswith("recording:"))
    if result.out_dir is not None:
        console.print(
            f"wrote {n_fig} figures in {result.out_dir / 'figures'}, {n_bag} recordings in "
            f"{result.out_dir / 'recordings'}"
        )
    console.print(
        f"robot time {result.robot_time_s / 60.0:.1f} min, wall time {result.wall_time_s:.1f} s"
    )


def run_campaign_command(
    out: Path,
    robot: str,
    twin: str | None,
    seed: int,
    method: str,
    max_iterations: int,
    tolerance_scale_percent: float,
    tolerance_crosstalk_mrad_per_m: float,
    installed: Path | None,
    beacons: Path | None,
) -> CampaignResult:
    """``omnical calibrate --out DIR``: the campaign on the twin."""
    if out.suffix in {".yaml", ".yml"}:
        msg = f"--out {out}: the campaign writes a directory; give a directory name"
        raise ConfigError(msg)
    description = load_robot(robot)
    params = load_twin(twin if twin is not None else "default", description)
    tolerance = Tolerance(tolerance_scale_percent / 100.0, tolerance_crosstalk_mrad_per_m / 1e3)
    start = read_factors(installed).factors if installed is not None else None
    bmap = load_beacon_map(beacons) if beacons is not None else None
    with _campaign_progress() as on_progress:
        result = run_campaign(
            description,
            params,
            seed=seed,
            out_dir=out,
            tolerance=tolerance,
            max_iterations=max_iterations,
            on_progress=on_progress,
            method=_method(method),
            installed=start,
            beacons=bmap,
        )
    _print_campaign(result)
    return result


def run_offline_command(
    runs: list[Path],
    out: Path,
    robot: str,
    method: str,
    installed: Path | None,
    beacons: Path | None,
) -> None:
    """``omnical calibrate RUN.mcap ... --out factors.yaml``: the offline analysis."""
    if out.suffix not in {".yaml", ".yml"}:
        msg = f"--out {out}: the offline analysis writes a factors file; give a .yaml path"
        raise ConfigError(msg)
    chosen = _method(method)
    description = load_robot(robot)
    prior = read_factors(installed).factors if installed is not None else None
    bmap = load_beacon_map(beacons) if beacons is not None else None
    recordings = []
    with console.status("reading recordings"):
        for run in runs:
            recordings.append(read_bag(run))
    label = f"estimating the factors from {len(runs)} recording(s) ({chosen})"
    with console.status(label):
        estimate = estimate_factors(
            recordings,
            installed=prior,
            method=chosen,
            hedge_offset_m=description.hedge_offset_m,
            beacons=bmap,
        )
    unc = estimate.uncertainty()
    comment = f"omnical calibrate {' '.join(str(r) for r in runs)} --method {chosen}"
    written = [
        write_factors(out, estimate.factors, unc, comment=comment),
        write_c_header(out.with_name("omnical_factors.h"), estimate.factors, unc),
        write_wheeltec_params(out.with_name("wheeltec_params.yaml"), estimate.factors, unc),
    ]
    console.print(
        _factors_table(f"{description.name}: correction factors", estimate.factors, estimate.sigma)
    )
    if estimate.installed != CorrectionFactors():
        console.print(
            "installed during the recordings (the totals include them): "
            + ", ".join(f"{_KEY[k]} {v:.5g}" for k, v in estimate.installed.as_dict().items())
        )
    if chosen == "joint":
        x, y = estimate.hedge_offset_xy_m
        console.print(f"hedgehog offset in base_link: x {x:+.3f} m, y {y:+.3f} m")
    for note in estimate.notes:
        console.print(f"note: {note}")
    for path in written:
        console.print(f"wrote {path}")


def calibrate(
    runs: Annotated[
        list[Path] | None,
        typer.Argument(
            help="Recordings (bags) to analyse offline; leave out to run the campaign on the twin."
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="Campaign: output directory (default omnical-calibration). Offline: the "
            "factors.yaml to write (default factors.yaml; omnical_factors.h and "
            "wheeltec_params.yaml go beside it).",
        ),
    ] = None,
    robot: Annotated[
        str, typer.Option(help="Robot preset (rosy-mecanum, omni-x) or robot YAML.")
    ] = "rosy-mecanum",
    twin: Annotated[
        str | None,
        typer.Option(help="Campaign: twin YAML, or 'default' / 'ideal' (default: default)."),
    ] = None,
    seed: Annotated[int, typer.Option(help="Campaign: random seed (same seed, same run).")] = 0,
    method: Annotated[
        str, typer.Option(help="procedures (seed 000, default) or joint (one least squares).")
    ] = "procedures",
    max_iterations: Annotated[
        int, typer.Option(help="Campaign: most iterations of the flowchart.", min=1)
    ] = 4,
    tolerance_scale: Annotated[
        float, typer.Option(help="Campaign: stop when no scaling changes by more (%).")
    ] = 0.3,
    tolerance_crosstalk: Annotated[
        float, typer.Option(help="Campaign: ... and no cross-talk by more (mrad/m).")
    ] = 1.0,
    installed: Annotated[
        Path | None,
        typer.Option(
            help="factors.yaml installed in the vehicle controller (campaign: at the start; "
            "offline: during the recordings, default: from the recordings, else identity)."
        ),
    ] = None,
    beacons: Annotated[
        Path | None, typer.Option(help="Beacon map YAML (default: seed 000 Table 3 / the bags').")
    ] = None,
) -> None:
    """Calibrate the seven correction factors: the campaign on the twin, or from recordings."""
    with user_errors():
        if runs:
            if twin is not None:
                msg = "--twin applies to the campaign only, not to the analysis of recordings"
                raise ConfigError(msg)
            target = out if out is not None else Path("factors.yaml")
            run_offline_command(list(runs), target, robot, method, installed, beacons)
        else:
            run_campaign_command(
                out if out is not None else Path("omnical-calibration"),
                robot,
                twin,
                seed,
                method,
                max_iterations,
                tolerance_scale,
                tolerance_crosstalk,
                installed,
                beacons,
            )


def register(app: typer.Typer) -> None:
    """Add the ``calibrate`` command to a typer app (``omnical.cli.main`` calls this)."""
    app.command(name="calibrate")(calibrate)
