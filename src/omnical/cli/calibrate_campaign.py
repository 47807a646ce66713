"""``omnical calibrate campaign``: seed 000's procedures (Figure 7) run on a robot.

Writes ``DIR/factors.yaml``, ``DIR/omnical_factors.h``, ``DIR/wheeltec_params.yaml``,
``DIR/report.md``, ``DIR/figures/*.png`` and ``DIR/recordings/*.mcap``. The library calls are
in :func:`_run_campaign_and_write`.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.choices import EstimationMethod, parse_choice
from omnical.cli.calibrate_options import BeaconMapOption, Installed, Method
from omnical.cli.errors import handled_errors
from omnical.cli.options import Overwrite, Robot, Seed

if TYPE_CHECKING:
    from omnical.calibration.campaign import CampaignResult, Tolerance
    from omnical.ips.beacons import BeaconMap
    from omnical.kinematics.correction import CorrectionFactors
    from omnical.robot.description import RobotDescription
    from omnical.twin.params import TwinParams

__all__ = ["campaign"]


def campaign(
    robot: Robot = "rosy-mecanum",
    twin: Annotated[
        str, typer.Option(help="The robot's digital twin: twin YAML, or 'default' / 'ideal'.")
    ] = "default",
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Output directory (factors, report, figures, bags).")
    ] = Path("omnical-calibration"),
    seed: Seed = 0,
    method: Method = EstimationMethod.PROCEDURES.value,
    max_iterations: Annotated[
        int, typer.Option(help="Most iterations of the flowchart.", min=1)
    ] = 4,
    tolerance_scale: Annotated[
        float, typer.Option(help="Stop when no scaling changes by more (%).")
    ] = 0.3,
    tolerance_crosstalk: Annotated[
        float, typer.Option(help="... and no cross-talk by more (mrad/m).")
    ] = 1.0,
    installed: Installed = None,
    beacons: BeaconMapOption = None,
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
