"""The twin's recording: its sensor logs, the truth and the simulated IPS as bag rows.

With ``/scan`` when the run is in a world, ``/dead_wheels`` and ``/imu/mag`` when the robot has
dead wheels; stamped from a fixed epoch (:data:`EPOCH_NS`) so that runs are reproducible.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from omnical.experiment.rig import RowSink
from omnical.ips.beacons import BeaconMap, default_beacon_map
from omnical.recording.topics import (
    BEACON_RAW_DISTANCE,
    BEACONS_POS_A,
    DEAD_WHEELS,
    GROUND_TRUTH,
    HEDGE_POS_ANG,
    HEDGE_QUALITY,
    IMU,
    IMU_MAG,
    ODOM,
    SCAN,
)
from omnical.robot.description import RobotDescription
from omnical.twin.ips_model import simulate_ips
from omnical.twin.params import TwinParams
from omnical.twin.simulator import ImuColumn, StateColumn, TwinLog

if TYPE_CHECKING:  # the world and the LiDAR are imported only when a run has a world
    from omnical.twin.lidar import LidarParams, LidarScans
    from omnical.twin.world import World

__all__ = [
    "EPOCH_NS",
    "add_scans",
    "lidar_params",
    "stamp_ns",
    "twin_recording",
    "write_state_logs",
]

TESLA_PER_GAUSS = 1e-4

EPOCH_NS = 1_667_865_600_000_000_000
"""Bag time of t = 0 in simulated runs: 2022-11-08 00:00 UTC (seed 000's publication date)."""


def stamp_ns(t_s: np.ndarray, epoch_ns: int = EPOCH_NS) -> np.ndarray:
    """Bag times of twin times: ``epoch_ns`` + ``t_s`` in whole ns."""
    return epoch_ns + np.round(np.asarray(t_s) * 1e9).astype(np.int64)


def write_state_logs(sink: RowSink, log: TwinLog, epoch_ns: int = EPOCH_NS) -> None:
    """Write the twin's ``/odom``, ``/ground_truth`` and ``/imu`` rows to ``sink``, stamped
    ``epoch_ns`` + their twin times."""
    for topic, rows, columns in (
        (ODOM, log.odom, StateColumn),
        (GROUND_TRUTH, log.ground_truth, StateColumn),
        (IMU, log.imu, ImuColumn),
    ):
        sink.write_rows(
            topic,
            stamp_ns(rows[:, 0], epoch_ns),
            **{c.name.lower(): rows[:, c] for c in columns if c != 0},
        )


def lidar_params(robot: RobotDescription, base: LidarParams | None = None) -> LidarParams:
    """The LiDAR of ``robot``: ``base`` (default RPLidar-like) at the description's mounting."""
    from omnical.twin.lidar import LidarParams

    lp = base or LidarParams()
    mount = robot.lidar_mount
    return replace(lp, mount_pose=(mount.x_m, mount.y_m, mount.yaw_rad))


def add_scans(builder: RowSink, scans: LidarScans) -> None:
    """Add ``scans`` to ``builder`` as ``/scan`` (REP 117: +inf no return, -inf too close,
    NaN dropout; no intensities; one pose per scan, so ``time_increment`` is 0)."""
    p = scans.params
    n = len(scans)
    inc = p.angle_increment_rad

    def const(v: float) -> np.ndarray:
        return np.full(n, v, dtype=np.float32).astype(np.float64)

    builder.write_rows(
        SCAN,
        stamp_ns(scans.t_s),
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
    builder: RowSink,
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
    write_state_logs(builder, log)
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
    builder.write_rows(
        HEDGE_POS_ANG,
        stamp_ns(pos.t_s),
        address=pos.address,
        timestamp_ms=pos.timestamp_ms,
        x_m=pos.x_m,
        y_m=pos.y_m,
        z_m=pos.z_m,
        flags=pos.flags,
        angle_deg=pos.angle_deg,
    )
    dist = ips.distances
    builder.write_rows(
        BEACON_RAW_DISTANCE,
        stamp_ns(dist.t_s),
        address_hedge=dist.address_hedge,
        address_beacon=dist.address_beacon,
        distance_m=dist.distance_m,
    )
    q = ips.quality
    builder.write_rows(
        HEDGE_QUALITY, stamp_ns(q.t_s), address=q.address, quality_percent=q.quality_percent
    )
    b = ips.beacons
    builder.write_rows(
        BEACONS_POS_A, stamp_ns(b.t_s), address=b.address, x_m=b.x_m, y_m=b.y_m, z_m=b.z_m
    )
    if robot.dead_wheels and log.dead_wheel_counts.shape[0]:
        counts = log.dead_wheel_cumulative_counts
        n = counts.shape[0]
        per_rev = np.array([d.counts_per_rev for d in robot.dead_wheels], dtype=np.float64)
        builder.write_rows(
            DEAD_WHEELS,
            stamp_ns(log.dead_wheel_t_s),
            name=np.array([[d.name for d in robot.dead_wheels]] * n, dtype=object),
            position_rad=counts * (2.0 * np.pi / per_rev),
            velocity_radps=np.zeros((n, 0)),
            effort_nm=np.zeros((n, 0)),
        )
        mag = log.magnetometer
        field_t = log.magnetic_field_g * TESLA_PER_GAUSS
        builder.write_rows(
            IMU_MAG,
            stamp_ns(mag[:, 0]),
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
