"""Control: a discrete PID (seed 003 form), Ziegler–Nichols tuning and the plants it is tried on."""

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
from omnical.control.plants import (
    DiscretePlant,
    SpeedTrackingTable,
    discretize_plant,
    motor_speed_plant,
    simulate_p_loop,
    simulate_pid_loop,
    speed_tracking_table,
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
    "SEED003_MOTOR_PID",
    "AntiWindup",
    "DiscretePlant",
    "Oscillation",
    "PidBatchState",
    "PidParams",
    "PidState",
    "SpeedTrackingTable",
    "UltimatePoint",
    "ZnRule",
    "analyse_oscillation",
    "discretize_plant",
    "find_ultimate_gain",
    "motor_speed_plant",
    "pid_batch_state",
    "pid_step",
    "pid_step_batch",
    "simulate_p_loop",
    "simulate_pid_loop",
    "speed_tracking_table",
    "ziegler_nichols_gains",
]
