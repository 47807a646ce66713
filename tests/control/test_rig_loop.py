"""The experiments written once against a rig, driven on the twin rig (what the serial rig runs).

``run_controller_on`` and ``navigate_on`` are the code a robot over serial runs too; here they
run in simulated time, where every stop, refusal and recording rule can be checked exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
import pytest

from omnical.control.limits import DEFAULT_COMMAND_LIMITS, CommandLimits
from omnical.control.loop import ControlOutput
from omnical.control.rig_loop import run_controller_on
from omnical.control.waypoint import WaypointController
from omnical.drivers.safety import PathCheck
from omnical.errors import ConfigError, SafetyStopError
from omnical.estimation.fusion import FusionParams
from omnical.kinematics.correction import CorrectionFactors
from omnical.navigation.grid import OccupancyGrid
from omnical.navigation.inflation import InflatedMap, inflate
from omnical.navigation.prm import PlanParams, Roadmap, build_roadmap
from omnical.recording.recording import RecordingBuilder
from omnical.recording.topics import CMD_VEL, EVENTS, GROUND_TRUTH, ODOM
from omnical.robot.loader import load_robot
from omnical.services.navigation import navigate_on, robot_footprint
from omnical.twin.params import TwinParams
from omnical.twin.rig import TwinRig

ROBOT = load_robot("rosy-mecanum")
LIMITS = CommandLimits.from_robot(ROBOT.limits).tightened(DEFAULT_COMMAND_LIMITS)
GOAL = (0.6, 0.0)
START = (1.0, 0.2, 0.0)  # in _navigation's room, beside its block
FIRST = (1.4, 0.3)


def _rig(**kwargs: object) -> TwinRig:
    return TwinRig(ROBOT, TwinParams.ideal_twin(), seed=1, **kwargs)  # type: ignore[arg-type]


def test_a_loop_on_the_rig_records_what_it_commanded_and_sensed() -> None:
    sink = RecordingBuilder()
    installed = CorrectionFactors.identity()
    run = run_controller_on(
        _rig(), WaypointController((GOAL,)), sink, limits=LIMITS, installed=installed
    )
    rec = sink.build()
    assert run.control.reason == "done"
    for topic in (CMD_VEL, EVENTS, ODOM, GROUND_TRUTH):
        assert rec.has(topic), topic
    texts = list(rec.topic(EVENTS)["text"])
    assert "installed_factors" in texts[0]  # the run's first event
    # the ideal twin: odometry is the truth; the path ends at the goal within the tolerance
    end = run.odometry_path[-1, 1:3]
    assert np.hypot(*(end - np.asarray(GOAL))) < 0.03
    assert run.ground_truth is not None
    assert run.odometry_path[0, 0] >= run.control.t_s[0] - 0.1  # the loop's span only
    # lead-in and tail at rest are recorded around the loop
    t_cmd = (np.asarray(rec.topic(CMD_VEL).t_ns) - run.origin_ns) / 1e9
    assert t_cmd[0] == pytest.approx(1.0, abs=0.06)
    t_gt = (np.asarray(rec.topic(GROUND_TRUTH).t_ns) - run.origin_ns) / 1e9
    assert t_gt[-1] >= run.control.t_s[-1] + 1.9


def test_a_stop_in_the_loop_keeps_what_was_recorded_and_hands_the_stop_back() -> None:
    sink = RecordingBuilder()

    def stop_late(t_s: float, _out: ControlOutput) -> None:
        if t_s > 1.0:
            raise SafetyStopError("vehicle controller", 0.2, "no status")

    run = run_controller_on(
        _rig(), WaypointController((GOAL,)), sink, limits=LIMITS, on_tick=stop_late
    )
    assert run.interrupted
    assert isinstance(run.control.interruption, SafetyStopError)
    rec = sink.build()
    assert rec.has(CMD_VEL) and rec.has(ODOM)  # recorded although the run was cut
    assert float(rec.topic(CMD_VEL)["vx_mps"][-1]) == 0.0  # the last command: zero
    t_gt = (np.asarray(rec.topic(GROUND_TRUTH).t_ns) - run.origin_ns) / 1e9
    assert t_gt[-1] < run.control.t_s[-1] + 0.1  # no tail after a stop


def test_a_loop_closes_only_on_a_source_the_rig_has() -> None:
    @dataclass(frozen=True)
    class OdometryOnly(TwinRig):
        sources: ClassVar[frozenset[str]] = frozenset({"odometry"})

    rig = OdometryOnly(ROBOT, TwinParams.ideal_twin())
    with pytest.raises(ConfigError, match="cannot close a loop on 'fused'"):
        run_controller_on(
            rig, WaypointController((GOAL,)), RecordingBuilder(), limits=LIMITS, pose="fused"
        )
    with pytest.raises(ConfigError, match="fusion parameters"):
        run_controller_on(
            _rig(), WaypointController((GOAL,)), RecordingBuilder(), limits=LIMITS, pose="fused"
        )


def test_a_fused_loop_starts_from_the_fixes_at_rest_with_the_hedgehog_offset() -> None:
    offset = (float(ROBOT.hedge_offset_m[0]), float(ROBOT.hedge_offset_m[1]))
    params = replace(TwinParams.ideal_twin(), start_pose_map=(1.5, 1.2, 0.3))
    rig = TwinRig(ROBOT, params, seed=2)
    run = run_controller_on(
        rig,
        WaypointController((GOAL,)),
        RecordingBuilder(),
        limits=LIMITS,
        pose="fused",
        fusion=FusionParams(hedge_offset_m=offset),
        start_pose_map=(1.5, 1.2, 0.3),
    )
    assert run.control.reason == "done" and run.estimates is not None
    assert run.accepted > 10
    first = run.estimates[0, 1:3]
    assert np.hypot(first[0] - 1.5, first[1] - 1.2) < 0.03  # the base, not the hedgehog


def _navigation() -> tuple[InflatedMap, PlanParams, Roadmap]:
    """A 4 × 3 m walled room with a block at (0–0.5, 0.5–1) m."""
    occ = np.zeros((60, 80), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    occ[20:30, 20:30] = True
    grid = OccupancyGrid.from_occupied(occ, 0.05, (-1.0, -0.5, 0.0))
    inflated = inflate(grid, footprint=robot_footprint(ROBOT))
    plan_params = PlanParams()
    return inflated, plan_params, build_roadmap(inflated, plan_params.prm)


def test_navigation_on_the_rig_stops_before_a_refused_leg_moves() -> None:
    inflated, plan_params, roadmap = _navigation()
    params = replace(TwinParams.ideal_twin(), start_pose_map=START)
    offset = (float(ROBOT.hedge_offset_m[0]), float(ROBOT.hedge_offset_m[1]))
    refused: list[tuple[float, float]] = []

    def refuse_second(path_m: np.ndarray, goal: tuple[float, float]) -> PathCheck:
        ok = goal == FIRST
        if not ok:
            refused.append(goal)
        return PathCheck(ok, 0.5 if ok else -0.1, None, "" if ok else "outside the coverage")

    sink = RecordingBuilder()
    clock: list[float] = []
    nav = navigate_on(
        TwinRig(ROBOT, params, seed=3),
        sink,
        [FIRST, (1.2, 1.5)],
        ["waypoint", "tracking"],
        inflated=inflated,
        roadmap=roadmap,
        plan_params=plan_params,
        limits=LIMITS,
        start_pose_map=START,
        fusion=FusionParams(hedge_offset_m=offset),
        check_leg=refuse_second,
        on_time=clock.append,
    )
    assert [leg.control is not None for leg in nav.legs] == [True, False]
    # the twin's rows reach the sink at its end: the progress display follows its clock
    leg_s = float(nav.legs[0].control.t_s[-1])  # type: ignore[union-attr]
    assert len(clock) > 10 and np.all(np.diff(clock) > 0) and clock[-1] >= leg_s - 0.1
    assert refused == [(1.2, 1.5)], nav.legs[1].plan.reason
    assert nav.stopped_because == "refused: outside the coverage"
    assert not nav.reached and nav.interruption is None
    assert nav.legs[0].estimated_error_m < 0.05  # localised by the fixes
    assert nav.legs[0].goal_error_m < 0.05  # and by the twin's truth
    assert sink.build().has(CMD_VEL)
