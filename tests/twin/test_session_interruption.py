"""Ctrl-C / SIGTERM during a twin run: ``simulate_run`` raises it again (the demo, a campaign
and ``omnical run`` stop), or hands back the run so far when asked (``omnical simulate``)."""

from __future__ import annotations

import pytest

from omnical.experiment.script import load_script
from omnical.robot.loader import load_robot
from omnical.twin.params import default_twin
from omnical.twin.session import simulate_run


class _Stop(KeyboardInterrupt):
    """Stands for the CLI's Terminated (a KeyboardInterrupt subclass)."""


def _stop_after(robot_s: float) -> object:
    def tick(t_s: float, duration_s: float) -> None:
        if t_s >= robot_s:
            raise _Stop

    return tick


def test_an_interruption_during_the_script_is_raised_again() -> None:
    robot = load_robot("rosy-mecanum")
    script = load_script("straight-10m", robot.limits)
    with pytest.raises(_Stop):
        simulate_run(script, robot, default_twin(robot), on_tick=_stop_after(2.0))  # type: ignore[arg-type]


def test_the_run_so_far_is_kept_when_asked() -> None:
    robot = load_robot("rosy-mecanum")
    script = load_script("straight-10m", robot.limits)
    whole = simulate_run(script, robot, default_twin(robot))
    part = simulate_run(
        script,
        robot,
        default_twin(robot),
        on_tick=_stop_after(2.0),  # type: ignore[arg-type]
        keep_interrupted=True,
    )
    assert 2.0 < part.duration_s < whole.duration_s - 10.0
    assert part.topic("/cmd_vel")["vx_mps"][-1] == 0.0  # the robot was stopped
