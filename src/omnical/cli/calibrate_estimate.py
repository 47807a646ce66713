"""``omnical calibrate estimate``: the seven factors from recordings, with header and parameters.

Reference: the IPS unless ``--reference-topic`` / ``--reference-file``; odometry ``/odom`` unless
``--wheel-topic`` / ``--odometry seed003``, which are uncompensated (the factors are the totals).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.choices import EstimationMethod, parse_choice
from omnical.cli.errors import handled_errors
from omnical.cli.options import (
    BeaconMapOption,
    EstimateMethod,
    Installed,
    Overwrite,
    Robot,
)
from omnical.cli.output import console
from omnical.cli.reference_options import (
    DeadWheelTopic,
    Odometry,
    ReferenceChild,
    ReferenceFile,
    ReferenceSigma,
    ReferenceTopic,
    WheelTopic,
)

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
    method: EstimateMethod = None,
    installed: Installed = None,
    beacons: BeaconMapOption = None,
    reference_topic: ReferenceTopic = None,
    reference_child: ReferenceChild = None,
    reference_file: ReferenceFile = None,
    reference_sigma: ReferenceSigma = 0.002,
    wheel_topic: WheelTopic = None,
    odometry: Odometry = None,
    # recording.topics.DEAD_WHEELS written out: the CLI imports no library at start-up
    dead_wheel_topic: DeadWheelTopic = "/dead_wheels",
    overwrite: Overwrite = False,
) -> None:
    """Estimate the factors from recordings that ran with the same installed factors.

    Prints the factors with their uncertainty and writes OUT (factors.yaml), and beside it the
    firmware header and the Wheeltec ROS parameters named from it (factors.h,
    factors.wheeltec.yaml). The reference is the IPS unless --reference-topic (motion capture
    in the bag) or --reference-file gives another; the odometry is /odom unless --wheel-topic
    or --odometry seed003 computes it.
    """
    with handled_errors():
        from omnical.cli.calibrate_output import print_estimate
        from omnical.cli.output import tell, voice
        from omnical.cli.robot_target import load_said_robot
        from omnical.errors import ConfigError
        from omnical.reports.estimate import read_for_estimate
        from omnical.reports.outputs import side_file, stage_files
        from omnical.services.sources import Sources

        chosen = None if method is None else parse_choice(EstimationMethod, method, "--method")
        sources = Sources.of(
            odometry, wheel_topic, dead_wheel_topic, reference_topic, reference_child,
            reference_file, reference_sigma_m=reference_sigma,
        )  # fmt: skip
        if out.suffix not in {".yaml", ".yml"}:
            msg = f"--out {out}: the estimate is a factors file; give a .yaml path"
            raise ConfigError(msg)
        final = [out, side_file(out, ".h"), side_file(out, ".wheeltec.yaml")]
        outputs = stage_files(final, overwrite=overwrite, notify=tell)
        description = load_said_robot(robot)
        inputs = read_for_estimate(
            bags,
            robot=description,
            sources=sources,
            method=chosen,
            installed=installed,
            beacons=beacons,
            voice=voice(),
        )
        label = f"estimating the factors from {len(bags)} recording(s) ({inputs.method})"
        # the files put in place together
        with console().status(label), outputs.staged(tell) as staged:
            result = inputs.estimate_and_write(staged[0], "omnical calibrate estimate")
        print_estimate(description.name, result, inputs.method, final)
