"""Seed 003 end to end on the omni-X twin: tuned motors, its own odometry in the loop, its tests.

:func:`run_seed003` does what seed 003 did, on the ``omni-x`` twin (:func:`omnical.twin.default_twin`:
true motors with gain, lag and friction errors, imperfect dead wheels with 1 % slip, IMU with gyro
bias, magnetometer):

1. **Motor tuning** (§IV.A, Fig. 5, Table II): Ziegler–Nichols 2 on the twin's first motor at
   100 rpm (ultimate gain and period by gain bisection), the rules compared on the 100 rpm step,
   the classic PID row refined when it overshoots more than 25 % (small-signal), the chosen
   gains installed in the firmware's four wheel loops, and Table II measured as the paper did
   (100 readings, mean of 10 tests, each motor, 110–200 rpm) with the motors' reading noise and
   load ripple.
2. **The four positioning tests** (§IV.B, Figs. 6–9), closed on the seed 003 estimate (dead
   wheels + IMU yaw + magnetometer, :class:`~omnical.estimation.seed003_estimator.Seed003PoseSource`):
   centred turning to (100, 100) cm, driving forward to (125, 100) cm, the square
   X = {0, 120, 120, 0, 0}, Y = {0, 0, −120, −120, 0} cm and the triangle X = {0, 120, 60, 0},
   Y = {0, 0, 60, 0} cm, the trajectories driven as the paper drove them: straight from corner
   to corner with the heading held (its inverse kinematics with (Vx, Vy), §IV.B.3; the triangle's
   second leg is the diagonal to (60, 60), Fig. 9).

The errors are measured as the paper states them (final heading and distance; final x and y;
maximum |x| and |y| deviation from the reference path), once on the estimate (what the paper
could measure) and once on the ground truth (what it could not). Returns results, writes nothing.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from omnical.control.centred import CentredController, CentredMode
from omnical.estimation.se2 import between_poses, wrap_angle
from omnical.paper import SEED003_PAPER_TABLE2, SEED003_PAPER_TEST_ERRORS
from omnical.robot.description import RobotDescription
from omnical.robot.loader import load_robot
from omnical.twin.closed_loop import ClosedLoopRun, closed_loop_run
from omnical.twin.motor import LoopDisturbance, MotorTuning, seed003_motor_tuning, seed003_table2
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.simulator import wheel_command_limit

__all__ = [
    "SEED003_PAPER_TABLE2",
    "SEED003_PAPER_TEST_ERRORS",
    "Seed003Result",
    "Seed003Test",
    "TestErrors",
    "run_seed003",
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
        run: the closed-loop run (its ``estimates`` are the seed 003 estimate, map frame).
        estimate_path: (N, 4) t_s, x, y, ψ of the estimate in the path frame.
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


def _max_axis_deviation(path_xy: NDArray[np.float64], ref: NDArray[np.float64]) -> TestErrors:
    """Max |x| and |y| of each point's offset from the nearest point of the reference polyline."""
    a, b = ref[:-1], ref[1:]
    d = b - a
    seg_len2 = np.maximum(np.sum(d * d, axis=1), 1e-12)
    p = path_xy[:, None, :]
    u = np.clip(np.sum((p - a) * d, axis=2) / seg_len2, 0.0, 1.0)
    nearest = a + u[..., None] * d
    offset = p - nearest
    which = np.argmin(np.sum(offset * offset, axis=2), axis=1)
    off = offset[np.arange(len(path_xy)), which]
    return TestErrors(float(np.abs(off[:, 0]).max()) * 100, float(np.abs(off[:, 1]).max()) * 100)


def _errors(slug: str, path: NDArray[np.float64], ref: NDArray[np.float64]) -> TestErrors:
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
    return _max_axis_deviation(path[:, 1:3], ref)


def _cases() -> tuple[tuple[str, str, CentredController, tuple[tuple[float, float], ...]], ...]:
    square = ((0.0, 0.0), (1.2, 0.0), (1.2, -1.2), (0.0, -1.2), (0.0, 0.0))
    triangle = ((0.0, 0.0), (1.2, 0.0), (0.6, 0.6), (0.0, 0.0))
    return (
        (
            "centred-turning",
            "centred turning to (100, 100) cm (Fig. 6)",
            CentredController(((1.0, 1.0),), mode=CentredMode.CENTRED_TURNING),
            ((0.0, 0.0), (1.0, 1.0)),
        ),
        (
            "driving-forward",
            "driving forward to (125, 100) cm (Fig. 7)",
            CentredController(((1.25, 1.0),), mode=CentredMode.DRIVING_FORWARD),
            ((0.0, 0.0), (1.25, 0.0), (1.25, 1.0)),
        ),
        (
            "square",
            "square trajectory (Fig. 8)",
            CentredController(square[1:], mode=CentredMode.TRANSLATE),
            square,
        ),
        (
            "triangle",
            "triangle trajectory (Fig. 9)",
            CentredController(triangle[1:], mode=CentredMode.TRANSLATE),
            triangle,
        ),
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
    for i, (slug, name, controller, outline) in enumerate(_cases()):
        say(name)
        run = closed_loop_run(controller, robot, params, seed=seed + i, pose_source="seed003")
        ref = np.array(outline, dtype=np.float64)
        assert run.estimates is not None
        origin = np.asarray(run.path_origin_map)
        est = np.column_stack([run.estimates[:, 0], between_poses(origin, run.estimates[:, 1:])])
        truth = run.ground_truth_path()
        # the test ends when the loop stops; the truth's tail (the robot coming to rest) counts
        t_end = float(run.control.t_s[-1])
        truth_run = truth[truth[:, 0] >= est[0, 0] - 1e-9]
        tests.append(
            Seed003Test(
                slug,
                name,
                ref,
                run,
                est[est[:, 0] <= t_end + 1e-9],
                truth_run,
                _errors(slug, est[est[:, 0] <= t_end + 1e-9], ref),
                _errors(slug, truth_run, ref),
            )
        )
    return Seed003Result(
        robot,
        params,
        seed,
        tuning,
        np.asarray(setpoints, dtype=np.float64),
        np.asarray(means, dtype=np.float64),
        tuple(tests),
    )
