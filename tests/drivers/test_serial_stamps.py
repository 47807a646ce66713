"""Stamps and gaps of the serial drivers: strictly increasing /odom, device-timed hedgehog rows."""

from __future__ import annotations

import time

import numpy as np
import pytest

from omnical.drivers.hedgehog import SerialHedgehog
from omnical.drivers.wheeltec import StatusFrame, encode_status
from omnical.drivers.wheeltec_serial import STATUS_PERIOD_S, WheeltecRobot


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


def _turning(n: int) -> list[tuple[float, float, float]]:
    """Twists of an accelerating turn: a frame's motion depends on which period it covers."""
    return [(0.02 * i, 0.01 * i, 0.5 + 0.05 * i) for i in range(n)]


def _at_their_period(
    twists: list[tuple[float, float, float]], periods: list[int] | None = None
) -> tuple[float, float, float]:
    """The twists after the first integrated over their periods (mid-step heading)."""
    x = y = yaw = 0.0
    for i, (vx, vy, wz) in enumerate(twists[1:], start=1):
        dt = STATUS_PERIOD_S * (1 if periods is None else periods[i])
        mid = yaw + 0.5 * wz * dt
        x += (vx * np.cos(mid) - vy * np.sin(mid)) * dt
        y += (vx * np.sin(mid) + vy * np.cos(mid)) * dt
        yaw += wz * dt
    return x, y, yaw


def _frame(twist: tuple[float, float, float]) -> bytes:
    return encode_status(StatusFrame.from_si(twist))


def test_frames_late_after_a_stall_of_the_sender_each_cover_their_own_period() -> None:
    """A served twin (or an adapter) silent for almost its silence limit (3 periods) sends the
    frames due meanwhile one after another: each stands for its own period, not the first for
    the whole silence (4.5 mm and 12.5 mrad off here when integrated by arrival)."""
    twists = _turning(30)
    P = STATUS_PERIOD_S
    with WheeltecRobot(_SilentPort(), host_watchdog_s=None) as robot:
        for i, tw in enumerate(twists):
            if i < 12:
                arrival = 5.0 + i * P
            elif i < 15:  # held back, then 2 ms apart (the wire's pace)
                arrival = 5.0 + 14.8 * P + (i - 12) * 0.002
            else:
                arrival = 5.0 + i * P + 0.001
            robot._on_bytes(_frame(tw), arrival)
        pose = robot.read_state().odom_pose
        stamps = np.array([s.t_s for s in robot.drain_log()])
    assert pose == pytest.approx(_at_their_period(twists), abs=1e-9)
    assert stamps == pytest.approx(5.0 + P * np.arange(30), abs=1e-9)


def test_a_garbled_frame_s_period_goes_to_the_next_frame() -> None:
    twists = _turning(20)
    P = STATUS_PERIOD_S
    with WheeltecRobot(_SilentPort(), host_watchdog_s=None) as robot:
        for i, tw in enumerate(twists):
            frame = bytearray(_frame(tw))
            if i == 7:
                frame[22] ^= 0xFF  # the XOR byte: the frame is dropped
            robot._on_bytes(bytes(frame), 1.0 + i * P)
        pose = robot.read_state().odom_pose
    received = twists[:7] + twists[8:]
    periods = [1] * 7 + [2] + [1] * 11  # frame 8 covers frame 7's period with its own twist
    assert pose == pytest.approx(_at_their_period(received, periods), abs=1e-9)


@pytest.mark.parametrize("rate_hz", [10.0, 40.0])
def test_a_firmware_at_another_rate_is_bounded_by_the_arrivals(rate_hz: float) -> None:
    """Frames every 0.1 s would give half the distance at the firmware's 20 Hz period, every
    25 ms twice it; the arrival times keep the integral within the silence limit of them."""
    v = 0.2
    with WheeltecRobot(_SilentPort(), host_watchdog_s=None) as robot:
        for i in range(101):
            robot._on_bytes(_frame((v, 0.0, 0.0)), 2.0 + i / rate_hz)
        x = robot.read_state().odom_pose[0]
    assert 100 / rate_hz * v - 3 * STATUS_PERIOD_S * v - 1e-9 <= x <= 100 / rate_hz * v + 1e-9


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


def test_the_first_status_is_any_valid_frame_since_the_port_opened() -> None:
    """``wait_for_status`` passes on one valid frame, however old by the robot's clock (a
    loaded test machine's host read its backlog late: every frame 'stale' for 2 s, 'no valid
    status frame'); nothing valid at all is the one-line refusal."""
    from omnical.errors import ProtocolError
    from omnical.services.hil import wait_for_status

    now = [100.0]
    with WheeltecRobot(_SilentPort(), host_watchdog_s=None, clock=lambda: now[0]) as robot:
        with pytest.raises(ProtocolError, match=r"no valid status frame .* within 0\.2 s"):
            wait_for_status(robot, timeout_s=0.2)
        robot._on_bytes(b"\x00garbage" + _frames(1), 100.0)
        now[0] = 105.0  # five seconds later by the robot's clock: stale, but it came
        assert robot.read_state().stale
        wait_for_status(robot, timeout_s=0.2)
