"""The procedures' analyses on recordings of a simulator that is not ours (issue 4).

`foreign_sim` shares no code with omnical's twin or kinematics; only the documented topics reach
the analysis. Its beacon map, addresses, rates, latency, hedgehog mounting and odometry origin
all differ from the twin's.
"""

from __future__ import annotations

import dataclasses

import foreign_sim as fs
import numpy as np
import pytest

from omnical.calibration.procedures.analysis import analyse_procedures
from omnical.calibration.procedures.scripts import (
    lateral_procedure,
    longitudinal_procedure,
    rotation_procedure,
)
from omnical.experiment.script import parse_script
from omnical.robot.loader import load_robot


@pytest.mark.parametrize("seed", [10, 20])
def test_procedures_recover_a_foreign_simulators_truth(seed: int) -> None:
    limits = load_robot("rosy-mecanum").limits
    truth = dataclasses.replace(fs.ForeignTruth(), start_map=(1.5, 1.6, 0.0))
    recordings = []
    for i, proc in enumerate((rotation_procedure(), longitudinal_procedure(), lateral_procedure())):
        script = parse_script(proc, limits)
        recordings.append(
            fs.simulate(script.twist_at, script.duration_s + 2.0, truth, seed=seed + i)
        )
    offset = (truth.hedge_offset_m[0], truth.hedge_offset_m[1], truth.hedge_z_m)
    est = analyse_procedures(recordings, hedge_offset_m=offset)
    np.testing.assert_allclose(est.factors.scales, truth.scales, rtol=0.005)
    np.testing.assert_allclose(est.factors.crosstalks_rad_per_m, truth.crosstalks, atol=0.0015)
