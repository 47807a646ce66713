"""The host's odometry of a serial run: what the status frames said, and when they came.

The driver integrates each status frame's twist over the firmware's period ``STATUS_PERIOD_S``,
its arrival times only bounding that (``omnical.drivers.frame_clock``); integrated over the
period here from the recording, the frames give the device's own odometry whatever the host's
scheduling was (load cannot change what a frame says: a wrong axis, sign or scale, a frame lost
or read twice, shows there). The host's integral differs from that only where the arrival bound
acted: a stall longer than the silence limit. (Integrated over the arrival times, as before
session 15, a burst after a stall left up to 9 cm of lasting error beside two busy loops.)

The frames at their period differ from the device's odometry by what a frame cannot carry: its
twist rounded to 1 mm/s and 1 mrad/s, and the firmware's yaw rate sampled once a period (it
steps by 0.73 mrad/s; the host's integral of it drifted up to 0.6 mrad/s per move:
``tests/calibration/test_analysis_odometry.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from omnical.drivers.wheeltec_serial import STATUS_PERIOD_S
from omnical.estimation.se2 import between_poses
from omnical.recording.recording import Recording

FRAMES_OFF_M = 0.015
FRAMES_OFF_RAD = math.radians(0.75)
"""How far the frames at their period may end from the device's odometry: measured up to 8.3 mm
and 0.38° over 12 runs (the centred turning: its 45° turn's rate sampled once a period, each
edge of the turn up to half a period off, where the commands fell against the frames' phase;
then 1.4 m at that heading), about half of this; an axis, a sign or a unit wrong is decimetres
over these runs, a scale 2 % wrong 2.8 cm on the centred turning's 1.4 m."""


def frames_tolerance(history: NDArray[np.float64]) -> tuple[float, float]:
    """:data:`FRAMES_OFF_M` and :data:`FRAMES_OFF_RAD` plus what stalls of the device's own
    loop may add. The frames due during a stall go out after it, each with the twist after
    it: per stall (an iteration 5 ms or more beyond the usual one), its frames (its length in
    whole status periods) times the change of the true body-frame twist across it, and the
    heading so lost times the distance driven after it. From the served twin's
    ``truth_history`` (device time, x, y, yaw at each loop iteration)."""
    if len(history) < 4:
        return FRAMES_OFF_M, FRAMES_OFF_RAD
    t, pose = history[:, 0], np.array(history[:, 1:])
    pose[:, 2] = np.unwrap(pose[:, 2])
    dt = np.diff(t)
    usual_s = float(np.median(dt))

    def twist(a: int, b: int) -> NDArray[np.float64]:  # the mean body twist from sample a to b
        d = (pose[b] - pose[a]) / max(t[b] - t[a], 1e-9)
        mid = 0.5 * (pose[a, 2] + pose[b, 2])
        c, s = math.cos(mid), math.sin(mid)
        return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]])

    driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pose[:, :2], axis=0).T))])
    lost_m = lost_rad = 0.0
    for i in map(int, np.flatnonzero(dt > usual_s + 0.005)):  # a stall from sample i to i + 1
        before = twist(int(np.searchsorted(t, t[i] - STATUS_PERIOD_S)), i)
        after = twist(i + 1, min(int(np.searchsorted(t, t[i + 1] + STATUS_PERIOD_S)), len(t) - 1))
        frames_s = math.ceil((dt[i] - usual_s) / STATUS_PERIOD_S) * STATUS_PERIOD_S
        turn = abs(after[2] - before[2]) * frames_s
        lost_rad += turn
        lost_m += float(np.hypot(*(after[:2] - before[:2]))) * frames_s
        lost_m += turn * float(driven[-1] - driven[i])
    return FRAMES_OFF_M + lost_m, FRAMES_OFF_RAD + lost_rad


def end_in_start_frame(rec: Recording, topic: str) -> NDArray[np.float64]:
    """The last (x, y, yaw) of ``topic`` in the frame of its first."""
    tab = rec.topic(topic)
    pose = np.column_stack([tab["x_m"], tab["y_m"], tab["yaw_rad"]])
    end: NDArray[np.float64] = np.asarray(between_poses(pose[0], pose[-1:]), dtype=np.float64)[0]
    return end


def _poses_from_first(rec: Recording) -> NDArray[np.float64]:
    o = rec.topic("/odom")
    pose = np.column_stack([o["x_m"], o["y_m"], o["yaw_rad"]])
    return np.asarray(between_poses(pose[0], pose), dtype=np.float64)


def frames_at_their_period(rec: Recording) -> NDArray[np.float64]:
    """(N, 3) the recorded ``/odom`` frames' twists, each integrated over the firmware's status
    period (robot time, as the bag's stamps) as the driver integrates them (mid-step heading),
    from the first frame's pose: x, y, yaw after each frame."""
    o = rec.topic("/odom")
    vx, vy, wz = (np.asarray(o[c], dtype=np.float64) for c in ("vx_mps", "vy_mps", "wz_radps"))
    out = np.zeros((len(vx), 3))
    x = y = yaw = 0.0
    dt = STATUS_PERIOD_S
    for i in range(1, len(vx)):
        mid = yaw + 0.5 * wz[i] * dt
        c, s = math.cos(mid), math.sin(mid)
        x += (vx[i] * c - vy[i] * s) * dt
        y += (vx[i] * s + vy[i] * c) * dt
        yaw += wz[i] * dt
        out[i] = (x, y, yaw)
    return out


def arrival_drift(rec: Recording) -> tuple[float, float, float]:
    """What the arrival times added to the host's odometry, against the frames at their period:
    (the largest position difference over the run, m; at the end, m; the heading's at the end,
    rad)."""
    d = _poses_from_first(rec) - frames_at_their_period(rec)
    dist = np.hypot(d[:, 0], d[:, 1])
    return float(dist.max()), float(dist[-1]), float(abs(d[-1, 2]))


def costliest_stall(commands: NDArray[np.float64]) -> tuple[float, float, float]:
    """The stall of a serial run that could move the robot furthest: from the commands the
    served twin took, (device time, vx, vy, wz) rows (``TwinDeviceServer.command_history``),
    the gap beyond the usual one, s, the distance the last command drove over it, m (each
    gap's excess times the speed commanded before it; a stall of the host or of the device),
    and the angle a gap could add or take, rad (its excess times the change of the turn rate
    across it: the rate before ran on, the one after started late). The gap reported is the
    one of the costliest distance."""
    if len(commands) < 3:
        return 0.0, 0.0, 0.0
    gaps = np.diff(commands[:, 0])
    usual = float(np.median(gaps))
    excess = np.maximum(gaps - usual, 0.0)
    excess_m = excess * np.hypot(*commands[:-1, 1:3].T)
    excess_rad = excess * np.abs(np.diff(commands[:, 3]))
    worst = int(np.argmax(excess_m))
    return float(gaps[worst] - usual), float(excess_m[worst]), float(excess_rad.max())
