"""``omnical calibrate estimate``'s work, for the command and ``fleet calibrate``: the recordings
read with the odometry and reference their options name and the method chosen
(:func:`read_for_estimate`), then the factors estimated and written (:class:`EstimateInputs`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from omnical.bags.bag import read_bag, resolve_source
from omnical.bags.recover import storage_file
from omnical.calibration.campaign import ExternalReference, FactorEstimate, estimate_factors
from omnical.calibration.export import write_c_header, write_wheeltec_params
from omnical.calibration.factors_io import read_factors, write_factors
from omnical.calibration.procedures.tracks import yaw_deadband_radps
from omnical.choices import EstimationMethod
from omnical.errors import ConfigError, RecordingError
from omnical.ips.beacons import BeaconMap, load_beacon_map
from omnical.kinematics.correction import CorrectionFactors
from omnical.recording.recording import Recording
from omnical.recording.topics import BEACON_RAW_DISTANCE, CMD_VEL
from omnical.reports.outputs import side_file
from omnical.robot.description import RobotDescription
from omnical.services.sources import (
    ReadReference,
    Sources,
    check_installed,
    odometry_for,
    reference_for,
)
from omnical.services.voice import SILENT, Voice

__all__ = ["EstimateInputs", "read_for_estimate"]


@dataclass(frozen=True)
class EstimateInputs:
    """What the factors are estimated from (:func:`read_for_estimate`).

    Attributes:
        bags: the recordings' paths; recordings: as read, with the odometry of ``sources``.
        robot: their robot; sources: the odometry and reference options.
        references: each recording's external reference as read (empty: the IPS).
        method: how the factors are estimated.
        installed: the factors the recordings ran with (None: what they say).
        beacons: the beacon map (None: the recordings').
    """

    bags: tuple[Path, ...]
    recordings: list[Recording]
    robot: RobotDescription
    sources: Sources
    references: tuple[ReadReference, ...]
    method: EstimationMethod
    installed: CorrectionFactors | None
    beacons: BeaconMap | None

    def estimate_and_write(self, out: Path, command: str) -> FactorEstimate:
        """The factors, written to ``out`` (factors.yaml) with the firmware header and the
        Wheeltec ROS parameters beside it (``NAME.h``, ``NAME.wheeltec.yaml``); their comment
        is ``command`` with the recordings and the options."""
        s = self.sources
        references = None
        if self.references:
            label = s.reference_topic or str(s.reference_file)
            references = []
            for rec, ref in zip(self.recordings, self.references, strict=True):
                assert ref.trajectory is not None  # an external reference, read
                t_ns = np.int64(rec.start_ns) + np.round(ref.trajectory.t_s * 1e9).astype(np.int64)
                xy_m = ref.trajectory.xy_m
                references.append(ExternalReference(t_ns, xy_m, s.reference_sigma_m, label=label))
        # the bag's /odom: the robot's own resolution; odometry computed here from the wheels'
        # positions does not drift by a rounded rate
        resolution = self.robot.odom_yaw_resolution_radps if s.odometry == "odom" else 0.0
        result = estimate_factors(
            self.recordings,
            installed=self.installed,
            method=self.method,
            hedge_offset_m=self.robot.hedge_offset_m,
            beacons=self.beacons,
            references=references,
            odom_yaw_deadband_radps=yaw_deadband_radps(resolution),
        )
        bags = " ".join(map(str, self.bags))
        comment = f"{command} {bags} --method {self.method}{s.options()}"
        unc, held = result.uncertainty(), result.held
        write_factors(out, result.factors, unc, comment=comment, held=held)
        write_c_header(side_file(out, ".h"), result.factors, unc, held=held)
        write_wheeltec_params(side_file(out, ".wheeltec.yaml"), result.factors, unc, held=held)
        return result


def _each_once(bags: list[Path]) -> None:
    """Refuse a recording given twice (overlapping globs): it would count twice, every 1σ
    shrunk by √2."""
    seen: dict[Path, Path] = {}
    for bag in bags:
        source = resolve_source(bag)  # a folder, its X.mcap alias, or its storage file itself
        key = (storage_file(source) or source).resolve()
        if key in seen:
            msg = (
                f"{bag}: the same recording as {seen[key]}, given before: each recording "
                "counts once (twice, every 1σ would shrink by √2)"
            )
            raise ConfigError(msg)
        seen[key] = bag


def read_for_estimate(
    bags: list[Path],
    *,
    robot: RobotDescription,
    sources: Sources,
    method: EstimationMethod | None = None,
    installed: Path | None = None,
    beacons: Path | None = None,
    hints: bool = True,
    voice: Voice = SILENT,
) -> EstimateInputs:
    """Read what ``calibrate estimate`` estimates from: the ``installed`` factors (None: what
    the recordings say; odometry computed here: none), the ``beacons`` map (None: the
    recordings'), the ``bags`` with the odometry ``sources`` name and their external reference;
    choose the ``method`` unless given (joint with an external reference or a recording without
    ``/cmd_vel``, else seed 000's procedures). ``hints``: a refusal names a bag's pose topics
    (read again from it), the single command's message (False: the fleet rows' short one).
    ``voice``: what was read and used, the warnings, the spinner.

    Raises:
        ConfigError: ``installed`` with computed odometry; a recording given twice.
        RecordingError: without an external reference, a recording without the IPS's raw
            distances (and as reading the recordings raises).
    """
    check_installed(installed, sources.odometry)
    _each_once(bags)
    prior = read_factors(installed).factors if installed is not None else None
    if sources.odometry != "odom":  # computed with the nominal kinematics: nothing installed
        prior = CorrectionFactors()
    bmap = load_beacon_map(beacons) if beacons is not None else None
    with voice.status("reading recordings"):
        recordings = [read_bag(bag) for bag in bags]
    for rec in recordings:
        for note in rec.notes:
            voice.warn(note)
    recordings = [
        odometry_for(rec, sources, robot, name=bag.name, voice=voice)
        for bag, rec in zip(bags, recordings, strict=True)
    ]
    references = []
    if sources.external:
        for bag, rec in zip(bags, recordings, strict=True):
            ref = reference_for(bag, rec, sources, voice)
            assert ref is not None  # an external reference was given
            references.append(ref)
    else:
        _check_ips(bags, recordings, hints)
    if method is None:
        joint = sources.external or any(not rec.has(CMD_VEL) for rec in recordings)
        method = EstimationMethod.JOINT if joint else EstimationMethod.PROCEDURES
    return EstimateInputs(
        tuple(bags), recordings, robot, sources, tuple(references), method, prior, bmap
    )


def _check_ips(bags: list[Path], recordings: list[Recording], hints: bool) -> None:
    """Without an external reference every recording needs the IPS's raw distances.

    Raises:
        RecordingError: a recording has none (with ``hints``, the pose topics of its bag are
            suggested).
    """
    for bag, rec in zip(bags, recordings, strict=True):
        if rec.has(BEACON_RAW_DISTANCE) and len(rec.topic(BEACON_RAW_DISTANCE)) > 0:
            continue
        what = "no IPS raw distances (/beacon_raw_distance) to calibrate against"
        if not hints:
            msg = f"{bag.name}: {what}; give a reference with --reference-topic or --reference-file"
            raise RecordingError(msg)
        from omnical.bags.reference_topics import bag_topics, pose_topics

        poses = pose_topics(bag_topics(bag))
        hint = (
            f"it has the pose topic(s) {', '.join(poses)}: give one as the reference with "
            f"--reference-topic {poses[0]}"
            if poses
            else "give a reference with --reference-topic TOPIC or --reference-file FILE"
        )
        raise RecordingError(f"{bag}: {what}; {hint}")
