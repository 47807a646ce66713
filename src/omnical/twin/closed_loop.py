"""Closed-loop runs on the digital twin, recorded like a real run.

:func:`closed_loop_run` runs a controller on a fresh twin, closed on wheel odometry, the fused
IPS + odometry estimate or the true pose, and assembles one recording of the run.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from omnical.control.limits import DEFAULT_COMMAND_LIMITS, CommandLimits
from omnical.control.loop import Controller, ControlLog
from omnical.control.rig_loop import PoseChoice, RigControlRun, run_controller_on
from omnical.errors import ConfigError
from omnical.estimation.fusion import FusionParams
from omnical.estimation.se2 import Pose2, between_poses
from omnical.ips.beacons import BeaconMap
from omnical.recording.recording import Recording, RecordingBuilder
from omnical.robot.description import RobotDescription
from omnical.twin.online_ips import OnlineIpsParams
from omnical.twin.params import TwinParams
from omnical.twin.rig import TwinRig, TwinSession
from omnical.twin.simulator import TwinLog
from omnical.twin.world import World

__all__ = ["ClosedLoopRun", "closed_loop_run"]

StateT = TypeVar("StateT")

PoseSourceName = PoseChoice
"""What closes the loop (:data:`omnical.control.rig_loop.PoseChoice`)."""


@dataclass(frozen=True, eq=False)
class ClosedLoopRun:
    """A closed-loop run on the digital twin.

    Attributes:
        recording: /cmd_vel, /omnical/events and the twin topics (odometry, ground truth, IMU,
            post-hoc simulated IPS), stamped from :data:`omnical.twin.record.EPOCH_NS`.
        control: the loop's own log (poses used, commands, way-point indices).
        twin_log: the twin's sensor and truth arrays (seconds).
        path_origin_map: pose of the path frame in the map frame (the robot's start pose).
        odom_origin: odometry pose at the start of the loop (the path frame in the odom frame).
        pose_source: which pose closed the loop ("odometry", "fused", "ground_truth", "seed003").
        estimates: (M, 4) t_s, x, y, yaw of the fused or seed 003 estimate in the map frame
            ("fused" and "seed003" only; seed 003: one row per dead-wheel sample).
    """

    recording: Recording
    control: ControlLog
    twin_log: TwinLog
    path_origin_map: Pose2
    odom_origin: Pose2
    pose_source: str
    estimates: NDArray[np.float64] | None = field(default=None)

    @classmethod
    def of(cls, run: RigControlRun, recording: Recording, pose_source: str) -> ClosedLoopRun:
        """The twin's view of a run on a :class:`~omnical.twin.rig.TwinRig`."""
        session = run.session
        assert isinstance(session, TwinSession), "a closed-loop run of the twin rig"
        return cls(
            recording,
            run.control,
            session.twin.log(),
            session.start_pose_map,
            run.odom_origin,
            pose_source,
            run.estimates,
        )

    def ground_truth_path(self) -> NDArray[np.float64]:
        """(N, 4) t_s, x, y, yaw: the true pose in the path frame."""
        log = self.twin_log
        return _in_frame(self.path_origin_map, log.ground_truth_t_s, log.ground_truth_pose)

    def odometry_path(self) -> NDArray[np.float64]:
        """(N, 4) t_s, x, y, yaw: the odometry pose in the path frame."""
        log = self.twin_log
        return _in_frame(self.odom_origin, log.odom_t_s, log.odom_pose)

    def final_error_m(self, target_xy_m: tuple[float, float], source: str) -> float:
        """Distance from the final pose (``"odometry"``, ``"ground_truth"`` or ``"control"``) to a target.

        Raises:
            ConfigError: an unknown source.
        """
        if source == "odometry":
            final = self.odometry_path()[-1, 1:3]
        elif source == "ground_truth":
            final = self.ground_truth_path()[-1, 1:3]
        elif source == "control":
            final = self.control.final_pose()[:2]
        else:
            msg = f"unknown pose source {source!r}; use odometry, ground_truth or control"
            raise ConfigError(msg)
        return math.hypot(float(final[0]) - target_xy_m[0], float(final[1]) - target_xy_m[1])


def _in_frame(
    origin: Pose2, times_s: NDArray[np.float64], poses: NDArray[np.float64]
) -> NDArray[np.float64]:
    return np.column_stack([times_s, between_poses(np.asarray(origin), poses)])


def closed_loop_run(
    controller: Controller[StateT],
    robot: RobotDescription,
    params: TwinParams,
    *,
    seed: int = 0,
    pose_source: PoseSourceName = "odometry",
    rate_hz: float = 20.0,
    max_duration_s: float = 600.0,
    limits: CommandLimits | None = None,
    ips: OnlineIpsParams | None = None,
    fusion: FusionParams | None = None,
    beacons: BeaconMap | None = None,
    pause: Callable[[float], bool] | None = None,
    emergency_stop: Callable[[float], bool] | None = None,
    lead_in_s: float = 1.0,
    tail_s: float = 2.0,
    world: World | None = None,
    keep_interrupted: bool = False,
) -> ClosedLoopRun:
    """Run ``controller`` in closed loop on a fresh twin and record everything.

    The robot stands still ``lead_in_s``, the loop runs, the twin goes on ``tail_s`` after it.
    The path frame is ``params.start_pose_map``. Ctrl-C or SIGTERM stops the robot and is
    raised again, unless ``keep_interrupted``: then the run so far is returned
    (``control.reason`` ``"interrupted"``, no tail).

    Args:
        controller: the control law, path-frame targets.
        robot: robot description.
        params: twin parameters (e.g. ``TwinParams.ideal_twin()`` or ``default_twin(robot)``).
        seed: twin seed; the online IPS uses ``seed`` too, the post-hoc IPS its own stream.
        pose_source: what closes the loop: wheel odometry, the fused IPS + odometry estimate
            (initialised during the lead-in), the true pose, or seed 003's dead wheels + IMU +
            magnetometer (from the end of the lead-in).
        rate_hz: control rate.
        max_duration_s: loop time-out.
        limits: output stage; None = the robot's limits tightened by the default command limits.
        ips: online IPS fixes for ``"fused"`` (None = derived from ``params.ips``).
        fusion: filter parameters for ``"fused"`` (None = defaults with the robot's hedge offset).
        beacons: beacon map of the post-hoc simulated IPS in the recording.
        pause: pause switch, see :func:`run_controller`.
        emergency_stop: emergency stop switch, see :func:`run_controller`.
        lead_in_s: standing time before the loop starts.
        tail_s: simulated time after the loop stops.
        world: a floor plan: the recording holds the LiDAR's ``/scan`` (the run is the same).

    Returns:
        The run: recording, control log, twin log and frames.

    Raises:
        ConfigError: an unknown pose source, a bad rate or duration.
    """
    if pose_source not in ("odometry", "fused", "ground_truth", "seed003"):
        msg = f"unknown pose source {pose_source!r}; use odometry, fused, ground_truth or seed003"
        raise ConfigError(msg)
    origin_map: Pose2 = tuple(float(v) for v in params.start_pose_map)  # type: ignore[assignment]
    out_limits = limits or CommandLimits.from_robot(robot.limits).tightened(DEFAULT_COMMAND_LIMITS)
    ips_params = ips or OnlineIpsParams.from_ips_params(params.ips)
    fusion_params = fusion or FusionParams(
        hedge_offset_m=(robot.hedge_offset_m[0], robot.hedge_offset_m[1]),
        ips_sigma_m=max(ips_params.sigma_m, 0.005),
    )
    rig = TwinRig(robot, params, seed=seed, beacons=beacons, world=world, ips=ips_params)
    builder = RecordingBuilder()
    run = run_controller_on(
        rig,
        controller,
        builder,
        limits=out_limits,
        pose=pose_source,
        fusion=fusion_params,
        start_pose_map=origin_map,
        rate_hz=rate_hz,
        max_duration_s=max_duration_s,
        lead_in_s=lead_in_s,
        tail_s=tail_s,
        pause=pause,
        emergency_stop=emergency_stop,
    )
    control = run.control
    if control.reason == "interrupted" and not keep_interrupted:
        raise control.interruption or KeyboardInterrupt
    return ClosedLoopRun.of(run, builder.build(), pose_source)
