"""A simulated clock: sleeping advances the twin, so time runs as fast as the machine allows."""

from __future__ import annotations

from omnical.twin.simulator import DigitalTwin

__all__ = ["TwinClock"]


class TwinClock:
    """The :class:`~omnical.experiment.ports.Clock` of a digital twin."""

    def __init__(self, twin: DigitalTwin) -> None:
        self._twin = twin

    def now_s(self) -> float:
        """Simulated seconds."""
        return self._twin.t_s

    def sleep_until(self, t_s: float) -> None:
        """Advance the simulation to ``t_s``."""
        self._twin.advance_to(t_s)
