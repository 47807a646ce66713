"""Seed 003's position control (§IV.B): centred turning, driving forward, or straight to the goal.

:class:`CentredController` runs a sequence of goals in one mode: a PID per body axis and one on
the heading, the translation saturated on its norm.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import StrEnum

from omnical.control.loop import ControlOutput
from omnical.control.pid import PidParams, PidState, pid_step
from omnical.errors import ConfigError
from omnical.estimation.se2 import Pose2, rotate, wrap_angle
from omnical.experiment.library import BuiltinTask

__all__ = [
    "SEED003_HEADING_PID",
    "SEED003_POSITION_PID",
    "CentredController",
    "CentredMode",
    "CentredState",
    "centred_step",
    "task_controller",
]


#: Body-axis position loop (chosen; seed 003 gives no values): P = 0.8 (m/s)/m, within ±0.2 m/s.
SEED003_POSITION_PID = PidParams(kp=0.8, output_min=-0.2, output_max=0.2)
#: Heading loop (chosen): P = 2 (rad/s)/rad with a slow integral, within ±1 rad/s.
SEED003_HEADING_PID = PidParams(kp=2.0, ti_s=10.0, output_min=-1.0, output_max=1.0)


class CentredMode(StrEnum):
    """How a goal is approached."""

    CENTRED_TURNING = "centred_turning"
    DRIVING_FORWARD = "driving_forward"
    TRANSLATE = "translate"


@dataclass(frozen=True)
class CentredState:
    """What the seed 003 controller remembers between ticks.

    Attributes:
        index: goal being approached.
        phase: "turn"/"drive" (centred turning), "x"/"y" (driving forward), "drive"
            (translate); "" before a goal's first tick.
        heading_rad: heading held while driving (None until fixed).
        hold_m: coordinate held during the x phase of driving forward (the y at its start).
        x, y, yaw: states of the body-x, body-y and heading PIDs.
        done: the last goal was reached.
    """

    index: int = 0
    phase: str = ""
    heading_rad: float | None = None
    hold_m: float = 0.0
    x: PidState = field(default_factory=PidState)
    y: PidState = field(default_factory=PidState)
    yaw: PidState = field(default_factory=PidState)
    done: bool = False


def _goal(i: int, p: Sequence[float]) -> tuple[float, float]:
    if len(p) != 2 or not all(math.isfinite(v) for v in p):
        msg = f"goal {i}: expected finite (x, y), got {tuple(p)}"
        raise ConfigError(msg)
    return (float(p[0]), float(p[1]))


@dataclass(frozen=True)
class CentredController:
    """Seed 003's position controller over a sequence of goals.

    Attributes:
        goals_m: (x, y) goals in the path frame, in order (the start point excluded).
        mode: centred turning, driving forward or translate.
        position_pid: PID of each body axis, position error (m) → speed (m/s).
        heading_pid: PID of the heading, error (rad) → yaw rate (rad/s).
        max_speed_mps: saturation of the translational speed (norm).
        goal_tolerance_m: distance at which a goal is reached.
        axis_tolerance_m: |x error| that ends the x phase of driving forward.
        heading_tolerance_rad: heading error that ends the turn of centred turning.
        heading_rad: heading held by driving forward and translate; None = the heading at the
            first tick.
        name: label for logs.

    Raises:
        ConfigError: on construction, for no goals, a bad goal or a non-positive tolerance or speed.
    """

    goals_m: tuple[tuple[float, float], ...]
    mode: CentredMode = CentredMode.CENTRED_TURNING
    position_pid: PidParams = SEED003_POSITION_PID
    heading_pid: PidParams = SEED003_HEADING_PID
    max_speed_mps: float = 0.2
    goal_tolerance_m: float = 0.01
    axis_tolerance_m: float = 0.01
    heading_tolerance_rad: float = math.radians(1.0)
    heading_rad: float | None = None
    name: str = "seed003-position"

    def __post_init__(self) -> None:
        goals = tuple(_goal(i, p) for i, p in enumerate(self.goals_m))
        if not goals:
            msg = "the seed 003 controller needs at least one goal"
            raise ConfigError(msg)
        object.__setattr__(self, "goals_m", goals)
        try:
            object.__setattr__(self, "mode", CentredMode(self.mode))
        except ValueError as err:
            msg = f"unknown mode {self.mode!r}; use one of {[m.value for m in CentredMode]}"
            raise ConfigError(msg) from err
        for name in (
            "max_speed_mps",
            "goal_tolerance_m",
            "axis_tolerance_m",
            "heading_tolerance_rad",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                msg = f"{name} must be finite and > 0, got {value}"
                raise ConfigError(msg)

    def initial_state(self) -> CentredState:
        """State before the first tick."""
        return CentredState(heading_rad=self.heading_rad)

    def step(
        self, state: CentredState, t_s: float, pose: Pose2, dt_s: float
    ) -> tuple[ControlOutput, CentredState]:
        """One tick; see :func:`centred_step` (``t_s`` is not used)."""
        return centred_step(self, state, pose, dt_s)


def _start_phase(ctrl: CentredController, state: CentredState, pose: Pose2) -> CentredState:
    """The first phase for the current goal, with fresh loops."""
    gx, gy = ctrl.goals_m[state.index]
    heading = state.heading_rad
    if ctrl.mode == CentredMode.CENTRED_TURNING:
        phase, heading = "turn", math.atan2(gy - pose[1], gx - pose[0])
        heading = pose[2] + wrap_angle(heading - pose[2])
    elif ctrl.mode == CentredMode.DRIVING_FORWARD:
        phase = "x"
    else:
        phase = "drive"
    if heading is None:
        heading = pose[2]
    # the heading loop carries on while a held heading carries on, and starts afresh for a turn
    yaw = PidState() if phase == "turn" else state.yaw
    return CentredState(state.index, phase, heading, pose[1], yaw=yaw)


def _drive(
    ctrl: CentredController,
    state: CentredState,
    pose: Pose2,
    target: tuple[float, float],
    dt_s: float,
) -> tuple[tuple[float, float, float], CentredState]:
    """Body-axis PIDs towards ``target`` with the heading held."""
    ex_b, ey_b = rotate(-pose[2], target[0] - pose[0], target[1] - pose[1])
    vx, sx = pid_step(ctrl.position_pid, state.x, ex_b, 0.0, dt_s)
    vy, sy = pid_step(ctrl.position_pid, state.y, ey_b, 0.0, dt_s)
    heading = state.heading_rad if state.heading_rad is not None else pose[2]
    wz, syaw = pid_step(ctrl.heading_pid, state.yaw, 0.0, -wrap_angle(heading - pose[2]), dt_s)
    speed = math.hypot(vx, vy)
    if speed > ctrl.max_speed_mps:
        vx, vy = vx * ctrl.max_speed_mps / speed, vy * ctrl.max_speed_mps / speed
    new = CentredState(state.index, state.phase, state.heading_rad, state.hold_m, sx, sy, syaw)
    return (vx, vy, wz), new


def centred_step(
    ctrl: CentredController, state: CentredState, pose: Pose2, dt_s: float
) -> tuple[ControlOutput, CentredState]:
    """One tick of seed 003's position control.

    Args:
        ctrl: parameters and goals.
        state: state after the previous tick.
        pose: (x m, y m, yaw rad) of base_link in the path frame.
        dt_s: time since the previous tick.

    Returns:
        ``(output, new_state)``: the body twist, the goal index and the phase.
    """
    last = len(ctrl.goals_m) - 1
    if state.done:
        return ControlOutput((0.0, 0.0, 0.0), last, "done", done=True), state
    if state.phase == "":
        state = _start_phase(ctrl, state, pose)
    gx, gy = ctrl.goals_m[state.index]
    while math.hypot(gx - pose[0], gy - pose[1]) < ctrl.goal_tolerance_m:
        if state.index == last:
            done = CentredState(state.index, "done", state.heading_rad, done=True)
            return ControlOutput((0.0, 0.0, 0.0), state.index, "done", done=True), done
        keep = state.heading_rad if ctrl.mode != CentredMode.CENTRED_TURNING else None
        state = _start_phase(
            ctrl, CentredState(state.index + 1, heading_rad=keep, yaw=state.yaw), pose
        )
        gx, gy = ctrl.goals_m[state.index]
    if state.phase == "turn":
        heading = state.heading_rad if state.heading_rad is not None else pose[2]
        error = wrap_angle(heading - pose[2])
        if abs(error) >= ctrl.heading_tolerance_rad:
            wz, syaw = pid_step(ctrl.heading_pid, state.yaw, 0.0, -error, dt_s)
            new = CentredState(state.index, "turn", heading, state.hold_m, state.x, state.y, syaw)
            return ControlOutput((0.0, 0.0, wz), state.index, "turn"), new
        state = CentredState(state.index, "drive", heading, state.hold_m)  # fresh heading loop
    if state.phase == "x":
        if abs(gx - pose[0]) >= ctrl.axis_tolerance_m:
            twist, new = _drive(ctrl, state, pose, (gx, state.hold_m), dt_s)
            return ControlOutput(twist, state.index, "x"), new
        state = CentredState(state.index, "y", state.heading_rad, state.hold_m, yaw=state.yaw)
    twist, new = _drive(ctrl, state, pose, (gx, gy), dt_s)
    return ControlOutput(twist, state.index, state.phase), new


def task_controller(task: BuiltinTask) -> CentredController:
    """The seed 003 controller of a built-in task (:data:`omnical.experiment.library.BUILTIN_TASKS`).

    Raises:
        ConfigError: a task whose mode is not a seed 003 mode.
    """
    try:
        mode = CentredMode(task.mode)
    except ValueError as err:
        msg = f"task {task.name}: unknown mode {task.mode!r}; use one of {[m.value for m in CentredMode]}"
        raise ConfigError(msg) from err
    return CentredController(task.goals_m, mode=mode, name=task.name)
