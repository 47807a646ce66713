"""The Runner: executes a motion script on a :class:`Robot` against a :class:`Clock`, and logs it.

:func:`run_script` sends the script's twist at its command rate and logs ``/cmd_vel`` and step
markers (``/omnical/events``); Ctrl-C or a safety stop stops the robot and keeps the log.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from omnical.errors import RunStop, SafetyStopError
from omnical.experiment.ports import BatchClock, Clock, Robot
from omnical.experiment.script import CommandSource, ScheduledCommandSource

__all__ = ["RunLog", "run_script"]


@dataclass(frozen=True)
class RunLog:
    """What the runner itself recorded.

    Attributes:
        cmd_vel: (N, 4) t_s, vx_mps, vy_mps, wz_radps.
        events: list of (t_s, JSON text).
        interrupted: the run was stopped before the end of the script.
        interruption: what stopped it (a ``KeyboardInterrupt`` or a subclass such as the CLI's
            SIGTERM, or a :class:`~omnical.errors.SafetyStopError`), for the caller to re-raise once
            the recording is safe; None if it ran out.
    """

    cmd_vel: NDArray[np.float64]
    events: tuple[tuple[float, str], ...]
    interrupted: bool = False
    interruption: RunStop | None = None


def run_script(
    script: CommandSource,
    robot: Robot,
    clock: Clock,
    *,
    t0_s: float | None = None,
    on_tick: Callable[[float, float], None] | None = None,
    on_event: Callable[[float, str], None] | None = None,
) -> RunLog:
    """Execute ``script`` on ``robot``; returns the commands and step markers it sent.

    Args:
        script: compiled motion script, or any command source (e.g. a played-back
            feed-forward :class:`~omnical.experiment.script.TwistSequence`).
        robot: any Robot port (twin, serial, ROS).
        clock: the matching clock (simulated for the twin). A
            :class:`~omnical.experiment.ports.BatchClock` gets the commands a block of about one
            robot-second at a time; an interrupt then keeps the commands of the whole blocks run.
        t0_s: clock time at which the script starts (default: now).
        on_tick: progress callback ``(elapsed_s, total_s)``: after every tick, or after every
            block on a BatchClock.
        on_event: receives each step marker ``(t_s, JSON text)`` as it is logged (a live
            view), on a real-time clock only (a BatchClock's run is computed, not watched).
    """
    start = clock.now_s() if t0_s is None else t0_s
    dt = 1.0 / script.rate_hz
    duration_s = script.duration_s
    n_ticks = math.ceil(duration_s * script.rate_hz)
    t_rel = np.arange(n_ticks + 1, dtype=np.float64) * dt
    twists, indices = _schedule(script, t_rel)
    t_cmd = start + t_rel
    t_wake = t_cmd + dt
    n_steps = len(script.steps)
    events: list[tuple[float, str]] = []
    current = -1

    live = None if isinstance(clock, BatchClock) else on_event

    def log_event(t_s: float, text: str) -> None:
        events.append((t_s, text))
        if live is not None:
            live(t_s, text)

    def mark(k: int) -> None:
        nonlocal current
        index = int(indices[k])
        t_c = float(t_cmd[k])
        if 0 <= current < n_steps:
            log_event(t_c, _marker(script, current, "end"))
        if index < n_steps:
            log_event(t_c, _marker(script, index, "start"))
        current = index

    changes = [0, *(np.flatnonzero(indices[1:] != indices[:-1]) + 1).tolist()]
    sent = 0
    interrupted = False
    interruption: RunStop | None = None
    try:
        if isinstance(clock, BatchClock):
            # blocks of about one robot-second: one call each, progress once per block
            block = max(1, round(script.rate_hz))
            c = 0
            for a in range(0, n_ticks + 1, block):
                b = min(a + block, n_ticks + 1)
                while c < len(changes) and changes[c] < b:
                    mark(changes[c])
                    c += 1
                clock.run_commands(robot, twists[a:b], t_wake[a:b])
                sent = b
                if on_tick is not None:
                    on_tick(float(t_rel[b - 1]), duration_s)
        else:
            is_change = np.zeros(n_ticks + 1, dtype=np.bool_)
            is_change[changes] = True
            for k, (t_r, t_w, change, (vx, vy, wz)) in enumerate(
                zip(
                    t_rel.tolist(),
                    t_wake.tolist(),
                    is_change.tolist(),
                    twists.tolist(),
                    strict=True,
                )
            ):
                if change:
                    mark(k)
                robot.send_twist(vx, vy, wz)
                sent = k + 1
                if on_tick is not None:
                    on_tick(t_r, duration_s)
                clock.sleep_until(t_w)
    except (KeyboardInterrupt, SafetyStopError) as stop:
        interrupted, interruption = True, stop
    finally:
        robot.stop()
    t_end = clock.now_s()
    cmds = np.empty((sent + 1, 4), dtype=np.float64)
    cmds[:sent, 0] = t_cmd[:sent]
    cmds[:sent, 1:] = twists[:sent]
    cmds[sent] = (t_end, 0.0, 0.0, 0.0)
    if 0 <= current < n_steps:  # a stopped step says so (the monitor shows it as an abort)
        log_event(t_end, _marker(script, current, "aborted" if interrupted else "end"))
    return RunLog(cmds, tuple(events), interrupted, interruption)


def _schedule(
    script: CommandSource, t_rel: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """(N, 3) twists and (N,) step indices (``len(steps)`` where no step) at the tick times."""
    n_steps = len(script.steps)
    if isinstance(script, ScheduledCommandSource):
        twists = np.asarray(script.twists_at(t_rel), dtype=np.float64).reshape(-1, 3)
        index = np.asarray(script.step_index_at(t_rel), dtype=np.int64)
        return twists, np.where(index >= 0, index, n_steps)
    times = t_rel.tolist()
    twists = np.array([script.twist_at(t) for t in times], dtype=np.float64).reshape(-1, 3)
    indices = []
    for t in times:
        step = script.step_at(t)
        indices.append(step.index if step is not None else n_steps)
    return twists, np.array(indices, dtype=np.int64).reshape(-1)


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
