"""A simulated clock: sleeping advances the twin, so time runs as fast as the machine allows."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from omnical.experiment.ports import Robot
from omnical.twin.simulator import DigitalTwin

__all__ = ["TwinClock"]


class TwinClock:
    """The :class:`~omnical.experiment.ports.Clock` of a digital twin (a
    :class:`~omnical.experiment.ports.BatchClock`)."""

    def __init__(self, twin: DigitalTwin) -> None:
        self._twin = twin

    def now_s(self) -> float:
        """Simulated seconds."""
        return self._twin.t_s

    def sleep_until(self, t_s: float) -> None:
        """Advance the simulation to ``t_s``."""
        self._twin.advance_to(t_s)

    def run_commands(
        self, robot: Robot, twists: NDArray[np.float64], wake_s: NDArray[np.float64]
    ) -> None:
        """Send each twist and advance to its wake time; in one call when ``robot`` is the twin."""
        if robot is self._twin:
            self._twin.play(twists, wake_s)
            return
        for (vx, vy, wz), t in zip(
            np.asarray(twists).tolist(), np.asarray(wake_s).tolist(), strict=True
        ):
            robot.send_twist(vx, vy, wz)
            self.sleep_until(t)
