"""Command output stage (saturation, acceleration limiting) and the closed control loop."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest

from omnical.control.limits import (
    DEFAULT_COMMAND_LIMITS,
    CommandLimits,
    limit_acceleration,
    limit_command,
    saturate_twist,
)
from omnical.control.loop import ControlOutput, run_controller
from omnical.control.waypoint import WaypointController
from omnical.errors import ConfigError, LimitError
from omnical.estimation.se2 import Pose2
from omnical.experiment.ports import RobotState
from omnical.robot.loader import load_robot
from omnical.trajectory.references import SEED001_SQUARE_M
from omnical.twin.clock import TwinClock
from omnical.twin.closed_loop import closed_loop_run
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.simulator import DigitalTwin

MECANUM = load_robot("rosy-mecanum")
SQUARE = (*SEED001_SQUARE_M[1:], SEED001_SQUARE_M[0])


# --------------------------------------------------------------------------- limits


def test_saturation_per_axis_then_norm_keeps_direction() -> None:
    lim = CommandLimits(max_vx_mps=0.3, max_vy_mps=0.2, max_wz_radps=1.0, max_speed_mps=0.25)
    assert saturate_twist(lim, (0.1, 0.05, -0.5)) == (0.1, 0.05, -0.5)
    vx, vy, wz = saturate_twist(lim, (0.6, 0.0, -3.0))
    assert (vx, vy, wz) == (0.25, 0.0, -1.0)
    vx, vy, _ = saturate_twist(lim, (0.3, 0.3, 0.0))  # vy clipped to 0.2 first, then the norm
    assert math.hypot(vx, vy) == pytest.approx(0.25)
    assert vy / vx == pytest.approx(0.2 / 0.3)


def test_acceleration_limit_scales_translation_change_as_a_vector() -> None:
    lim = CommandLimits(max_ax_mps2=0.5, max_ay_mps2=0.5, max_alpha_radps2=1.0, max_accel_mps2=0.5)
    out = limit_acceleration(lim, (0.0, 0.0, 0.0), (0.3, 0.4, 2.0), 0.1)
    # |Δv| = 0.5 m/s > 0.05 → scaled by 0.1, direction kept; Δwz clamped to 0.1 rad/s
    assert out == pytest.approx((0.03, 0.04, 0.1))
    assert limit_acceleration(lim, (0.1, 0.0, 0.0), (0.12, 0.0, 0.05), 0.1) == pytest.approx(
        (0.12, 0.0, 0.05)
    )


def test_limit_command_respects_all_bounds_on_random_sequences() -> None:
    rng = np.random.default_rng(7)
    lim = DEFAULT_COMMAND_LIMITS
    dt = 0.05
    prev = (0.0, 0.0, 0.0)
    for _ in range(2000):
        raw = tuple(float(v) for v in rng.normal(0.0, 0.5, 3))
        out = limit_command(lim, prev, raw, dt)  # type: ignore[arg-type]
        lim.check(out)
        assert math.hypot(out[0], out[1]) <= 0.3 + 1e-12
        assert abs(out[0] - prev[0]) <= 0.3 * dt + 1e-12
        assert math.hypot(out[0] - prev[0], out[1] - prev[1]) <= 0.3 * dt + 1e-12
        assert abs(out[2] - prev[2]) <= 1.0 * dt + 1e-12
        prev = out


def test_limits_validation_and_helpers() -> None:
    with pytest.raises(ConfigError, match="max_vx_mps"):
        CommandLimits(max_vx_mps=0.0)
    with pytest.raises(ConfigError, match="max_speed_mps"):
        CommandLimits(max_speed_mps=math.nan)
    with pytest.raises(ConfigError, match="time step"):
        limit_acceleration(CommandLimits(), (0.0, 0.0, 0.0), (0.1, 0.0, 0.0), 0.0)
    with pytest.raises(ConfigError, match="finite"):
        saturate_twist(CommandLimits(), (math.inf, 0.0, 0.0))
    robot = CommandLimits.from_robot(MECANUM.limits)
    assert (robot.max_vx_mps, robot.max_speed_mps, robot.max_alpha_radps2) == (0.8, 0.8, 1.5)
    tight = robot.tightened(DEFAULT_COMMAND_LIMITS)
    assert (tight.max_vx_mps, tight.max_wz_radps, tight.max_alpha_radps2) == (0.3, 1.0, 1.0)
    with pytest.raises(LimitError, match="speed"):
        CommandLimits(max_speed_mps=0.1).check((0.08, 0.08, 0.0))


# --------------------------------------------------------------------------- loop, no twin


@dataclass
class _FakeRobot:
    """A point robot that moves exactly as commanded (to test the loop alone)."""

    x: float = 0.0
    t: float = 0.0
    v: float = 0.0
    stops: int = 0

    def send_twist(self, vx_mps: float, vy_mps: float, wz_radps: float) -> None:
        self.v = vx_mps

    def read_state(self) -> RobotState:
        return RobotState(self.t, (self.x, 0.0, 0.0), (self.v, 0.0, 0.0), (), 0.0)

    def stop(self) -> None:
        self.v = 0.0
        self.stops += 1


@dataclass
class _FakeClock:
    robot: _FakeRobot

    def now_s(self) -> float:
        return self.robot.t

    def sleep_until(self, t_s: float) -> None:
        self.robot.x += self.robot.v * (t_s - self.robot.t)
        self.robot.t = t_s


@dataclass(frozen=True)
class _GoTo:
    """Full speed ahead until x ≥ goal (a minimal controller)."""

    goal_m: float
    name: str = "goto"

    def initial_state(self) -> int:
        return 0

    def step(self, state: int, t_s: float, pose: Pose2, dt_s: float) -> tuple[ControlOutput, int]:
        done = pose[0] >= self.goal_m
        return ControlOutput((0.0 if done else 1.0, 0.0, 0.0), 0, "go", done), state + 1


def test_loop_ramps_with_acceleration_limit_and_stops_when_done() -> None:
    robot = _FakeRobot(t=3.0, x=5.0)  # odometry not at zero: the path frame starts here
    lim = CommandLimits(max_vx_mps=0.2, max_ax_mps2=0.5)
    log = run_controller(_GoTo(1.0), robot, _FakeClock(robot), rate_hz=10.0, limits=lim)
    assert log.reason == "done"
    v = log.command[:, 0]
    assert v[:5] == pytest.approx([0.05, 0.10, 0.15, 0.20, 0.20])  # 0.5 m/s² × 0.1 s per tick
    assert np.all(v <= 0.2 + 1e-12)
    assert log.pose[0, 0] == 0.0  # first odometry reading = path origin
    assert log.final_pose()[0] >= 1.0
    assert log.command[-1] == pytest.approx([0.0, 0.0, 0.0])
    assert log.mode[-1] == "stop"
    assert robot.stops >= 1
    # one /cmd_vel message per tick, the final stop folded into the goal's tick: times increase
    assert log.cmd_vel.shape == (log.t_s.shape[0] - 1, 4)
    assert np.all(np.diff(log.cmd_vel[:, 0]) > 0)
    kinds = [json.loads(e)["event"] for _, e in log.events]
    assert kinds[0] == "start"
    assert kinds[-1] == "end"
    assert json.loads(log.events[-1][1])["reason"] == "done"


def test_loop_times_out_and_validates() -> None:
    robot = _FakeRobot()
    log = run_controller(_GoTo(100.0), robot, _FakeClock(robot), rate_hz=10.0, max_duration_s=2.0)
    assert log.reason == "timeout"
    assert log.t_s[-1] == pytest.approx(2.1)
    assert robot.v == 0.0
    with pytest.raises(ConfigError, match="rate"):
        run_controller(_GoTo(1.0), robot, _FakeClock(robot), rate_hz=0.0)
    with pytest.raises(ConfigError, match="pose source"):
        run_controller(_GoTo(1.0), robot, _FakeClock(robot), pose_source="imu")  # type: ignore[arg-type]


# --------------------------------------------------------------------------- loop on the twin


def test_commands_on_the_twin_respect_saturation_and_acceleration() -> None:
    lim = CommandLimits(
        max_vx_mps=0.08,
        max_vy_mps=0.08,
        max_wz_radps=0.3,
        max_speed_mps=0.08,
        max_ax_mps2=0.1,
        max_ay_mps2=0.1,
        max_alpha_radps2=0.4,
    )
    run = closed_loop_run(
        WaypointController(SQUARE), MECANUM, TwinParams.ideal_twin(), seed=1, limits=lim
    )
    c = run.control
    assert c.reason == "done"
    cmd = c.command[:-1]  # the last row is the stop
    assert np.abs(cmd[:, 0]).max() == pytest.approx(0.08)  # the saturation is reached ...
    assert np.abs(cmd[:, 0]).max() <= 0.08 + 1e-12  # ... and never exceeded
    assert np.abs(cmd[:, 2]).max() <= 0.3 + 1e-12
    dv = np.abs(np.diff(cmd, axis=0))
    assert dv[:, 0].max() == pytest.approx(0.1 * 0.05)
    assert dv[:, 0].max() <= 0.1 * 0.05 + 1e-12
    assert dv[:, 2].max() <= 0.4 * 0.05 + 1e-12
    assert np.all(cmd[:, 1] == 0.0)  # seed 001 drives like a differential robot


def _speed_after(log: np.ndarray, t_s: float) -> float:
    rows = log[log[:, 0] >= t_s]
    return float(np.hypot(rows[:, 4], rows[:, 5]).max())


def test_emergency_stop_zeroes_the_command_at_once() -> None:
    stop_at = 8.0  # the robot is driving the first side at 0.1 m/s by then
    run = closed_loop_run(
        WaypointController(SQUARE),
        MECANUM,
        TwinParams.ideal_twin(),
        seed=2,
        emergency_stop=lambda t: t >= stop_at,
    )
    c = run.control
    assert c.reason == "emergency_stop"
    k = c.mode.index("emergency_stop")
    assert c.t_s[k] == pytest.approx(stop_at)
    assert c.command[k - 1, 0] == pytest.approx(0.1)  # full speed one tick before
    assert np.all(c.command[k:] == 0.0)
    gt = run.twin_log.ground_truth
    assert _speed_after(gt, stop_at + 0.3) < 1e-3  # the firmware ramp (0.5 m/s²) takes 0.2 s
    moved = np.hypot(*(gt[-1, 1:3] - gt[gt[:, 0] >= stop_at][0, 1:3]))
    assert moved < 0.02
    events = [json.loads(e)["event"] for e in run.recording.topic("/omnical/events")["text"]]
    assert "emergency_stop" in events


def test_pause_holds_zero_and_resumes() -> None:
    def paused(t: float) -> bool:
        return 8.0 <= t < 14.0

    free = closed_loop_run(WaypointController(SQUARE), MECANUM, TwinParams.ideal_twin(), seed=3)
    run = closed_loop_run(
        WaypointController(SQUARE), MECANUM, TwinParams.ideal_twin(), seed=3, pause=paused
    )
    c = run.control
    assert c.reason == "done"
    during = (c.t_s >= 8.0) & (c.t_s < 14.0)
    assert all(m == "paused" for m, d in zip(c.mode, during, strict=True) if d)
    # ramped down at the acceleration limit (0.3 m/s²: 0.1 m/s in 0.35 s), then held at zero
    assert np.all(c.command[(c.t_s >= 8.4) & (c.t_s < 14.0)] == 0.0)
    assert np.all(np.abs(np.diff(c.command[during | np.roll(during, 1), 0])) <= 0.3 * 0.05 + 1e-12)
    gt = run.twin_log.ground_truth
    still = gt[(gt[:, 0] >= 9.0) & (gt[:, 0] < 14.0)]
    assert np.hypot(*(still[-1, 1:3] - still[0, 1:3])) < 1e-3
    assert c.t_s[-1] - free.control.t_s[-1] == pytest.approx(6.0, abs=0.6)
    assert run.final_error_m(SQUARE[-1], "odometry") < 0.011
    kinds = [json.loads(e)["event"] for _, e in c.events]
    assert kinds.count("pause") == 1
    assert kinds.count("resume") == 1


def test_closed_loop_run_records_commands_events_and_twin_topics() -> None:
    rec = closed_loop_run(
        WaypointController(((0.5, 0.0),)), MECANUM, default_twin(MECANUM), seed=4
    ).recording
    for topic in (
        "/cmd_vel",
        "/odom",
        "/ground_truth",
        "/imu",
        "/hedge_pos_ang",
        "/omnical/events",
    ):
        assert rec.has(topic)
    cmd = rec.topic("/cmd_vel")
    assert float(np.max(cmd["vx_mps"])) == pytest.approx(0.1, abs=1e-4)
    assert float(cmd["vx_mps"][-1]) == 0.0
    events = [json.loads(e) for e in rec.topic("/omnical/events")["text"]]
    assert events[0]["event"] == "start"
    assert events[-1] == {"controller": "seed001-waypoint", "event": "end", "reason": "done"}
    assert rec.duration_s > 6.0


def test_twin_loop_with_a_callable_pose_source() -> None:
    twin = DigitalTwin(MECANUM, default_twin(MECANUM), seed=5)
    start = twin.ground_truth_pose

    def truth(_: RobotState) -> Pose2:
        x, y, yaw = twin.ground_truth_pose
        return (x - start[0], y - start[1], yaw - start[2])

    log = run_controller(
        WaypointController(((0.6, 0.0),)), twin, TwinClock(twin), pose_source=truth
    )
    twin.advance_to(twin.t_s + 1.0)
    x, y, _ = twin.ground_truth_pose
    assert log.reason == "done"
    assert math.hypot(x - start[0] - 0.6, y - start[1]) < 0.012


def test_cmd_vel_sends_each_command_once() -> None:
    """The goal's tick and the final stop row log the zero command at one time: one message."""
    from omnical.control.loop import ControlLog

    t = np.array([0.0, 0.05, 0.10, 0.10])
    command = np.array([[0.2, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    log = ControlLog(
        t_s=t,
        pose=np.zeros((4, 3)),
        command=command,
        raw_command=command,
        target_index=np.zeros(4, dtype=np.int64),
        mode=("drive", "drive", "drive", "stop"),
        reason="done",
    )
    cmd = log.cmd_vel
    assert cmd.shape == (3, 4)
    np.testing.assert_array_equal(cmd[:, 0], [0.0, 0.05, 0.10])
    # a zero command repeated at a later time is a message of its own
    later = ControlLog(**{**log.__dict__, "t_s": np.array([0.0, 0.05, 0.10, 0.15])})
    assert later.cmd_vel.shape == (4, 4)


class _Interrupt(KeyboardInterrupt):
    """Stands for Ctrl-C (or the CLI's Terminated) arriving during the loop."""


def _interrupt_at(t_stop_s: float) -> Callable[[float], bool]:
    def check(t_s: float) -> bool:
        if t_s >= t_stop_s:
            raise _Interrupt
        return False

    return check


def test_an_interruption_of_a_twin_loop_is_raised_again_or_kept_when_asked() -> None:
    # the demo and `omnical seed003` went on as if the loop had finished
    with pytest.raises(_Interrupt):
        closed_loop_run(
            WaypointController(SQUARE),
            MECANUM,
            TwinParams.ideal_twin(),
            seed=2,
            emergency_stop=_interrupt_at(5.0),
        )
    run = closed_loop_run(
        WaypointController(SQUARE),
        MECANUM,
        TwinParams.ideal_twin(),
        seed=2,
        emergency_stop=_interrupt_at(5.0),
        keep_interrupted=True,
    )
    assert run.control.reason == "interrupted"
    assert isinstance(run.control.interruption, _Interrupt)
    assert np.all(run.control.command[-1] == 0.0)
