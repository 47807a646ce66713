"""``twin serve --monitor``: the served twin's truth, the commands it received and its status.

:func:`feed_device` polls :meth:`~omnical.twin.device.TwinDeviceServer.snapshot` from its own
thread (never the device loop's) and queues rows on a :class:`~omnical.web.tee.MonitorLink`.
"""

from __future__ import annotations

import threading

import numpy as np

from omnical.ips.beacons import BeaconMap, default_beacon_map
from omnical.recording.topics import CMD_VEL, GROUND_TRUTH
from omnical.twin.device import TwinDeviceServer
from omnical.web.protocol import beacons_payload
from omnical.web.tee import MonitorLink

__all__ = ["feed_device"]


def feed_device(
    server: TwinDeviceServer,
    link: MonitorLink,
    stop: threading.Event,
    *,
    period_s: float = 0.02,
    beacons: BeaconMap | None = None,
) -> int:
    """Until ``stop`` is set (or the server fails): every ``period_s`` of wall time, the twin's
    true pose as ``/ground_truth`` rows and each new command as ``/cmd_vel`` (device time,
    wall-clock stamped), a ``status`` frame twice a second. Returns the snapshots sent. The
    odometry is the run's to send (``run --monitor``): it is what the host integrated."""
    bmap = beacons if beacons is not None else default_beacon_map()
    link.latch("beacons", beacons_payload(bmap.addresses, bmap.positions_m))
    sent = 0
    last_status = -1.0
    last_commands = -1
    while not stop.wait(period_s) and server.error is None:
        snap = server.snapshot()
        t_ns = np.array([server.t0_wall_ns + round(snap.t_s * 1e9)], dtype=np.int64)
        tx, ty, tyaw = snap.truth_pose_map
        link.rows(GROUND_TRUTH, t_ns, {"x_m": [tx], "y_m": [ty], "yaw_rad": [tyaw],
                                       "vx_mps": [0.0], "vy_mps": [0.0], "wz_radps": [0.0]})  # fmt: skip
        if snap.last_command is not None and snap.commands_applied != last_commands:
            last_commands = snap.commands_applied
            cx, cy, cw = snap.last_command
            link.rows(CMD_VEL, t_ns, {"vx_mps": [cx], "vy_mps": [cy], "wz_radps": [cw]})
        if snap.t_s - last_status >= 0.5 * server.config.time_scale:
            last_status = snap.t_s
            watchdog = server.config.watchdog_s
            link.send(
                "status",
                {
                    "t": t_ns[0] / 1e9,
                    "battery_v": server.config.battery_v,
                    "stop": False,
                    "firmware_watchdog": "off"
                    if watchdog is None
                    else f"{watchdog:g} s, tripped {snap.watchdog_trips}×",
                    "commands": snap.commands_applied,
                },
            )
        sent += 1
    return sent
