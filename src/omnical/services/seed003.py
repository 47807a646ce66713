"""Seed 003 end to end on the omni-X twin: tuned motors, its own odometry in the loop, its tests.

:func:`run_seed003` tunes the motors, measures Table II and runs the four tests (results only);
:func:`run_seed003_test` / :func:`run_task_on` run one test on any robot or rig.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from omnical.control.centred import task_controller
from omnical.control.limits import DEFAULT_COMMAND_LIMITS, CommandLimits
from omnical.control.loop import ControlLog, ControlOutput
from omnical.control.rig_loop import ControlRig, RigControlRun, path_in_frame, run_controller_on
from omnical.estimation.se2 import Pose2, wrap_angle
from omnical.experiment.library import BUILTIN_TASKS, BuiltinTask
from omnical.experiment.rig import RowSink
from omnical.ips.beacons import BeaconMap
from omnical.kinematics.correction import CorrectionFactors
from omnical.paper import SEED003_PAPER_TABLE2, SEED003_PAPER_TEST_ERRORS
from omnical.recording.recording import RecordingBuilder
from omnical.robot.description import RobotDescription
from omnical.robot.loader import load_robot
from omnical.twin.closed_loop import ClosedLoopRun
from omnical.twin.motor import LoopDisturbance, MotorTuning, seed003_motor_tuning, seed003_table2
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.rig import TwinRig
from omnical.twin.simulator import wheel_command_limit

__all__ = [
    "SEED003_PAPER_TABLE2",
    "SEED003_PAPER_TEST_ERRORS",
    "Seed003Result",
    "Seed003Test",
    "TaskRun",
    "TestErrors",
    "max_leg_deviation",
    "run_seed003",
    "run_seed003_test",
    "run_task_on",
    "task_errors",
    "task_pose_source",
]

Progress = Callable[[str], None]

ERROR_LABELS: dict[str, tuple[str, str]] = {
    "centred-turning": ("final heading error, °", "final distance error, cm"),
    "driving-forward": ("final x error, cm", "final y error, cm"),
    "square": ("max |x error|, cm", "max |y error|, cm"),
    "triangle": ("max |x error|, cm", "max |y error|, cm"),
}
_START_MAP = (0.6, 1.8, 0.0)  # the path origin on the 2.4 × 2.4 m arena (room for the square)


@dataclass(frozen=True)
class TestErrors:
    """The two numbers the paper gives for one test (labels in :data:`ERROR_LABELS`)."""

    first: float
    second: float


@dataclass(frozen=True, eq=False)
class Seed003Test:
    """One positioning test.

    Attributes:
        slug, name: identifiers ("square", "square trajectory (Fig. 8)").
        reference_m: (P, 2) the reference path in the path frame, start point first.
        run: the closed-loop run (its ``estimates`` are the seed 003 estimate, map frame; None
            when wheel odometry closed the loop, :func:`task_pose_source`).
        estimate_path: (N, 4) t_s, x, y, ψ of the pose that closed the loop (the seed 003
            estimate, or the wheel odometry) in the path frame, from the loop's start to its end.
        truth_path: (N, 4) t_s, x, y, yaw of the ground truth in the path frame.
        estimate_errors, truth_errors: the paper's measures on the estimate and on the truth.
    """

    slug: str
    name: str
    reference_m: NDArray[np.float64]
    run: ClosedLoopRun
    estimate_path: NDArray[np.float64]
    truth_path: NDArray[np.float64]
    estimate_errors: TestErrors
    truth_errors: TestErrors


@dataclass(frozen=True, eq=False)
class Seed003Result:
    """Everything :func:`run_seed003` found.

    Attributes:
        robot: the omni-x description.
        params: the twin, with the chosen wheel PID installed.
        seed: the run's seed.
        tuning: Ku, Pu, the rules compared, the chosen gains.
        table2_setpoints_rpm: (10,) 110–200 rpm.
        table2_means_rpm: (10, 4) the twin's motors with the installed gains.
        tests: the four positioning tests.
    """

    robot: RobotDescription
    params: TwinParams
    seed: int
    tuning: MotorTuning
    table2_setpoints_rpm: NDArray[np.float64]
    table2_means_rpm: NDArray[np.float64]
    tests: tuple[Seed003Test, ...]


def _legs_at(control: ControlLog, t_s: NDArray[np.float64]) -> NDArray[np.int64]:
    """The reference leg being driven at each time: the controller's goal index at the latest
    tick at or before it (goal k is the end of leg k; the first goal before the loop, the last
    after it)."""
    ticks = np.searchsorted(control.t_s, t_s + 1e-9, side="right") - 1
    index = control.target_index[np.clip(ticks, 0, len(control.t_s) - 1)]
    return np.asarray(np.maximum(index, 0), dtype=np.int64)


def max_leg_deviation(
    path_xy: NDArray[np.float64], ref: NDArray[np.float64], legs: NDArray[np.int64]
) -> TestErrors:
    """Max |x| and |y| (cm) of each point's offset from the nearest point of the leg it was on.

    Args:
        path_xy: (N, 2) positions, path frame, m.
        ref: (P, 2) the reference polyline, start point first, m.
        legs: (N,) the leg each position was driven on (leg k runs from ``ref[k]`` to
            ``ref[k + 1]``; clipped to the legs there are).
    """
    leg = np.clip(legs, 0, len(ref) - 2)
    a, b = ref[leg], ref[leg + 1]
    d = b - a
    seg_len2 = np.maximum(np.sum(d * d, axis=1), 1e-12)
    u = np.clip(np.sum((path_xy - a) * d, axis=1) / seg_len2, 0.0, 1.0)
    off = path_xy - (a + u[:, None] * d)
    return TestErrors(float(np.abs(off[:, 0]).max()) * 100, float(np.abs(off[:, 1]).max()) * 100)


def task_errors(
    slug: str, path: NDArray[np.float64], ref: NDArray[np.float64], control: ControlLog
) -> TestErrors:
    """The paper's two measures of test ``slug`` (:data:`ERROR_LABELS`) on ``path`` ((N, 4)
    t_s, x, y, yaw in the path frame) against the reference ``ref`` ((P, 2), start first)."""
    final = path[-1, 1:]
    goal = ref[-1]
    if slug == "centred-turning":
        heading = math.atan2(goal[1], goal[0])
        return TestErrors(
            abs(math.degrees(wrap_angle(float(final[2]) - heading))),
            math.hypot(float(final[0] - goal[0]), float(final[1] - goal[1])) * 100,
        )
    if slug == "driving-forward":
        return TestErrors(
            abs(float(final[0] - goal[0])) * 100, abs(float(final[1] - goal[1])) * 100
        )
    return max_leg_deviation(path[:, 1:3], ref, _legs_at(control, path[:, 0]))


def task_pose_source(robot: RobotDescription) -> Literal["seed003", "odometry"]:
    """What closes a seed 003 task's loop on ``robot``: the seed 003 estimate (dead wheels + IMU
    + magnetometer) when it has three or more dead wheels, else its wheel odometry."""
    return "seed003" if len(robot.dead_wheels) >= 3 else "odometry"


@dataclass(frozen=True, eq=False)
class TaskRun:
    """A seed 003 task on a rig, with the paper's measures.

    Attributes:
        run: the closed-loop run.
        pose: what closed the loop ("seed003" or "odometry", :func:`task_pose_source`).
        estimate_path: (N, 4) t_s, x, y, ψ of the pose that closed the loop in the path frame,
            from the loop's start to its end.
        truth_path: (N, 4) the ground truth in the path frame (a twin only), tail included.
        estimate_errors, truth_errors: the paper's measures on them (None: a stop ended the
            run, or no truth).
    """

    run: RigControlRun
    pose: str
    estimate_path: NDArray[np.float64]
    truth_path: NDArray[np.float64] | None
    estimate_errors: TestErrors | None
    truth_errors: TestErrors | None


def run_task_on(
    rig: ControlRig,
    task: BuiltinTask,
    robot: RobotDescription,
    sink: RowSink,
    *,
    installed: CorrectionFactors | None = None,
    start_pose_map: Pose2 = (0.0, 0.0, 0.0),
    on_tick: Callable[[float, ControlOutput], None] | None = None,
) -> TaskRun:
    """One seed 003 test on ``rig`` closed on :func:`task_pose_source`, recorded into ``sink``;
    measured as the paper does on the closing pose and, on a twin, on the truth.

    Raises:
        ConfigError: a task the seed 003 controller cannot run, a twin without the sensors.
    """
    pose = task_pose_source(robot) if "seed003" in rig.sources else "odometry"
    run = run_controller_on(
        rig,
        task_controller(task),
        sink,
        limits=CommandLimits.from_robot(robot.limits).tightened(DEFAULT_COMMAND_LIMITS),
        pose=pose,
        installed=installed,
        start_pose_map=start_pose_map,
        on_tick=on_tick,
    )
    t0, t_end = float(run.control.t_s[0]), float(run.control.t_s[-1])
    est = (
        run.odometry_path if run.estimates is None else path_in_frame(start_pose_map, run.estimates)
    )
    est = est[(est[:, 0] >= t0 - 1e-9) & (est[:, 0] <= t_end + 1e-9)]
    truth = None
    if run.ground_truth is not None and len(est):
        # the test ends when the loop stops; the truth's tail (the robot coming to rest) counts
        truth = path_in_frame(start_pose_map, run.ground_truth)
        truth = truth[truth[:, 0] >= est[0, 0] - 1e-9]
    ref = np.array(task.reference_m, dtype=np.float64)
    measured = not run.interrupted and len(est) > 0
    return TaskRun(
        run,
        pose,
        est,
        truth,
        task_errors(task.slug, est, ref, run.control) if measured else None,
        task_errors(task.slug, truth, ref, run.control) if measured and truth is not None else None,
    )


def run_seed003_test(
    task: BuiltinTask,
    robot: RobotDescription,
    params: TwinParams,
    *,
    seed: int = 0,
    beacons: BeaconMap | None = None,
) -> Seed003Test:
    """One seed 003 test on the twin (:func:`run_task_on` on a fresh twin), kept in memory.

    Raises:
        ConfigError: a task the seed 003 controller cannot run, a twin without the sensors.
        KeyboardInterrupt: Ctrl-C or SIGTERM (the robot was stopped).
    """
    builder = RecordingBuilder()
    start = params.start_pose_map
    origin: Pose2 = (float(start[0]), float(start[1]), float(start[2]))
    rig = TwinRig(robot, params, seed=seed, beacons=beacons)
    done = run_task_on(rig, task, robot, builder, start_pose_map=origin)
    if done.run.interrupted:
        raise done.run.control.interruption or KeyboardInterrupt
    assert done.estimate_errors and done.truth_errors and done.truth_path is not None
    return Seed003Test(
        task.slug,
        task.title,
        np.array(task.reference_m, dtype=np.float64),
        ClosedLoopRun.of(done.run, builder.build(), done.pose),
        done.estimate_path,
        done.truth_path,
        done.estimate_errors,
        done.truth_errors,
    )


def run_seed003(*, seed: int = 0, progress: Progress | None = None) -> Seed003Result:
    """Tune the omni-X twin's motors, install the gains, run the four tests (module docstring)."""
    say = progress or (lambda _msg: None)
    robot = load_robot("omni-x")
    base = replace(default_twin(robot), start_pose_map=_START_MAP)
    dtr = robot.drive_train
    motors = base.wheel_motors(dtr, robot.wheel_count)
    disturbance = LoopDisturbance.of_twin(base)

    say("Ziegler–Nichols tuning at 100 rpm")
    tuning = seed003_motor_tuning(
        dtr,
        motors[0],
        output_limit_radps=wheel_command_limit(robot),
        disturbance=disturbance,
        seed=seed,
    )
    params = base.with_wheel_pid(tuning.chosen.pid)

    say("Table II")
    setpoints, means = seed003_table2(
        dtr, tuning.chosen.pid, motors, disturbance=disturbance, seed=seed
    )

    tests = []
    for i, task in enumerate(BUILTIN_TASKS):
        say(task.title)
        tests.append(run_seed003_test(task, robot, params, seed=seed + i))
    return Seed003Result(
        robot,
        params,
        seed,
        tuning,
        np.asarray(setpoints, dtype=np.float64),
        np.asarray(means, dtype=np.float64),
        tuple(tests),
    )
