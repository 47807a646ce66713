"""A simulated run end to end: a motion script on the twin, recorded with the simulated IPS.

This is what ``omnical simulate`` does: the Runner drives the twin through the script, the twin
logs its sensors and the truth, and the simulated Marvelmind system (non-inverse architecture)
measures the true hedgehog trajectory. Everything is assembled into one :class:`Recording` with
the topics of ARCHITECTURE.md, stamped from a fixed epoch so runs are reproducible.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

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

__all__ = ["EPOCH_NS", "simulate_run", "twin_recording"]

EPOCH_NS = 1_667_865_600_000_000_000
"""Bag time of t = 0 in simulated runs: 2022-11-08 00:00 UTC (seed 000's publication date)."""

_LEAD_IN_S = 1.0
_TAIL_S = 1.0


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
) -> Recording:
    """Run ``script`` on a fresh twin and return the full recording (with IPS and ground truth).

    The robot stands still for 1 s before the script starts and 1 s after it ends.
    """
    twin = DigitalTwin(robot, params, seed=seed)
    clock = TwinClock(twin)
    twin.advance_to(_LEAD_IN_S)
    run = run_script(script, twin, clock, on_tick=on_tick)
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
    twin_recording(builder, twin.log(), robot, params, seed=seed, beacons=beacons)
    return builder.build()


def twin_recording(
    builder: RecordingBuilder,
    log: TwinLog,
    robot: RobotDescription,
    params: TwinParams,
    *,
    seed: int,
    beacons: BeaconMap | None = None,
) -> None:
    """Add the twin's sensor logs, the truth and the simulated IPS to ``builder``."""
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
