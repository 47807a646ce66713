"""The way-point controller of seed 001 §4.2: two PID loops, azimuth first, then drive.

Turns in place while the bearing error is large (with hysteresis), else drives with the speed cut
as the heading realigns; the defaults (not in the paper) are on :class:`WaypointController`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from omnical.control.loop import ControlOutput
from omnical.control.pid import PidParams, PidState, pid_step
from omnical.errors import ConfigError
from omnical.estimation.se2 import Pose2, wrap_angle

__all__ = [
    "SEED001_AZIMUTH_PID",
    "SEED001_DISTANCE_PID",
    "SEED001_MAX_SPEED_MPS",
    "WaypointController",
    "WaypointState",
    "seed001_circle_waypoints",
    "waypoint_step",
]

#: Seed 001 §4.2.1: "the maximum 0.1 m s⁻¹ allowed by the controller".
SEED001_MAX_SPEED_MPS = 0.1
#: Azimuth loop (chosen): P = 1.2 (rad/s)/rad with a slow integral, yaw rate within ±0.5 rad/s.
SEED001_AZIMUTH_PID = PidParams(kp=1.2, ti_s=10.0, output_min=-0.5, output_max=0.5)
#: Distance loop (chosen): P = 0.5 (m/s)/m, forward only, saturated at 0.1 m/s.
SEED001_DISTANCE_PID = PidParams(kp=0.5, output_min=0.0, output_max=SEED001_MAX_SPEED_MPS)


def _point(i: int, p: Sequence[float]) -> tuple[float, float]:
    if len(p) != 2 or not all(math.isfinite(v) for v in p):
        msg = f"way-point {i}: expected finite (x, y), got {tuple(p)}"
        raise ConfigError(msg)
    return (float(p[0]), float(p[1]))


@dataclass(frozen=True)
class WaypointState:
    """What the way-point controller remembers between ticks.

    Attributes:
        index: way-point being approached.
        turning: in the azimuth (turn in place) phase.
        azimuth: state of the azimuth PID.
        distance: state of the distance PID.
        done: the last way-point was reached.
    """

    index: int = 0
    turning: bool = False
    azimuth: PidState = field(default_factory=PidState)
    distance: PidState = field(default_factory=PidState)
    done: bool = False


@dataclass(frozen=True)
class WaypointController:
    """Seed 001's way-point controller (frozen parameters; state in :class:`WaypointState`).

    Attributes:
        waypoints_m: (x, y) targets in the path frame, in order (the start point excluded).
        azimuth_pid: azimuth loop, output yaw rate rad/s.
        distance_pid: distance loop, output linear speed m/s (clip it to ≥ 0).
        max_speed_mps: saturation of the linear speed (seed 001: 0.1 m/s).
        turn_enter_rad: heading error above which the linear speed is switched to zero (20°).
        turn_exit_rad: heading error below which the drive phase starts again (3°).
        vicinity_m: distance at which the selector moves on to the next way-point.
        final_tolerance_m: distance at which the last way-point counts as reached.
        name: label for logs.

    Raises:
        ConfigError: on construction, for no way-points, a bad point, or thresholds that are
            not 0 < exit < enter ≤ π and tolerances > 0.
    """

    waypoints_m: tuple[tuple[float, float], ...]
    azimuth_pid: PidParams = SEED001_AZIMUTH_PID
    distance_pid: PidParams = SEED001_DISTANCE_PID
    max_speed_mps: float = SEED001_MAX_SPEED_MPS
    turn_enter_rad: float = math.radians(20.0)
    turn_exit_rad: float = math.radians(3.0)
    vicinity_m: float = 0.05
    final_tolerance_m: float = 0.01
    name: str = "seed001-waypoint"

    def __post_init__(self) -> None:
        points = tuple(_point(i, p) for i, p in enumerate(self.waypoints_m))
        if not points:
            msg = "the way-point controller needs at least one way-point"
            raise ConfigError(msg)
        object.__setattr__(self, "waypoints_m", points)
        if not 0.0 < self.turn_exit_rad < self.turn_enter_rad <= math.pi:
            msg = (
                f"need 0 < turn_exit_rad < turn_enter_rad <= pi, got "
                f"{self.turn_exit_rad}, {self.turn_enter_rad}"
            )
            raise ConfigError(msg)
        for name in ("max_speed_mps", "vicinity_m", "final_tolerance_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                msg = f"{name} must be finite and > 0, got {value}"
                raise ConfigError(msg)

    def initial_state(self) -> WaypointState:
        """State before the first tick."""
        return WaypointState()

    def step(
        self, state: WaypointState, t_s: float, pose: Pose2, dt_s: float
    ) -> tuple[ControlOutput, WaypointState]:
        """One tick; see :func:`waypoint_step` (``t_s`` is not used)."""
        return waypoint_step(self, state, pose, dt_s)


def waypoint_step(
    ctrl: WaypointController, state: WaypointState, pose: Pose2, dt_s: float
) -> tuple[ControlOutput, WaypointState]:
    """One tick of seed 001's way-point controller.

    Args:
        ctrl: parameters and way-points.
        state: state after the previous tick.
        pose: (x m, y m, yaw rad) of base_link in the path frame.
        dt_s: time since the previous tick.

    Returns:
        ``(output, new_state)``: a (v, 0, wz) body twist, the way-point index and the phase
        ("turn", "drive" or "done").
    """
    last = len(ctrl.waypoints_m) - 1
    if state.done:
        return ControlOutput((0.0, 0.0, 0.0), last, "done", done=True), state
    index = state.index
    az_state, d_state, turning = state.azimuth, state.distance, state.turning
    while True:
        gx, gy = ctrl.waypoints_m[index]
        dx, dy = gx - pose[0], gy - pose[1]
        dist = math.hypot(dx, dy)
        tolerance = ctrl.final_tolerance_m if index == last else ctrl.vicinity_m
        if dist >= tolerance:
            break
        if index == last:
            done = WaypointState(index, False, PidState(), PidState(), True)
            return ControlOutput((0.0, 0.0, 0.0), index, "done", done=True), done
        index += 1  # way-point selector: next target, fresh loops
        az_state, d_state, turning = PidState(), PidState(), False
    error = wrap_angle(math.atan2(dy, dx) - pose[2])
    if turning and abs(error) < ctrl.turn_exit_rad:
        turning = False
    elif not turning and abs(error) > ctrl.turn_enter_rad:
        turning = True
        d_state = PidState()
    wz, az_state = pid_step(ctrl.azimuth_pid, az_state, 0.0, -error, dt_s)
    if turning:
        v = 0.0
    else:
        v_pid, d_state = pid_step(ctrl.distance_pid, d_state, 0.0, -dist, dt_s)
        taper = max(0.0, 1.0 - abs(error) / ctrl.turn_enter_rad)
        v = min(max(v_pid, 0.0), ctrl.max_speed_mps) * taper
    new_state = WaypointState(index, turning, az_state, d_state, False)
    return ControlOutput((v, 0.0, wz), index, "turn" if turning else "drive"), new_state


def seed001_circle_waypoints(
    *,
    radius_m: float = 1.0,
    count: int = 24,
    center_m: tuple[float, float] = (0.0, 0.0),
    start_angle_rad: float = 0.0,
) -> tuple[tuple[float, float], ...]:
    """Seed 001 §4.2.1: from the centre straight to the periphery, then around counter-clockwise.

    Args:
        radius_m: circle radius (1 m in the paper).
        count: way-points per turn.
        center_m: circle centre in the path frame (the robot starts there).
        start_angle_rad: polar angle of the first periphery point.

    Returns:
        ``count + 1`` points around the circle, from the first periphery point back to it.

    Raises:
        ConfigError: a non-positive radius or fewer than 3 points.
    """
    if not (math.isfinite(radius_m) and radius_m > 0.0):
        msg = f"circle radius must be finite and > 0, got {radius_m}"
        raise ConfigError(msg)
    if count < 3:
        msg = f"a circle needs at least 3 way-points, got {count}"
        raise ConfigError(msg)
    cx, cy = center_m
    return tuple(
        (
            cx + radius_m * math.cos(start_angle_rad + 2.0 * math.pi * k / count),
            cy + radius_m * math.sin(start_angle_rad + 2.0 * math.pi * k / count),
        )
        for k in range(count + 1)
    )
