"""The digital twin as a :class:`~omnical.experiment.rig.Rig`: every session a fresh twin.

A session runs in simulated time from the twin's start pose with the installed factors in its
vehicle controller, and records, when it finishes, the commands and events with the twin's
odometry, IMU, ground truth and simulated IPS (:func:`~omnical.twin.record.twin_recording`).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from omnical.experiment.rig import RowSink
from omnical.ips.beacons import BeaconMap
from omnical.robot.description import RobotDescription
from omnical.twin.clock import TwinClock
from omnical.twin.params import TwinParams
from omnical.twin.simulator import DigitalTwin

if TYPE_CHECKING:
    from omnical.kinematics.correction import CorrectionFactors
    from omnical.twin.world import World

__all__ = ["TwinRig"]


@dataclass(frozen=True)
class TwinRig:
    """The twin of ``robot`` with ``params`` (its truth), seeded with ``seed``.

    Attributes:
        robot: the robot description.
        params: the twin; a session replaces its installed factors when given some.
        seed: seed of the twin's noise and of the simulated IPS.
        beacons: beacon map of the simulated IPS (default: seed 000 Table 3).
        world: a floor plan: the recording holds the LiDAR's ``/scan``.
    """

    robot: RobotDescription
    params: TwinParams
    seed: int = 0
    beacons: BeaconMap | None = None
    world: World | None = None

    @contextmanager
    def session(
        self,
        sink: RowSink,
        *,
        installed: CorrectionFactors | None = None,
        require_positions: bool = False,
    ) -> Iterator[_TwinSession]:
        """A fresh twin (the simulated IPS never falls silent: ``require_positions`` holds)."""
        params = self.params if installed is None else self.params.with_installed(installed)
        yield _TwinSession(self, params, sink)


class _TwinSession:
    """One run of a :class:`TwinRig`."""

    def __init__(self, rig: TwinRig, params: TwinParams, sink: RowSink) -> None:
        self._rig, self._params, self._sink = rig, params, sink
        self.twin = DigitalTwin(rig.robot, params, seed=rig.seed)
        self._clock = TwinClock(self.twin)

    @property
    def robot(self) -> DigitalTwin:
        return self.twin

    @property
    def clock(self) -> TwinClock:
        return self._clock

    def hold(self, duration_s: float) -> None:
        self.twin.advance_to(self.twin.t_s + duration_s)

    def poll(self) -> None:
        """Nothing to do: the twin logs as it goes."""

    def finish(self, cmd_vel: NDArray[np.float64], events: Sequence[tuple[float, str]]) -> None:
        from omnical.twin.record import stamp_ns, twin_recording

        sink, rig = self._sink, self._rig
        sink.write_rows(
            "/cmd_vel",
            stamp_ns(cmd_vel[:, 0]),
            vx_mps=cmd_vel[:, 1],
            vy_mps=cmd_vel[:, 2],
            wz_radps=cmd_vel[:, 3],
        )
        if events:
            sink.write_rows(
                "/omnical/events",
                stamp_ns(np.array([t for t, _ in events])),
                text=np.array([e for _, e in events], dtype=object),
            )
        log = self.twin.log()
        if len(log.ground_truth_t_s) < 2:  # stopped before the twin ran: nothing it sensed
            return
        twin_recording(
            sink,
            log,
            rig.robot,
            self._params,
            seed=rig.seed,
            beacons=rig.beacons,
            world=rig.world,
        )
