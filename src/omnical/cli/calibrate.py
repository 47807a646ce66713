"""``omnical calibrate``: the seven correction factors (seed 000 Table 2), two ways.

* ``omnical calibrate campaign --robot ROBOT --twin TWIN --out DIR`` runs seed 000's
  procedures (Figure 7) on a robot — today its digital twin — and writes ``DIR/factors.yaml``,
  ``DIR/omnical_factors.h``, ``DIR/wheeltec_params.yaml``, ``DIR/report.md``,
  ``DIR/figures/*.png`` and ``DIR/recordings/*.mcap``.
* ``omnical calibrate estimate BAG... --robot ROBOT --out factors.yaml`` estimates the factors
  from recordings and writes ``factors.yaml`` with the C header and the ROS parameters beside it.

The library calls are :func:`_run_campaign_and_write` and :func:`_estimate_and_write`; the
tables are printed by :mod:`omnical.cli.calibrate_output`.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.choices import EstimationMethod, parse_choice
from omnical.cli.errors import handled_errors
from omnical.cli.options import Overwrite, Robot, Seed, choice_metavar
from omnical.cli.output import console

if TYPE_CHECKING:
    from omnical.calibration.campaign import CampaignResult, FactorEstimate, Tolerance
    from omnical.ips.beacons import BeaconMap
    from omnical.kinematics.correction import CorrectionFactors
    from omnical.recording.recording import Recording
    from omnical.robot.description import RobotDescription
    from omnical.twin.params import TwinParams

__all__ = ["app", "campaign", "estimate"]

app = typer.Typer(
    name="calibrate",
    help="Calibrate the seven correction factors: run the procedures on a robot (campaign) "
    "or estimate them from recordings (estimate).",
    no_args_is_help=True,
    rich_markup_mode="markdown",
    pretty_exceptions_enable=False,
    add_completion=False,
)

_Method = Annotated[
    str,
    typer.Option(
        metavar=choice_metavar(EstimationMethod),
        help="procedures (seed 000, one factor group per manoeuvre) or joint (one least "
        "squares over all seven factors and the hedgehog offset).",
    ),
]
_Installed = Annotated[
    Path | None,
    typer.Option(
        help="factors.yaml installed in the vehicle controller during the runs "
        "(campaign: at its start; estimate: default from the recordings' events, else identity)."
    ),
]
_BeaconMap = Annotated[
    Path | None,
    typer.Option(help="Beacon map YAML (default: each recording's /beacons_pos_a)."),
]


@app.command()
def campaign(
    robot: Robot = "rosy-mecanum",
    twin: Annotated[
        str, typer.Option(help="The robot's digital twin: twin YAML, or 'default' / 'ideal'.")
    ] = "default",
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Output directory (factors, report, figures, bags).")
    ] = Path("omnical-calibration"),
    seed: Seed = 0,
    method: _Method = EstimationMethod.PROCEDURES.value,
    max_iterations: Annotated[
        int, typer.Option(help="Most iterations of the flowchart.", min=1)
    ] = 4,
    tolerance_scale: Annotated[
        float, typer.Option(help="Stop when no scaling changes by more (%).")
    ] = 0.3,
    tolerance_crosstalk: Annotated[
        float, typer.Option(help="... and no cross-talk by more (mrad/m).")
    ] = 1.0,
    installed: _Installed = None,
    beacons: _BeaconMap = None,
    overwrite: Overwrite = False,
) -> None:
    """Run seed 000's calibration procedures on a robot (today: its digital twin).

    Iterates until the factors settle, validates, measures before and after, prints the factors
    and the measures, and writes factors.yaml, omnical_factors.h, wheeltec_params.yaml,
    report.md, figures/ and recordings/ in OUT.
    """
    with handled_errors():
        chosen = parse_choice(EstimationMethod, method, "--method")
        _campaign(
            out,
            robot,
            twin,
            seed,
            chosen,
            max_iterations,
            (tolerance_scale, tolerance_crosstalk),
            installed,
            beacons,
            overwrite,
        )


@app.command()
def estimate(
    bags: Annotated[
        list[Path], typer.Argument(metavar="BAG...", help="Recordings (bags) to estimate from.")
    ],
    robot: Robot = "rosy-mecanum",
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            help="factors.yaml to write; NAME.h (firmware header) and NAME.wheeltec.yaml "
            "(Wheeltec ROS parameters) go beside it.",
        ),
    ] = Path("factors.yaml"),
    method: _Method = EstimationMethod.PROCEDURES.value,
    installed: _Installed = None,
    beacons: _BeaconMap = None,
    overwrite: Overwrite = False,
) -> None:
    """Estimate the factors from recordings that ran with the same installed factors.

    Prints the factors with their uncertainty and writes OUT (factors.yaml), and beside it the
    firmware header and the Wheeltec ROS parameters named from it (factors.h,
    factors.wheeltec.yaml).
    """
    with handled_errors():
        chosen = parse_choice(EstimationMethod, method, "--method")
        _estimate(bags, out, robot, chosen, installed, beacons, overwrite)


def _campaign(
    out: Path,
    robot: str,
    twin: str,
    seed: int,
    method: EstimationMethod,
    max_iterations: int,
    tolerance_percent_mrad: tuple[float, float],
    installed: Path | None,
    beacons: Path | None,
    overwrite: bool,
) -> None:
    from omnical.calibration.campaign import Tolerance
    from omnical.calibration.factors_io import read_factors
    from omnical.cli.calibrate_output import print_campaign
    from omnical.errors import ConfigError
    from omnical.ips.beacons import load_beacon_map
    from omnical.reports.outputs import claim_directory
    from omnical.robot.loader import load_robot
    from omnical.twin.params import load_twin

    if out.suffix in {".yaml", ".yml"}:
        msg = f"--out {out}: the campaign writes a directory; give a directory name"
        raise ConfigError(msg)
    description = load_robot(robot)
    params = load_twin(twin, description)
    start = read_factors(installed).factors if installed is not None else None
    bmap = load_beacon_map(beacons) if beacons is not None else None
    scale_percent, crosstalk_mrad_per_m = tolerance_percent_mrad
    tolerance = Tolerance(scale_percent / 100.0, crosstalk_mrad_per_m / 1e3)
    claim_directory(out, overwrite=overwrite, writer="omnical calibrate campaign")
    result, written = _run_campaign_and_write(
        description,
        params,
        out,
        seed=seed,
        method=method,
        max_iterations=max_iterations,
        tolerance=tolerance,
        installed=start,
        beacons=bmap,
    )
    print_campaign(result, written)


def _run_campaign_and_write(
    robot: RobotDescription,
    twin: TwinParams,
    out: Path,
    *,
    seed: int,
    method: EstimationMethod,
    max_iterations: int,
    tolerance: Tolerance,
    installed: CorrectionFactors | None,
    beacons: BeaconMap | None,
) -> tuple[CampaignResult, list[str]]:
    """The calls of ``omnical calibrate campaign`` into the library: run, write OUT.

    Returns the result and one ``wrote ...`` line per file or group of files written.
    """
    from omnical.calibration.campaign import CampaignProgress
    from omnical.cli.progress import campaign_progress
    from omnical.reports.campaign import write_campaign
    from omnical.twin.bench import run_twin_campaign

    with campaign_progress() as on_progress:
        result = run_twin_campaign(
            robot,
            twin.with_installed(installed) if installed is not None else twin,
            seed=seed,
            tolerance=tolerance,
            max_iterations=max_iterations,
            on_progress=on_progress,
            method=method.value,
            beacons=beacons,
        )
        files = write_campaign(
            result,
            out,
            robot,
            beacons=beacons,
            on_progress=lambda line: on_progress(CampaignProgress(line)),
            overwrite=True,  # claimed before the run; --overwrite was checked then
        )
    written = [
        f"wrote {files.files[role]}" for role in ("factors", "header", "ros_params", "report")
    ]
    n_figures, n_bags = len(files.by_kind("figure")), len(files.by_kind("recording"))
    written.append(
        f"wrote {n_figures} figures in {out / 'figures'}, {n_bags} recordings in {out / 'recordings'}"
    )
    return result, written


def _estimate(
    bags: list[Path],
    out: Path,
    robot: str,
    method: EstimationMethod,
    installed: Path | None,
    beacons: Path | None,
    overwrite: bool,
) -> None:
    from omnical.calibration.factors_io import read_factors
    from omnical.cli.calibrate_output import print_estimate
    from omnical.errors import ConfigError
    from omnical.ips.beacons import load_beacon_map
    from omnical.recording.bag import read_bag
    from omnical.reports.outputs import claim_files, side_file
    from omnical.robot.loader import load_robot

    if out.suffix not in {".yaml", ".yml"}:
        msg = f"--out {out}: the estimate is a factors file; give a .yaml path"
        raise ConfigError(msg)
    claim_files([out, side_file(out, ".h"), side_file(out, ".wheeltec.yaml")], overwrite=overwrite)
    description = load_robot(robot)
    prior = read_factors(installed).factors if installed is not None else None
    bmap = load_beacon_map(beacons) if beacons is not None else None
    with console().status("reading recordings"):
        recordings = [read_bag(bag) for bag in bags]
    comment = f"omnical calibrate estimate {' '.join(map(str, bags))} --method {method}"
    label = f"estimating the factors from {len(bags)} recording(s) ({method})"
    with console().status(label):
        result, written = _estimate_and_write(
            recordings,
            out,
            method=method,
            installed=prior,
            hedge_offset_m=description.hedge_offset_m,
            beacons=bmap,
            comment=comment,
        )
    print_estimate(description.name, result, method, written)


def _estimate_and_write(
    recordings: list[Recording],
    out: Path,
    *,
    method: EstimationMethod,
    installed: CorrectionFactors | None,
    hedge_offset_m: tuple[float, ...],
    beacons: BeaconMap | None,
    comment: str,
) -> tuple[FactorEstimate, list[Path]]:
    """The calls of ``omnical calibrate estimate`` into the library; writes the three files."""
    from omnical.calibration.campaign import estimate_factors
    from omnical.calibration.export import write_c_header, write_wheeltec_params
    from omnical.calibration.factors_io import write_factors
    from omnical.reports.outputs import side_file

    result = estimate_factors(
        recordings,
        installed=installed,
        method=method.value,
        hedge_offset_m=hedge_offset_m,
        beacons=beacons,
    )
    unc = result.uncertainty()
    written = [
        write_factors(out, result.factors, unc, comment=comment, held=result.held),
        write_c_header(side_file(out, ".h"), result.factors, unc, held=result.held),
        write_wheeltec_params(
            side_file(out, ".wheeltec.yaml"), result.factors, unc, held=result.held
        ),
    ]
    return result, written
