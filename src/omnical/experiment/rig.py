"""Where an experiment runs: a robot, its clock and the recording of its sensors, as one port.

Experiments are written once against :class:`Rig` (:func:`run_script_on` runs a script); the
twin's :class:`~omnical.twin.rig.TwinRig` and :class:`~omnical.services.hil.SerialRig` implement it.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import replace
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import SafetyStopError
from omnical.experiment.ports import Clock, Robot
from omnical.experiment.runner import RunLog, run_script
from omnical.experiment.script import CommandSource

if TYPE_CHECKING:
    from omnical.kinematics.correction import CorrectionFactors

__all__ = ["LEAD_IN_S", "TAIL_S", "Rig", "RigSession", "RowSink", "run_script_on"]

LEAD_IN_S = 1.0
"""The robot stands still this long before a script starts (robot time)."""
TAIL_S = 1.0
"""... and this long after it ends."""


class RowSink(Protocol):
    """Where a run's rows go: a :class:`~omnical.recording.recording.RecordingBuilder` (in
    memory) or a :class:`~omnical.bags.recorder.BagRecorder` (flushed to disk as it goes)."""

    def write_rows(self, topic: str, t_ns: ArrayLike, **columns: ArrayLike) -> None:
        """Append rows to ``topic``: ``t_ns`` (N,) bag times, each column (N, ...)."""
        ...


class RigSession(Protocol):
    """One run on a rig: the robot and clock to drive, and the recording of what it senses."""

    @property
    def robot(self) -> Robot:
        """The robot to command (the installed factors compensating, if any)."""
        ...

    @property
    def clock(self) -> Clock:
        """Robot time of this run, s."""
        ...

    def hold(self, duration_s: float) -> None:
        """Stand still for ``duration_s`` of robot time."""
        ...

    def poll(self) -> None:
        """Record what the rig's devices sent since the last call (between commands)."""
        ...

    def finish(self, cmd_vel: NDArray[np.float64], events: Sequence[tuple[float, str]]) -> None:
        """Record the run's commands ((N, 4) t_s, vx, vy, wz) and events (t_s, JSON), clock
        times, with everything the rig's sensors recorded."""
        ...


class Rig(Protocol):
    """A robot experiments run on: the twin, a robot over serial ports, a ROS 2 robot."""

    def session(
        self,
        sink: RowSink,
        *,
        installed: CorrectionFactors | None = None,
        require_positions: bool = False,
    ) -> AbstractContextManager[RigSession]:
        """A run recorded into ``sink``, with ``installed`` compensating (the twin's vehicle
        controller, or the host for stock firmware); ``require_positions``: the experiment needs
        the positioning system (a rig that loses it stops the robot). Leaving it, on any
        exception too, stops the robot."""
        ...


def run_script_on(
    rig: Rig,
    script: CommandSource,
    sink: RowSink,
    *,
    installed: CorrectionFactors | None = None,
    record_installed: bool = False,
    require_positions: bool = False,
    lead_in_s: float = LEAD_IN_S,
    tail_s: float = TAIL_S,
    on_tick: Callable[[float, float], None] | None = None,
) -> RunLog:
    """Run ``script`` on ``rig`` and record it into ``sink``.

    The robot stands still ``lead_in_s`` before and ``tail_s`` after the script. An interrupt
    or a safety stop during the script stops the robot and is in the log
    (``log.interruption``, for the caller to re-raise once the recording is safe); the rows so
    far are recorded. ``record_installed`` adds an ``installed_factors`` event at the start.
    """

    with rig.session(sink, installed=installed, require_positions=require_positions) as run:

        def tick(elapsed_s: float, total_s: float) -> None:
            run.poll()
            if on_tick is not None:
                on_tick(elapsed_s, total_s)

        try:  # a stop at rest too ends the run with what was recorded
            run.hold(lead_in_s)
        except (KeyboardInterrupt, SafetyStopError) as stop:
            log = RunLog(np.zeros((0, 4)), (), interrupted=True, interruption=stop)
        else:
            # a live sink (the monitor's tee) gets the step markers now, the recording at the end
            on_event = getattr(sink, "live_event", None)
            log = run_script(script, run.robot, run.clock, on_tick=tick, on_event=on_event)
            if not log.interrupted:
                try:
                    run.hold(tail_s)
                except (KeyboardInterrupt, SafetyStopError) as stop:
                    log = replace(log, interrupted=True, interruption=stop)
        events = list(log.events)
        if record_installed and installed is not None:
            text = json.dumps({"omnical": "installed_factors", "factors": installed.as_dict()})
            events.insert(0, (0.0, text))  # the run's start
        run.finish(log.cmd_vel, events)
    return log
