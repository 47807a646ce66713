"""``omnical calibrate estimate``: the seven factors from recordings.

Writes ``factors.yaml`` with the C header and the ROS parameters beside it. The library calls
are in :func:`_estimate_and_write`.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.choices import EstimationMethod, parse_choice
from omnical.cli.calibrate_options import BeaconMapOption, Installed, Method
from omnical.cli.errors import handled_errors
from omnical.cli.options import Overwrite, Robot
from omnical.cli.output import console

if TYPE_CHECKING:
    from omnical.calibration.campaign import FactorEstimate
    from omnical.ips.beacons import BeaconMap
    from omnical.kinematics.correction import CorrectionFactors
    from omnical.recording.recording import Recording

__all__ = ["estimate"]


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
    method: Method = EstimationMethod.PROCEDURES.value,
    installed: Installed = None,
    beacons: BeaconMapOption = None,
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
