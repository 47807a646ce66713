"""Experiments: the Robot/Clock ports, motion scripts and the Runner."""

from omnical.experiment.ports import Clock, Robot, RobotState, WallClock
from omnical.experiment.runner import RunLog, run_script
from omnical.experiment.script import MotionScript, Step, load_script, parse_script

__all__ = [
    "Clock",
    "MotionScript",
    "Robot",
    "RobotState",
    "RunLog",
    "Step",
    "WallClock",
    "load_script",
    "parse_script",
    "run_script",
]
