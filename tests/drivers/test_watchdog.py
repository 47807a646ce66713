"""The driver's safety stop: a device that falls silent under a moving robot stops it.

The twin serves the vehicle controller and the hedgehog on pseudo-terminals; a relay between it
and the driver goes silent, sends garbage or hangs up mid-motion. Measured on the wire: the
last non-zero command frame the host sent after the last good status frame.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from relay import Relay

from omnical.drivers.hedgehog import SerialHedgehog
from omnical.drivers.watchdog import GapLog, Silence
from omnical.drivers.wheeltec_serial import WheeltecRobot, open_wheeltec_port
from omnical.errors import SafetyStopError
from omnical.robot.loader import load_robot
from omnical.twin.device import TwinDeviceServer
from omnical.twin.params import load_twin

ROBOT = load_robot("rosy-mecanum")
STOP_WITHIN_S = 0.5  # issue 28: moving commands stop ≤ 0.5 s after the last good frame


@pytest.fixture(scope="module")
def server() -> Iterator[TwinDeviceServer]:
    with TwinDeviceServer(ROBOT, load_twin("ideal", ROBOT)) as srv:
        yield srv


def _wait(pred: object, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():  # type: ignore[operator]
            return True
        time.sleep(0.005)
    return False


def _drive_until_stopped(robot: WheeltecRobot, timeout_s: float = 3.0) -> SafetyStopError:
    """Command a slow forward motion at 20 Hz, as a runner would, until the driver refuses."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        try:
            robot.send_twist(0.05, 0.0, 0.0)
        except SafetyStopError as err:
            return err
        time.sleep(0.05)
    pytest.fail("the driver kept accepting motion commands")


@pytest.mark.alone  # wall clock against a device served from this process (see test_watchdog_cli)
@pytest.mark.parametrize("mode", ["silent", "garbage", "close"])
def test_a_silent_vehicle_controller_stops_the_robot(server: TwinDeviceServer, mode: str) -> None:
    with Relay(server.vehicle_path) as relay:
        port = open_wheeltec_port(relay.path)
        with WheeltecRobot(port, robot=ROBOT, name=f"vehicle controller on {relay.path}") as robot:
            assert _wait(lambda: not robot.read_state().stale, 2.0)
            robot.send_twist(0.05, 0.0, 0.0)
            time.sleep(0.3)
            relay.fail(mode)  # type: ignore[arg-type]
            err = _drive_until_stopped(robot)
            assert robot.safety_stop is err
        assert relay.last_forwarded is not None
        late = relay.moving_after(relay.last_forwarded)
    print(f"{mode}: last moving command {late * 1e3:.0f} ms after the last good status frame")
    assert relay.moved() and late <= STOP_WITHIN_S
    assert relay.path in str(err) and "robot stopped" in str(err)
    if mode == "garbage" and relay.garbage_before_the_stop(str(err)):
        print("garbage: sent 100 ms or more before the stop")
        assert "bytes received, none valid" in str(err)
    if mode == "close":
        assert "port failed" in str(err)


@contextmanager
def _relayed_hedgehog(
    server: TwinDeviceServer,
) -> Iterator[tuple[Relay, WheeltecRobot, SerialHedgehog]]:
    """The robot served directly, the hedgehog through a relay, both streaming. The vehicle
    controller's own limit is 0.5 s here: the hedgehog is the subject, and a loaded machine's
    stall of the served device (> 0.15 s) must not stop the robot first."""
    with (
        Relay(server.hedge_path) as relay,
        WheeltecRobot(
            open_wheeltec_port(server.vehicle_path), robot=ROBOT, watchdog_s=STOP_WITHIN_S
        ) as robot,
        SerialHedgehog.open(relay.path) as hedge,
    ):
        assert _wait(lambda: not robot.read_state().stale and hedge.latest_fix(), 3.0)
        yield relay, robot, hedge


@pytest.mark.alone
def test_a_silent_required_hedgehog_stops_the_robot(server: TwinDeviceServer) -> None:
    with _relayed_hedgehog(server) as (relay, robot, hedge):
        robot.require(hedge)
        assert _wait(lambda: not hedge.silence(time.monotonic()).exceeded, 2.0)
        robot.send_twist(0.05, 0.0, 0.0)
        time.sleep(0.3)
        relay.fail("silent")
        err = _drive_until_stopped(robot)
        stopped = time.monotonic()
        assert _wait(lambda: server.last_command == (0.0, 0.0, 0.0), 0.5)
        silence = hedge.silence(stopped)
    assert relay.last_forwarded is not None
    print(
        f"hedgehog limit {silence.limit_s * 1e3:.0f} ms: the driver refused "
        f"{(stopped - relay.last_forwarded) * 1e3:.0f} ms after the last good packet"
    )
    assert stopped - relay.last_forwarded <= STOP_WITHIN_S
    assert f"hedgehog on {relay.path}: no valid data for" in str(err)
    # what came after the last packet: nothing, or the head of one the relay cut off
    assert re.search(r"\((nothing received|\d+ bytes received, none valid)\)", str(err))


