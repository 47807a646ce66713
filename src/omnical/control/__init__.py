"""Control: PID (seed 003 form), Ziegler–Nichols, command limits, waypoint/centred/tracking controllers, the loop on any Robot."""

from omnical.control.centred import CentredController, CentredMode, CentredState, centred_step
from omnical.control.limits import (
    DEFAULT_COMMAND_LIMITS,
    CommandLimits,
    limit_acceleration,
    limit_command,
    saturate_twist,
)
from omnical.control.loop import (
    Controller,
    ControlLog,
    ControlOutput,
    PoseSource,
    run_controller,
)
from omnical.control.pid import (
    SEED003_MOTOR_PID,
    AntiWindup,
    PidBatchState,
    PidParams,
    PidState,
    pid_batch_state,
    pid_step,
    pid_step_batch,
)
from omnical.control.tracking import TrackingController, TrackingState, tracking_step
from omnical.control.waypoint import (
    WaypointController,
    WaypointState,
    seed001_circle_waypoints,
    waypoint_step,
)
from omnical.control.ziegler_nichols import (
    Oscillation,
    UltimatePoint,
    ZnRule,
    analyse_oscillation,
    find_ultimate_gain,
    ziegler_nichols_gains,
)

__all__ = [
    "DEFAULT_COMMAND_LIMITS",
    "SEED003_MOTOR_PID",
    "AntiWindup",
    "CentredController",
    "CentredMode",
    "CentredState",
    "CommandLimits",
    "ControlLog",
    "ControlOutput",
    "Controller",
    "Oscillation",
    "PidBatchState",
    "PidParams",
    "PidState",
    "PoseSource",
    "TrackingController",
    "TrackingState",
    "UltimatePoint",
    "WaypointController",
    "WaypointState",
    "ZnRule",
    "analyse_oscillation",
    "centred_step",
    "find_ultimate_gain",
    "limit_acceleration",
    "limit_command",
    "pid_batch_state",
    "pid_step",
    "pid_step_batch",
    "run_controller",
    "saturate_twist",
    "seed001_circle_waypoints",
    "tracking_step",
    "waypoint_step",
    "ziegler_nichols_gains",
]
