"""Holonomic trajectory tracking: reference feed-forward plus PID on the map-frame pose error.

The :class:`~omnical.trajectory.references.Reference` twist carries the motion, PIDs on x, y and
yaw remove the error; the final pose is held for ``settle_s`` after the reference ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from omnical.control.loop import ControlOutput
from omnical.control.pid import PidParams, PidState, pid_step
from omnical.errors import ConfigError
from omnical.estimation.se2 import Pose2, rotate, wrap_angle
from omnical.trajectory.references import Reference

__all__ = [
    "TRACKING_POSITION_PID",
    "TRACKING_YAW_PID",
    "TrackingController",
    "TrackingState",
    "tracking_step",
]


#: Position correction (chosen): PI, 2 (m/s)/m, Ti = 4 s, within ±0.1 m/s on top of the feed-forward.
TRACKING_POSITION_PID = PidParams(kp=2.0, ti_s=4.0, output_min=-0.1, output_max=0.1)
#: Yaw correction (chosen): PI, 2 (rad/s)/rad, Ti = 4 s, within ±0.5 rad/s.
TRACKING_YAW_PID = PidParams(kp=2.0, ti_s=4.0, output_min=-0.5, output_max=0.5)


@dataclass(frozen=True)
class TrackingState:
    """States of the x, y (map frame) and yaw PIDs."""

    x: PidState = field(default_factory=PidState)
    y: PidState = field(default_factory=PidState)
    yaw: PidState = field(default_factory=PidState)


@dataclass(frozen=True, eq=False)
class TrackingController:
    """Feed-forward + PID tracking of a reference (path frame = the reference's ``map``).

    Attributes:
        reference: the time-parameterised reference; controller time 0 is its start.
        position_pid: PID of x and of y, map-frame error (m) → velocity correction (m/s).
        yaw_pid: PID of the yaw, error (rad) → yaw-rate correction (rad/s).
        settle_s: regulation to the final pose after the reference ends, s.
        name: label for logs.

    Raises:
        ConfigError: on construction, for a negative or non-finite settle time.
    """

    reference: Reference
    position_pid: PidParams = TRACKING_POSITION_PID
    yaw_pid: PidParams = TRACKING_YAW_PID
    settle_s: float = 2.0
    name: str = "tracking"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.settle_s) and self.settle_s >= 0.0):
            msg = f"settle_s must be finite and >= 0, got {self.settle_s}"
            raise ConfigError(msg)

    def initial_state(self) -> TrackingState:
        """State before the first tick."""
        return TrackingState()

    def step(
        self, state: TrackingState, t_s: float, pose: Pose2, dt_s: float
    ) -> tuple[ControlOutput, TrackingState]:
        """One tick; see :func:`tracking_step`."""
        return tracking_step(self, state, t_s, pose, dt_s)


def tracking_step(
    ctrl: TrackingController, state: TrackingState, t_s: float, pose: Pose2, dt_s: float
) -> tuple[ControlOutput, TrackingState]:
    """One tick of the holonomic tracking controller.

    Args:
        ctrl: the reference and gains.
        state: state after the previous tick.
        t_s: controller time since the start of the reference.
        pose: (x m, y m, yaw rad) of base_link in the path frame.
        dt_s: time since the previous tick.

    Returns:
        ``(output, new_state)``: the body twist ("track", then "settle"; done after the settle
        time), target index −1.
    """
    if t_s > ctrl.reference.duration_s + ctrl.settle_s:
        return ControlOutput((0.0, 0.0, 0.0), -1, "done", done=True), state
    poses, twists = ctrl.reference.at(t_s)
    xr, yr, yaw_r = (float(v) for v in poses[0])
    vxr, vyr, wzr = (float(v) for v in twists[0])
    ff_x, ff_y = rotate(yaw_r, vxr, vyr)
    ux, sx = pid_step(ctrl.position_pid, state.x, xr, pose[0], dt_s)
    uy, sy = pid_step(ctrl.position_pid, state.y, yr, pose[1], dt_s)
    uw, sw = pid_step(ctrl.yaw_pid, state.yaw, 0.0, -wrap_angle(yaw_r - pose[2]), dt_s)
    vx, vy = rotate(-pose[2], ff_x + ux, ff_y + uy)
    mode = "track" if t_s <= ctrl.reference.duration_s else "settle"
    return ControlOutput((vx, vy, wzr + uw), -1, mode), TrackingState(sx, sy, sw)
