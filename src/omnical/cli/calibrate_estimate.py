"""``omnical calibrate estimate``: the seven factors from recordings, with header and parameters.

Reference: the IPS unless ``--reference-topic`` / ``--reference-file``; odometry ``/odom`` unless
``--wheel-topic`` / ``--odometry seed003``, which are uncompensated (the factors are the totals).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

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
    Sources,
    WheelTopic,
)

if TYPE_CHECKING:
    from omnical.calibration.campaign import ExternalReference
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
        from omnical.bags.bag import read_bag
        from omnical.calibration.factors_io import read_factors
        from omnical.cli.calibrate_output import print_estimate
        from omnical.cli.output import tell
        from omnical.cli.reference_options import odometry_for, warn
        from omnical.cli.robot_target import load_said_robot
        from omnical.errors import ConfigError
        from omnical.ips.beacons import load_beacon_map
        from omnical.kinematics.correction import CorrectionFactors
        from omnical.recording.topics import CMD_VEL
        from omnical.reports.campaign import estimate_and_write
        from omnical.reports.outputs import side_file, stage_files

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
        if installed is not None and sources.odometry != "odom":
            msg = (
                f"--installed: odometry from {sources.odometry} is computed with the nominal "
                "kinematics (nothing installed); drop --installed"
            )
            raise ConfigError(msg)
        prior = read_factors(installed).factors if installed is not None else None
        if sources.odometry != "odom":
            prior = CorrectionFactors()
        bmap = load_beacon_map(beacons) if beacons is not None else None
        with console().status("reading recordings"):
            recordings = [read_bag(bag) for bag in bags]
        for rec in recordings:
            for note in rec.notes:
                warn(note)
        recordings = [
            odometry_for(
                rec,
                sources.odometry,
                description,
                wheel_topic=sources.wheel_topic,
                dead_wheel_topic=sources.dead_wheel_topic,
                name=bag.name,
            )
            for bag, rec in zip(bags, recordings, strict=True)
        ]
        references = _references(bags, recordings, sources)
        if references is None:
            _check_ips_or_reference(bags, recordings)
        if chosen is None:
            no_commands = any(not rec.has(CMD_VEL) for rec in recordings)
            joint = references is not None or no_commands
            chosen = EstimationMethod.JOINT if joint else EstimationMethod.PROCEDURES
        comment = (
            f"omnical calibrate estimate {' '.join(map(str, bags))} --method {chosen}"
            + sources.options()
        )
        label = f"estimating the factors from {len(bags)} recording(s) ({chosen})"
        # the files put in place together
        with console().status(label), outputs.staged(tell) as staged:
            result = estimate_and_write(
                recordings,
                staged[0],
                method=chosen,
                installed=prior,
                hedge_offset_m=description.hedge_offset_m,
                beacons=bmap,
                comment=comment,
                references=references,
                # the bag's /odom: the robot's own resolution; odometry computed here from the
                # wheels' positions does not drift by a rounded rate
                odom_yaw_resolution_radps=(
                    description.odom_yaw_resolution_radps if sources.odometry == "odom" else 0.0
                ),
            )
        print_estimate(description.name, result, chosen, final)


def _references(
    bags: list[Path], recordings: list[Recording], sources: Sources
) -> list[ExternalReference] | None:
    """The external reference of each recording, or None for the IPS."""
    if not sources.external:
        return None
    import numpy as np

    from omnical.calibration.campaign import ExternalReference
    from omnical.cli.reference_options import reference_for

    refs = []
    for bag, rec in zip(bags, recordings, strict=True):
        ref = reference_for(
            bag, rec, sources.reference_topic, sources.reference_child, sources.reference_file
        )
        assert ref is not None  # an external reference was given
        t_ns = np.int64(rec.start_ns) + np.round(ref.t_s * 1e9).astype(np.int64)
        label = sources.reference_topic or str(sources.reference_file)
        refs.append(ExternalReference(t_ns, ref.xy_m, sources.reference_sigma_m, label=label))
    return refs


def _check_ips_or_reference(bags: list[Path], recordings: list[Recording]) -> None:
    """Without an external reference every recording needs the IPS's raw distances.

    Raises:
        RecordingError: a recording has none; the pose topics of its bag are suggested.
    """
    from omnical.bags.reference_topics import bag_topics, pose_topics
    from omnical.errors import RecordingError
    from omnical.recording.topics import BEACON_RAW_DISTANCE

    for bag, rec in zip(bags, recordings, strict=True):
        if rec.has(BEACON_RAW_DISTANCE) and len(rec.topic(BEACON_RAW_DISTANCE)) > 0:
            continue
        poses = pose_topics(bag_topics(bag))
        hint = (
            f"it has the pose topic(s) {', '.join(poses)}: give one as the reference with "
            f"--reference-topic {poses[0]}"
            if poses
            else "give a reference with --reference-topic TOPIC or --reference-file FILE"
        )
        msg = f"{bag}: no IPS raw distances (/beacon_raw_distance) to calibrate against; {hint}"
        raise RecordingError(msg)
