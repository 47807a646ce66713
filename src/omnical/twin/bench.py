"""The digital twin as a calibration bench, and the campaign on it.

:class:`TwinBench` runs every script on a fresh twin with the given factors installed;
:func:`run_twin_campaign` runs the whole seed 000 campaign on a twin, knowing its truth.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from omnical.calibration.campaign import (
    CampaignResult,
    EstimationMethod,
    ProgressFn,
    Tolerance,
    run_campaign,
)
from omnical.experiment.script import MotionScript
from omnical.ips.beacons import BeaconMap
from omnical.kinematics.correction import CorrectionFactors
from omnical.recording.recording import Recording
from omnical.robot.description import RobotDescription
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.session import simulate_run

__all__ = ["TwinBench", "run_seed", "run_twin_campaign"]


def run_seed(seed: int, name: str) -> int:
    """The seed of one named run of a campaign seeded with ``seed`` (stable across versions)."""
    state = np.random.SeedSequence([seed & 0xFFFFFFFF, zlib.crc32(name.encode("utf-8"))])
    return int(state.generate_state(1)[0])


@dataclass(frozen=True)
class TwinBench:
    """The digital twin as a bench: every run is a fresh twin from the start pose.

    Attributes:
        robot: the robot description.
        params: the twin (its ``installed_factors`` are replaced run by run).
        seed: campaign seed; each run's seed derives from it and the run's name.
        beacons: beacon map of the simulated IPS (default: seed 000 Table 3).
    """

    robot: RobotDescription
    params: TwinParams
    seed: int = 0
    beacons: BeaconMap | None = None

    def run(
        self,
        script: MotionScript,
        installed: CorrectionFactors,
        *,
        name: str,
        on_tick: Callable[[float, float], None] | None = None,
    ) -> Recording:
        """Simulate ``script`` with ``installed`` compensating (see ``Bench``)."""
        return simulate_run(
            script,
            self.robot,
            self.params.with_installed(installed),
            seed=run_seed(self.seed, name),
            beacons=self.beacons,
            on_tick=on_tick,
        )


def run_twin_campaign(
    robot: RobotDescription,
    params: TwinParams | None = None,
    *,
    seed: int = 0,
    tolerance: Tolerance | None = None,
    max_iterations: int = 4,
    on_progress: ProgressFn | None = None,
    method: EstimationMethod = "procedures",
    beacons: BeaconMap | None = None,
    validate: bool = True,
    measure: bool = True,
    procedures: Mapping[str, Mapping[str, Any]] | None = None,
) -> CampaignResult:
    """The seed 000 campaign on a twin (default: ``default_twin(robot)``), its truth in the result.

    The campaign starts from the twin's ``installed_factors``; the runs derive their seeds from
    ``seed`` and their names. Other arguments as :func:`omnical.calibration.campaign.run_campaign`.
    """
    twin = params if params is not None else default_twin(robot)
    return run_campaign(
        robot,
        TwinBench(robot, twin, seed=seed, beacons=beacons),
        seed=seed,
        tolerance=tolerance if tolerance is not None else Tolerance(),
        max_iterations=max_iterations,
        on_progress=on_progress,
        method=method,
        installed=twin.installed_factors,
        beacons=beacons,
        validate=validate,
        measure=measure,
        truth=twin.true_factors,
        procedures=procedures,
    )