@pytest.mark.alone
def test_a_released_hedgehog_may_be_silent(server: TwinDeviceServer) -> None:
    with _relayed_hedgehog(server) as (relay, robot, hedge):
        robot.require(hedge)
        robot.release(hedge)
        relay.fail("silent")
        time.sleep(0.6)
        robot.send_twist(0.05, 0.0, 0.0)  # no safety stop: nothing needs the hedgehog
        time.sleep(0.2)
        robot.stop()
        assert robot.safety_stop is None


def test_no_motion_starts_blind() -> None:
    """Before the first status frame (or after a silence at rest) a motion is refused at once."""

    class Mute:
        in_waiting = 0

        def read(self, size: int = 1, /) -> bytes:
            time.sleep(0.001)
            return b""

        def write(self, data: bytes, /) -> int:
            self.sent.append(data)
            return len(data)

        def flush(self) -> None:
            pass

        def close(self) -> None:
            pass

        sent: list[bytes] = []  # noqa: RUF012

    port = Mute()
    with WheeltecRobot(port, host_watchdog_s=None, name="vehicle controller on /dev/test") as robot:
        robot.send_twist(0.0, 0.0, 0.0)  # standing still needs no status
        with pytest.raises(
            SafetyStopError,
            match=r"/dev/test: no valid data at all before the robot moved.*motion not started",
        ):
            robot.send_twist(0.1, 0.0, 0.0)
        robot.send_twist(0.0, 0.0, 0.0)  # a stop is never refused
        with pytest.raises(SafetyStopError):  # latched: no motion until the experiment ends
            robot.send_twist(0.0, 0.1, 0.0)
    from omnical.drivers.wheeltec import encode_command

    assert encode_command(0.1, 0.0, 0.0) not in port.sent


@pytest.mark.alone
def test_the_drivers_own_thread_zeroes_a_command_nobody_repeats(server: TwinDeviceServer) -> None:
    """One motion command and then nothing from the caller (host watchdog off): the zero
    comes from the driver's thread, on the wire, within the limit of the last good frame."""
    with Relay(server.vehicle_path) as relay:
        port = open_wheeltec_port(relay.path)
        with WheeltecRobot(port, robot=ROBOT, host_watchdog_s=None) as robot:
            assert _wait(lambda: not robot.read_state().stale, 2.0)
            robot.send_twist(0.05, 0.0, 0.0)
            time.sleep(0.3)
            relay.fail("silent")
            assert _wait(lambda: robot.safety_stop is not None, 1.0)
            time.sleep(0.1)
            sent = list(relay.commands)
        assert relay.last_forwarded is not None
        late = relay.moving_after(relay.last_forwarded)
    print(f"the thread's zero: last moving frame {late * 1e3:.0f} ms after the last status")
    assert sent[-1][1] == (0.0, 0.0, 0.0) and late <= STOP_WITHIN_S


def test_gap_log_marks_both_edges_once() -> None:
    gaps = GapLog()
    quiet = Silence("hedgehog on X", 0.05, 0.3)
    assert gaps.update(quiet, 1.0) is None
    line = gaps.update(Silence("hedgehog on X", 0.4, 0.3, "nothing received"), 2.0)
    assert line is not None and "no valid data for 0.40 s" in line and "marked" in line
    assert gaps.update(Silence("hedgehog on X", 0.9, 0.3, "nothing received"), 2.5) is None
    back = gaps.update(Silence("hedgehog on X", 0.02, 0.3), 3.0)
    assert back is not None and "gap of 1.38 s" in back
    assert [t for t, _ in gaps.events] == [pytest.approx(1.6), pytest.approx(2.98)]
    assert '"edge":"start"' in gaps.events[0][1] and '"edge":"end"' in gaps.events[1][1]
    gaps.update(Silence("hedgehog on X", 1.0, 0.3), 4.0)  # silent from 3.0 to the end
    gaps.close(Silence("hedgehog on X", 2.0, 0.3), 5.0)
    assert [e[0] for e in gaps.events[2:]] == [3.0, 5.0]
    never = GapLog()  # a device that never sent: its gap starts with the run, said as "yet"
    line = never.update(Silence("hedgehog on Y", math.inf, 0.3), 0.4)
    assert line is not None and "no valid data yet" in line and never.events[0][0] == 0.0
