"""The Runner: executes a motion script on a :class:`Robot` against a :class:`Clock`, and logs it.

It sends the script's twist at the script's command rate, logs every command (``/cmd_vel``) and a
JSON marker at the start and end of every step (``/omnical/events``). The robot's own sensor
streams are recorded by whoever owns them (the twin logs its own, a bag recorder on hardware).
A keyboard interrupt stops the robot and keeps everything logged so far.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from omnical.experiment.ports import Clock, Robot
from omnical.experiment.script import CommandSource

__all__ = ["RunLog", "run_script"]


@dataclass(frozen=True)
class RunLog:
    """What the runner itself recorded.

    Attributes:
        cmd_vel: (N, 4) t_s, vx_mps, vy_mps, wz_radps.
        events: list of (t_s, JSON text).
        interrupted: the run was stopped before the end of the script.
    """

    cmd_vel: NDArray[np.float64]
    events: tuple[tuple[float, str], ...]
    interrupted: bool = False


def run_script(
    script: CommandSource,
    robot: Robot,
    clock: Clock,
    *,
    t0_s: float | None = None,
    on_tick: Callable[[float, float], None] | None = None,
) -> RunLog:
    """Execute ``script`` on ``robot``; returns the commands and step markers it sent.

    Args:
        script: compiled motion script, or any command source (e.g. a played-back
            feed-forward :class:`~omnical.experiment.script.TwistSequence`).
        robot: any Robot port (twin, serial, ROS).
        clock: the matching clock (simulated for the twin).
        t0_s: clock time at which the script starts (default: now).
        on_tick: progress callback ``(elapsed_s, total_s)``.
    """
    start = clock.now_s() if t0_s is None else t0_s
    dt = 1.0 / script.rate_hz
    n_ticks = math.ceil(script.duration_s * script.rate_hz)
    cmds: list[tuple[float, float, float, float]] = []
    events: list[tuple[float, str]] = []
    current = -1
    interrupted = False
    try:
        for k in range(n_ticks + 1):
            t_rel = k * dt
            step = script.step_at(t_rel)
            index = step.index if step is not None else len(script.steps)
            if index != current:
                if 0 <= current < len(script.steps):
                    events.append((start + t_rel, _marker(script, current, "end")))
                if step is not None:
                    events.append((start + t_rel, _marker(script, index, "start")))
                current = index
            vx, vy, wz = script.twist_at(t_rel)
            robot.send_twist(vx, vy, wz)
            cmds.append((start + t_rel, vx, vy, wz))
            if on_tick is not None:
                on_tick(t_rel, script.duration_s)
            clock.sleep_until(start + t_rel + dt)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        robot.stop()
    t_end = clock.now_s()
    cmds.append((t_end, 0.0, 0.0, 0.0))
    if 0 <= current < len(script.steps):
        events.append((t_end, _marker(script, current, "end")))
    return RunLog(np.array(cmds, dtype=np.float64), tuple(events), interrupted)


def _marker(script: CommandSource, index: int, edge: str) -> str:
    step = script.steps[index]
    payload = {
        "script": script.name,
        "step": index + 1,
        "kind": step.kind,
        "edge": edge,
        "marker": step.marker,
        "twist": list(step.twist),
    }
    return json.dumps(payload, separators=(",", ":"))
