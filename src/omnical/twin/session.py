"""A simulated run end to end: a motion script on the twin, recorded with the simulated IPS.

What ``omnical simulate`` does (:func:`simulate_run`): the Runner drives a
:class:`~omnical.twin.rig.TwinRig` through the script, and the run becomes one recording.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

from omnical.experiment.rig import LEAD_IN_S, TAIL_S, run_script_on
from omnical.experiment.script import CommandSource
from omnical.ips.beacons import BeaconMap
from omnical.recording.recording import Recording, RecordingBuilder
from omnical.robot.description import RobotDescription
from omnical.twin.params import TwinParams
from omnical.twin.rig import TwinRig

if TYPE_CHECKING:  # the world and the LiDAR are imported only when a run has a world
    from omnical.twin.world import World

__all__ = ["SHORT_RUN_S", "simulate_run"]

SHORT_RUN_S = 10.0
"""Runs shorter than this (robot s, lead-in and tail included) take the Python engine under
``"auto"``; both engines give the same logs."""


def simulate_run(
    script: CommandSource,
    robot: RobotDescription,
    params: TwinParams,
    *,
    seed: int = 0,
    beacons: BeaconMap | None = None,
    on_tick: Callable[[float, float], None] | None = None,
    world: World | None = None,
    keep_interrupted: bool = False,
) -> Recording:
    """Run ``script`` on a fresh twin and return the full recording (with IPS and ground truth).

    The robot stands still for 1 s before the script starts and 1 s after it ends. With a
    ``world`` the recording holds the LiDAR's ``/scan`` too (the run itself is the same).

    Ctrl-C or SIGTERM while the script runs stops the robot and is raised again, unless
    ``keep_interrupted``: then the run up to there is returned (``omnical simulate`` keeps it).
    """
    if params.engine == "auto" and script.duration_s + LEAD_IN_S + TAIL_S < SHORT_RUN_S:
        params = replace(params, engine="python")
    builder = RecordingBuilder()
    rig = TwinRig(robot, params, seed=seed, beacons=beacons, world=world)
    run = run_script_on(rig, script, builder, on_tick=on_tick)  # 1 s lead-in and tail
    if run.interrupted and not keep_interrupted:
        raise run.interruption or KeyboardInterrupt
    return builder.build()
