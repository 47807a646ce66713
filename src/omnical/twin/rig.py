"""The digital twin as a rig (:class:`~omnical.control.rig_loop.ControlRig`): each session a
fresh twin in simulated time from its start pose, recording at its end the commands and events
with the twin's odometry, IMU, ground truth and simulated IPS (:func:`.record.twin_recording`).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np
from numpy.typing import NDArray

from omnical.errors import ConfigError
from omnical.estimation.se2 import Pose2, between, compose_poses
from omnical.experiment.ports import RobotState
from omnical.experiment.rig import RowSink
from omnical.ips.beacons import BeaconMap
from omnical.recording.topics import CMD_VEL, EVENTS
from omnical.robot.description import RobotDescription
from omnical.twin.clock import TwinClock
from omnical.twin.lidar import Lidar, LidarParams
from omnical.twin.online_ips import OnlineIpsParams, TwinIpsSource
from omnical.twin.params import TwinParams
from omnical.twin.record import EPOCH_NS, lidar_params
from omnical.twin.simulator import DigitalTwin

if TYPE_CHECKING:
    from omnical.control.loop import PoseSource
    from omnical.estimation.seed003_estimator import Seed003PoseSource
    from omnical.kinematics.correction import CorrectionFactors
    from omnical.twin.world import World

__all__ = ["TwinRig", "TwinSession"]


@dataclass(frozen=True)
class TwinRig:
    """The twin of ``robot`` with ``params`` (its truth), seeded with ``seed``.

    Attributes:
        robot: the robot description.
        params: the twin; a session replaces its installed factors when given some.
        seed: seed of the twin's noise and of the simulated IPS.
        beacons: beacon map of the simulated IPS (default: seed 000 Table 3).
        world: a floor plan: the recording holds the LiDAR's ``/scan``.
        ips: the online fixes a fused loop closes on (None: from ``params.ips``).
        lidar: the LiDAR scanning ``world`` (None: the robot's, :func:`.record.lidar_params`).
        stop_on_collision: the footprint touching ``world`` (true pose) is the rig's alarm.
        record_sensors: record the twin's topics at a session's end (else commands and events).
    """

    robot: RobotDescription
    params: TwinParams
    seed: int = 0
    beacons: BeaconMap | None = None
    world: World | None = None
    ips: OnlineIpsParams | None = None
    lidar: LidarParams | None = None
    stop_on_collision: bool = False
    record_sensors: bool = True
    sources: ClassVar[frozenset[str]] = frozenset({"odometry", "fused", "ground_truth", "seed003"})

    @contextmanager
    def session(
        self,
        sink: RowSink,
        *,
        installed: CorrectionFactors | None = None,
        require_positions: bool = False,
    ) -> Iterator[TwinSession]:
        """A fresh twin (the simulated IPS never falls silent: ``require_positions`` holds)."""
        params = self.params if installed is None else self.params.with_installed(installed)
        yield TwinSession(self, params, sink)


class TwinSession:
    """One run of a :class:`TwinRig`."""

    def __init__(self, rig: TwinRig, params: TwinParams, sink: RowSink) -> None:
        self._rig, self._params, self._sink = rig, params, sink
        self.twin = DigitalTwin(rig.robot, params, seed=rig.seed)
        self._clock = TwinClock(self.twin)
        start = params.start_pose_map
        self.start_pose_map: Pose2 = (float(start[0]), float(start[1]), float(start[2]))
        self._fixes: TwinIpsSource | None = None
        self._seed003: Seed003PoseSource | None = None
        self._lidar: Lidar | None = None
        self.origin_ns = EPOCH_NS

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

    def fixes(self) -> TwinIpsSource:
        """Online IPS fixes from the twin's true pose (:class:`TwinIpsSource`)."""
        if self._fixes is None:
            ips = self._rig.ips or OnlineIpsParams.from_ips_params(self._params.ips)
            self._fixes = TwinIpsSource(self.twin, ips, seed=self._rig.seed)
        return self._fixes

    def own_pose_source(self, choice: str) -> PoseSource:
        """The true pose, or seed 003's estimate from now on; path frame = the start pose."""
        if choice == "ground_truth":
            twin, start = self.twin, self.start_pose_map

            def truth(_: RobotState) -> Pose2:
                return between(start, twin.ground_truth_pose)

            return truth
        if choice == "seed003":
            from omnical.estimation.seed003_estimator import Seed003Estimator, Seed003PoseSource
            from omnical.twin.seed003_sensors import TwinSeed003Samples

            samples = TwinSeed003Samples(self.twin, since_s=self.twin.t_s)
            self._seed003 = Seed003PoseSource(
                Seed003Estimator(self._rig.robot.dead_wheels), samples
            )
            return self._seed003
        msg = f"the twin has no pose source {choice!r}"
        raise ConfigError(msg)

    def lidar_params(self) -> LidarParams:
        """The twin's LiDAR (ConfigError: no world to scan)."""
        if self._rig.world is None:
            msg = "the twin has no floor plan to scan: give it a world"
            raise ConfigError(msg)
        return lidar_params(self._rig.robot, self._rig.lidar)

    def scan_now(self) -> NDArray[np.float64]:
        """The LiDAR's ranges at the true pose now, m."""
        if self._lidar is None:
            assert self._rig.world is not None
            self._lidar = Lidar(self._rig.world.grid, self.lidar_params(), self._rig.seed)
        return self._lidar.scan(np.asarray(self.twin.ground_truth_pose))

    def alarm(self) -> str:
        """A collision of the footprint with the floor plan (``stop_on_collision``), else ""."""
        world = self._rig.world
        if not self._rig.stop_on_collision or world is None:
            return ""
        return world.collision_message(self.twin.ground_truth_pose)

    def ground_truth(self) -> NDArray[np.float64]:
        """(N, 4) t_s, x, y, yaw of the true pose in the map."""
        log = self.twin.log()
        return np.column_stack([log.ground_truth_t_s, log.ground_truth_pose])

    def estimates(self) -> NDArray[np.float64] | None:
        """Seed 003's estimate in the map, if it closed a loop."""
        if self._seed003 is None:
            return None
        est = self._seed003.estimates()
        return np.column_stack(
            [est[:, 0], compose_poses(np.asarray(self.start_pose_map), est[:, 1:])]
        )

    def finish(self, cmd_vel: NDArray[np.float64], events: Sequence[tuple[float, str]]) -> None:
        from omnical.twin.record import stamp_ns, twin_recording

        sink, rig = self._sink, self._rig
        sink.write_rows(
            CMD_VEL,
            stamp_ns(cmd_vel[:, 0]),
            vx_mps=cmd_vel[:, 1],
            vy_mps=cmd_vel[:, 2],
            wz_radps=cmd_vel[:, 3],
        )
        if events:
            sink.write_rows(
                EVENTS,
                stamp_ns(np.array([t for t, _ in events])),
                text=np.array([e for _, e in events], dtype=object),
            )
        log = self.twin.log()
        if (
            len(log.ground_truth_t_s) < 2 or not rig.record_sensors
        ):  # stopped before the twin ran: nothing it sensed
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
