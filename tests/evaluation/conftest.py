"""Short twin recordings shared by the evaluation tests (simulated once per session)."""

from __future__ import annotations

import pytest

from omnical.experiment.script import load_script
from omnical.recording.recording import Recording
from omnical.robot.description import RobotDescription
from omnical.robot.loader import load_robot
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.session import simulate_run


@pytest.fixture(scope="session")
def rosy() -> RobotDescription:
    return load_robot("rosy-mecanum")


@pytest.fixture(scope="session")
def ideal_straight(rosy: RobotDescription) -> Recording:
    """straight-10m on a twin without imperfections."""
    return simulate_run(
        load_script("straight-10m", rosy.limits), rosy, TwinParams.ideal_twin(), seed=1
    )


@pytest.fixture(scope="session")
def ideal_tour(rosy: RobotDescription) -> Recording:
    """The tour (three turns in place) on a twin without imperfections."""
    return simulate_run(load_script("tour", rosy.limits), rosy, TwinParams.ideal_twin(), seed=1)


@pytest.fixture(scope="session")
def default_tour(rosy: RobotDescription) -> Recording:
    """The tour on the default twin: seed 000 Table 2 truth, uncalibrated, noisy IPS."""
    return simulate_run(load_script("tour", rosy.limits), rosy, default_twin(rosy), seed=4)
