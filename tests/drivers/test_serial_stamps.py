"""Stamps and gaps of the serial drivers: strictly increasing /odom, device-timed hedgehog rows."""

from __future__ import annotations

import time

import numpy as np
import pytest

from omnical.drivers.hedgehog import SerialHedgehog
from omnical.drivers.wheeltec import StatusFrame, encode_status
from omnical.drivers.wheeltec_serial import WheeltecRobot


class _SilentPort:
    """A port nothing arrives on; the test feeds the driver's byte handler itself."""

    in_waiting = 0

    def read(self, size: int = 1, /) -> bytes:
        time.sleep(0.001)
        return b""

    def write(self, data: bytes, /) -> int:
        return len(data)

    def flush(self) -> None:
        pass

    def close(self) -> None:
        pass


def _frames(n: int, vx_mps: float = 0.2) -> bytes:
    return b"".join(encode_status(StatusFrame.from_si((vx_mps, 0.0, 0.0))) for _ in range(n))


def test_frames_read_together_get_increasing_stamps_and_share_the_gap() -> None:
    with WheeltecRobot(_SilentPort(), host_watchdog_s=None) as robot:
        robot._on_bytes(_frames(1), 10.0)
        robot._on_bytes(_frames(3), 10.15)  # three frames in one read (a USB or host stall)
        robot._on_bytes(_frames(1), 10.15)  # one more in the same instant: still later
        samples = robot.drain_log()
    t = np.array([s.t_s for s in samples])
    assert np.all(np.diff(t) > 0), t
    assert t[1:4] == pytest.approx([10.05, 10.10, 10.15], abs=1e-9)
    # odometry: 0.15 s at 0.2 m/s over the three, the fifth adds (almost) nothing
    assert samples[3].pose[0] == pytest.approx(0.03, abs=1e-9)


def test_a_burst_after_a_stall_is_integrated_a_silent_link_is_not() -> None:
    with WheeltecRobot(_SilentPort(), host_watchdog_s=None, max_gap_s=1.0) as robot:
        robot._on_bytes(_frames(1), 0.0)
        robot._on_bytes(_frames(20), 1.0)  # 1 s late, all 20 frames: 1 s at 0.2 m/s
        x_after_burst = robot.read_state().odom_pose[0]
        robot._on_bytes(_frames(1), 4.0)  # 3 s of silence, one frame: the motion is unknown
        x_after_silence = robot.read_state().odom_pose[0]
        assert robot.gaps_skipped == 1
    assert x_after_burst == pytest.approx(0.2, abs=1e-9)
    assert x_after_silence == x_after_burst


def test_hedgehog_rows_keep_the_device_spacing_despite_receive_jitter() -> None:
    rng = np.random.default_rng(3)
    hedge = SerialHedgehog(_SilentPort())
    try:
        device = 100.0 + 0.0625 * np.arange(400)  # 16 Hz
        delay = 0.02 + rng.exponential(0.015, len(device))  # host scheduling + USB
        stamps = [
            hedge._stamp("position", 5000.0 + d + e, d) for d, e in zip(device, delay, strict=True)
        ]
    finally:
        hedge.close()
    stamps_arr = np.array(stamps)
    assert np.all(np.diff(stamps_arr) >= 0)
    assert np.all(stamps_arr <= 5000.0 + device + delay + 1e-12)  # never after receipt
    # after the first packets, the stamp is the device time + the smallest delay seen
    tail = stamps_arr[100:] - (5000.0 + device[100:])
    assert np.ptp(tail) < 0.002 and abs(tail.mean() - delay.min()) < 0.002
    raw_jitter = np.ptp(delay[100:])
    assert raw_jitter > 0.05  # what receive stamps would have carried
