"""A simulated run end to end: a motion script on the twin, recorded with the simulated IPS.

This is what ``omnical simulate`` does: the Runner drives the twin through the script, the twin
logs its sensors and the truth, and the simulated Marvelmind system (non-inverse architecture)
measures the true hedgehog trajectory. Everything is assembled into one :class:`Recording` with
the topics of ARCHITECTURE.md, stamped from a fixed epoch so runs are reproducible.

Sensors a robot or a run adds: ``/scan`` (``sensor_msgs/LaserScan``) when the run is in a
world (:class:`~omnical.twin.world.World`; the LiDAR of :mod:`omnical.twin.lidar` over the
ground truth, at its rate, mounted where the robot description says); ``/dead_wheels``
(``sensor_msgs/JointState``: the cumulative dead-wheel encoder angles in radians, counts ×
2π / ``counts_per_rev``, at the odometry rate) and ``/imu/mag`` (``sensor_msgs/MagneticField``,
tesla) when the robot has dead wheels (the ``omni-x`` preset, seed 003). A robot without dead
wheels run without a world records exactly what it always did.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from omnical.experiment.runner import run_script
from omnical.experiment.script import CommandSource
from omnical.ips.beacons import BeaconMap, default_beacon_map
from omnical.recording.recording import Recording, RecordingBuilder
from omnical.robot.description import RobotDescription
from omnical.twin.clock import TwinClock
from omnical.twin.ips_model import simulate_ips
from omnical.twin.params import TwinParams
from omnical.twin.simulator import DigitalTwin, ImuColumn, StateColumn, TwinLog

if TYPE_CHECKING:  # types only: the world (scipy.ndimage, ~0.3 s) and the LiDAR (numba's ray
    # casting, ~0.2 s) are imported when a run has a world
    from omnical.twin.lidar import LidarParams, LidarScans
    from omnical.twin.world import World

__all__ = ["EPOCH_NS", "SHORT_RUN_S", "add_scans", "lidar_params", "simulate_run", "twin_recording"]

TESLA_PER_GAUSS = 1e-4

EPOCH_NS = 1_667_865_600_000_000_000
"""Bag time of t = 0 in simulated runs: 2022-11-08 00:00 UTC (seed 000's publication date)."""

_LEAD_IN_S = 1.0
_TAIL_S = 1.0
SHORT_RUN_S = 10.0
"""Runs shorter than this (robot time, lead-in and tail included) take the twin's Python
reference under engine ``"auto"``: loading numba's cached kernels (≈ 0.45 s) costs more than
such a run does in Python (≈ 400× real time: 10 s in ≈ 25 ms); both give the same logs."""


def _ns(t_s: np.ndarray) -> np.ndarray:
    return EPOCH_NS + np.round(np.asarray(t_s) * 1e9).astype(np.int64)


def simulate_run(
    script: CommandSource,
    robot: RobotDescription,
    params: TwinParams,
    *,
    seed: int = 0,
    beacons: BeaconMap | None = None,
    on_tick: Callable[[float, float], None] | None = None,
    world: World | None = None,
    keep_interrupted: bool = False,
) -> Recording:
    """Run ``script`` on a fresh twin and return the full recording (with IPS and ground truth).

    The robot stands still for 1 s before the script starts and 1 s after it ends. With a
    ``world`` the recording holds the LiDAR's ``/scan`` too (the run itself is the same).

    Ctrl-C or SIGTERM while the script runs stops the robot and is raised again, unless
    ``keep_interrupted``: then the run up to there is returned (``omnical simulate`` keeps it).
    """
    if params.engine == "auto" and script.duration_s + _LEAD_IN_S + _TAIL_S < SHORT_RUN_S:
        params = replace(params, engine="python")
    twin = DigitalTwin(robot, params, seed=seed)
    clock = TwinClock(twin)
    twin.advance_to(_LEAD_IN_S)
    run = run_script(script, twin, clock, on_tick=on_tick)
    if run.interrupted and not keep_interrupted:
        raise run.interruption or KeyboardInterrupt
    twin.advance_to(twin.t_s + _TAIL_S)
    builder = RecordingBuilder()
    builder.add_many(
        "/cmd_vel",
        _ns(run.cmd_vel[:, 0]),
        vx_mps=run.cmd_vel[:, 1],
        vy_mps=run.cmd_vel[:, 2],
        wz_radps=run.cmd_vel[:, 3],
    )
    if run.events:
        t_ev = np.array([t for t, _ in run.events])
        builder.add_many(
            "/omnical/events", _ns(t_ev), text=np.array([e for _, e in run.events], dtype=object)
        )
    twin_recording(builder, twin.log(), robot, params, seed=seed, beacons=beacons, world=world)
    return builder.build()


def lidar_params(robot: RobotDescription, base: LidarParams | None = None) -> LidarParams:
    """The LiDAR of ``robot``: ``base`` (default RPLidar-like) at the description's mounting."""
    from omnical.twin.lidar import LidarParams

    lp = base or LidarParams()
    mount = robot.lidar_mount
    return replace(lp, mount_pose=(mount.x_m, mount.y_m, mount.yaw_rad))


def add_scans(builder: RecordingBuilder, scans: LidarScans) -> None:
    """Add ``scans`` to ``builder`` as ``/scan`` (REP 117: +inf no return, -inf too close,
    NaN dropout; no intensities; one pose per scan, so ``time_increment`` is 0)."""
    p = scans.params
    n = len(scans)
    inc = p.angle_increment_rad

    def const(v: float) -> np.ndarray:
        return np.full(n, v, dtype=np.float32).astype(np.float64)

    builder.add_many(
        "/scan",
        _ns(scans.t_s),
        angle_min_rad=const(p.angle_min_rad),
        angle_max_rad=const(p.angle_min_rad + (p.beams - 1) * inc),
        angle_increment_rad=const(inc),
        time_increment_s=const(0.0),
        scan_time_s=const(1.0 / p.rate_hz),
        range_min_m=const(p.range_min_m),
        range_max_m=const(p.range_max_m),
        ranges_m=scans.ranges_m.astype(np.float32),
        intensities=np.zeros((n, 0), dtype=np.float32),
    )


def twin_recording(
    builder: RecordingBuilder,
    log: TwinLog,
    robot: RobotDescription,
    params: TwinParams,
    *,
    seed: int,
    beacons: BeaconMap | None = None,
    world: World | None = None,
    lidar: LidarParams | None = None,
) -> None:
    """Add the twin's sensor logs, the truth and the simulated IPS to ``builder``; the
    LiDAR's scans in ``world`` if given (``lidar``: the sensor, default :func:`lidar_params`),
    the dead wheels and the magnetometer if the robot has dead wheels."""
    for topic, rows in (("/odom", log.odom), ("/ground_truth", log.ground_truth)):
        builder.add_many(
            topic,
            _ns(rows[:, StateColumn.T_S]),
            **{c.name.lower(): rows[:, c] for c in StateColumn if c is not StateColumn.T_S},
        )
    imu = log.imu
    builder.add_many(
        "/imu",
        _ns(imu[:, ImuColumn.T_S]),
        **{c.name.lower(): imu[:, c] for c in ImuColumn if c is not ImuColumn.T_S},
    )
    bmap = beacons if beacons is not None else default_beacon_map()
    offset = params.hedge_offset_m if params.hedge_offset_m is not None else robot.hedge_offset_m
    ips_params = replace(params.ips, hedge_offset_base_m=offset)
    ips = simulate_ips(
        log.ground_truth_t_s,
        log.ground_truth_pose,
        bmap.addresses,
        bmap.positions_m,
        ips_params,
        np.random.default_rng([seed, 0x1B5]),
        engine=params.engine,  # "python": the numpy reference of the vendor's solve too
    )
    pos = ips.positions
    builder.add_many(
        "/hedge_pos_ang",
        _ns(pos.t_s),
        address=pos.address,
        timestamp_ms=pos.timestamp_ms,
        x_m=pos.x_m,
        y_m=pos.y_m,
        z_m=pos.z_m,
        flags=pos.flags,
        angle_deg=pos.angle_deg,
    )
    dist = ips.distances
    builder.add_many(
        "/beacon_raw_distance",
        _ns(dist.t_s),
        address_hedge=dist.address_hedge,
        address_beacon=dist.address_beacon,
        distance_m=dist.distance_m,
    )
    q = ips.quality
    builder.add_many(
        "/hedge_quality", _ns(q.t_s), address=q.address, quality_percent=q.quality_percent
    )
    b = ips.beacons
    builder.add_many(
        "/beacons_pos_a", _ns(b.t_s), address=b.address, x_m=b.x_m, y_m=b.y_m, z_m=b.z_m
    )
    if robot.dead_wheels and log.dead_wheel_counts.shape[0]:
        counts = log.dead_wheel_cumulative_counts
        n = counts.shape[0]
        per_rev = np.array([d.counts_per_rev for d in robot.dead_wheels], dtype=np.float64)
        builder.add_many(
            "/dead_wheels",
            _ns(log.dead_wheel_t_s),
            name=np.array([[d.name for d in robot.dead_wheels]] * n, dtype=object),
            position_rad=counts * (2.0 * np.pi / per_rev),
            velocity_radps=np.zeros((n, 0)),
            effort_nm=np.zeros((n, 0)),
        )
        mag = log.magnetometer
        field_t = log.magnetic_field_g * TESLA_PER_GAUSS
        builder.add_many(
            "/imu/mag",
            _ns(mag[:, 0]),
            mag_x_t=field_t[:, 0],
            mag_y_t=field_t[:, 1],
            mag_z_t=field_t[:, 2],
        )
    if world is not None:
        from omnical.twin.lidar import simulate_scans

        lp = lidar or lidar_params(robot)
        scans = simulate_scans(
            log.ground_truth_t_s, log.ground_truth_pose, world.grid, lp, seed=seed
        )
        add_scans(builder, scans)
