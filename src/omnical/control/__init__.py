"""Control: PID (seed 003 form), Ziegler–Nichols, command limits, controllers, the loop on any Robot."""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
    from omnical.control.centred import (
        CentredController,
        CentredMode,
        CentredState,
        centred_step,
        task_controller,
    )
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
    from omnical.control.tracking import (
        TrackingController,
        TrackingState,
        tracking_step,
    )
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

_EXPORTS: dict[str, str] = {
    "AntiWindup": "omnical.control.pid",
    "CentredController": "omnical.control.centred",
    "CentredMode": "omnical.control.centred",
    "CentredState": "omnical.control.centred",
    "CommandLimits": "omnical.control.limits",
    "ControlLog": "omnical.control.loop",
    "ControlOutput": "omnical.control.loop",
    "Controller": "omnical.control.loop",
    "DEFAULT_COMMAND_LIMITS": "omnical.control.limits",
    "Oscillation": "omnical.control.ziegler_nichols",
    "PidBatchState": "omnical.control.pid",
    "PidParams": "omnical.control.pid",
    "PidState": "omnical.control.pid",
    "PoseSource": "omnical.control.loop",
    "SEED003_MOTOR_PID": "omnical.control.pid",
    "TrackingController": "omnical.control.tracking",
    "TrackingState": "omnical.control.tracking",
    "UltimatePoint": "omnical.control.ziegler_nichols",
    "WaypointController": "omnical.control.waypoint",
    "WaypointState": "omnical.control.waypoint",
    "ZnRule": "omnical.control.ziegler_nichols",
    "analyse_oscillation": "omnical.control.ziegler_nichols",
    "centred_step": "omnical.control.centred",
    "task_controller": "omnical.control.centred",
    "find_ultimate_gain": "omnical.control.ziegler_nichols",
    "limit_acceleration": "omnical.control.limits",
    "limit_command": "omnical.control.limits",
    "pid_batch_state": "omnical.control.pid",
    "pid_step": "omnical.control.pid",
    "pid_step_batch": "omnical.control.pid",
    "run_controller": "omnical.control.loop",
    "saturate_twist": "omnical.control.limits",
    "seed001_circle_waypoints": "omnical.control.waypoint",
    "tracking_step": "omnical.control.tracking",
    "waypoint_step": "omnical.control.waypoint",
    "ziegler_nichols_gains": "omnical.control.ziegler_nichols",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

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
    "task_controller",
    "tracking_step",
    "waypoint_step",
    "ziegler_nichols_gains",
]


__getattr__ = lazy_getattr(__name__, _EXPORTS)
