"""A device that fails mid-run, as the user meets it: ``omnical run`` and ``calibrate campaign``.

The twin serves the robot on pseudo-terminals; a relay between it and omnical goes silent, sends
garbage or hangs up while the robot moves. The vehicle controller, and the hedgehog where the
experiment needs it, stop the robot (moving commands end ≤ 0.5 s after the last good data),
exit status 4 with one line naming the device, the recording kept as ``RUN.partial``. A plain
script goes on without the hedgehog, with a warning and the gap marked in the bag.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from relay import Relay

from omnical.bags.bag import read_bag
from omnical.robot.loader import load_robot
from omnical.services.hil import SCALED_STALL_S
from omnical.twin.device import DeviceConfig, TwinDeviceServer
from omnical.twin.params import load_twin

# Wall-clock runs against a device served from this process (`alone`: see pyproject.toml). On
# the robot's own clock (x1) the vehicle controller's limit is 0.15 s: a loaded machine can
# stall the served device that long, and the run then stops on the vehicle controller. The
# tests whose subject is the vehicle controller take that as it comes (the stop, its one line
# and the kept bag are the same); the others run on a scaled clock, where every limit is
# SCALED_STALL_S of wall time (omnical.services.hil), and check that the stop happened, not at
# which millisecond.
pytestmark = pytest.mark.alone

ROBOT = load_robot("rosy-mecanum")
EXIT_SAFETY_STOP = 4
STOP_WITHIN_S = 0.5
SCRIPT = "name: long\nsteps:\n  - move: {vx_mps: 0.1, duration_s: 5.0}\n"


def _omnical(*args: str) -> list[str]:
    return [sys.executable, "-c", "from omnical.cli.main import main; main()", *args]


def _run(tmp_path: Path, vehicle: str, hedge: str, *extra: str) -> subprocess.Popen[str]:
    script = tmp_path / "long.yaml"
    script.write_text(SCRIPT)
    return subprocess.Popen(
        _omnical(
            "run", str(script), "--robot", f"serial:{vehicle}", "--hedge", f"serial:{hedge}",
            "--beacons", "default", "--yes", "--margin", "-100", "--out", str(tmp_path / "run.mcap"),
            *extra,
        ),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL,
    )  # fmt: skip


def _when_moving(relay: Relay, proc: subprocess.Popen[str], timeout_s: float = 30.0) -> None:
    end = time.monotonic() + timeout_s
    while not relay.moved():
        assert proc.poll() is None and time.monotonic() < end, "the run never moved"
        time.sleep(0.02)


@pytest.mark.parametrize("mode", ["silent", "garbage", "close"])
def test_run_stops_when_the_vehicle_controller_fails(tmp_path: Path, mode: str) -> None:
    with TwinDeviceServer(ROBOT, load_twin("ideal", ROBOT)) as server:
        with Relay(server.vehicle_path) as relay:
            proc = _run(tmp_path, relay.path, server.hedge_path)
            _when_moving(relay, proc)
            time.sleep(1.0)
            relay.fail(mode)  # type: ignore[arg-type]
            _, err = proc.communicate(timeout=30)
            assert relay.last_forwarded is not None
            late = relay.moving_after(relay.last_forwarded)
        assert server.last_command == (0.0, 0.0, 0.0) or mode == "close"
    print(f"{mode}: moving commands {late * 1e3:.0f} ms after the last good status frame")
    assert proc.returncode == EXIT_SAFETY_STOP, err
    assert late <= STOP_WITHIN_S
    errors = [line for line in err.splitlines() if line.startswith("omnical: error:")]
    assert len(errors) == 1 and f"vehicle controller on {relay.path}" in errors[0], err
    assert "Traceback" not in err and "kept the partial run" in err
    # a pty: a pause of the served twin looks like silence, never like garbage or a closed port
    # (unless this process, the relay and the served twin, paused: before the failure, the host
    # then saw a silence first (a partial frame forwarded last, its frame before it ended
    # <= 50 ms earlier); or after it, before the garbage went out, which the relay sends as the
    # served twin sends its frames)
    # A closed port is never "nothing received": the host saw that only if this process (the
    # relay and the served twin) paused before fail() and the relay forwarded the backlog just
    # before it, after the host's limit ran out (seen beside two busy loops)
    closed_late = mode == "close" and "nothing received" in errors[0]
    paused_first = relay.quiet_before_fail_s > 0.1 or closed_late
    if paused_first:
        print(f"the relay forwarded nothing for {relay.quiet_before_fail_s:.2f} s before failing")
    garbage_seen = mode == "garbage" and relay.garbage_before_the_stop(errors[0])
    if mode == "garbage" and not garbage_seen:
        print("garbage: none went out 100 ms or more before the stop")
    if mode == "silent" or (not paused_first and (mode == "close" or garbage_seen)):
        assert ("omnical: note: against `omnical twin serve`" in err) == (mode == "silent"), err
    if garbage_seen:
        assert "none valid" in errors[0], err
    partial = read_bag(tmp_path / "run.partial")
    assert partial.has("/cmd_vel") and partial.has("/odom")
    assert not (tmp_path / "run").exists()
    cmd = partial.topic("/cmd_vel")
    odom_end = int(np.asarray(partial.topic("/odom").t_ns)[-1])
    moving = np.asarray(cmd["vx_mps"]) != 0.0
    last_moving = int(np.asarray(cmd.t_ns)[moving][-1])
    assert (last_moving - odom_end) / 1e9 <= STOP_WITHIN_S  # the bag says the same


def test_run_goes_on_without_the_hedgehog_and_marks_the_gap(tmp_path: Path) -> None:
    k = 2.0  # the 5-s move in 2.5 s; the vehicle controller's limit SCALED_STALL_S of wall time
    with (
        TwinDeviceServer(
            ROBOT, load_twin("ideal", ROBOT), config=DeviceConfig(time_scale=k)
        ) as server,
        Relay(server.hedge_path) as hedge_relay,
        Relay(server.vehicle_path) as relay,
    ):
        proc = _run(tmp_path, relay.path, hedge_relay.path, "--time-scale", f"{k:g}")
        _when_moving(relay, proc)
        time.sleep(0.5)
        hedge_relay.fail("silent")
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    warning = [line for line in err.splitlines() if line.startswith("omnical: warning:")]
    assert len(warning) == 1 and f"hedgehog on {hedge_relay.path}" in warning[0], err
    assert "odometry alone" in warning[0]
    run = read_bag(tmp_path / "run.mcap")
    events = [json.loads(str(t)) for t in run.topic("/omnical/events")["text"]]
    gaps = [e for e in events if e.get("omnical") == "gap"]
    assert [g["edge"] for g in gaps] == ["start", "end"]
    assert gaps[0]["device"] == f"hedgehog on {hedge_relay.path}"


def test_campaign_stops_when_the_hedgehog_fails(tmp_path: Path) -> None:
    """The campaign needs the hedgehog: garbage from it stops the robot (exit 4, one line naming
    it), and the stopped run is kept. On a x2 clock (the limits SCALED_STALL_S of wall time): the
    last moving command within two such limits of the last good packet (the limit, and as much
    again for a loaded machine to schedule the driver: the stop is the subject, not its
    millisecond; the 0.5-s bound of the robot's own clock is tests/drivers/test_watchdog.py's)."""
    k = 2.0
    config = DeviceConfig(time_scale=k)
    with TwinDeviceServer(ROBOT, load_twin("default", ROBOT), config=config) as server:
        with Relay(server.hedge_path) as hedge_relay, Relay(server.vehicle_path) as relay:
            proc = subprocess.Popen(
                _omnical(
                    "calibrate", "campaign", "--robot", f"serial:{relay.path}",
                    "--hedge", f"serial:{hedge_relay.path}", "--yes", "--no-figures",
                    "--time-scale", f"{k:g}", "--out", str(tmp_path / "cal"),
                ),
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                stdin=subprocess.DEVNULL,
            )  # fmt: skip
            _when_moving(relay, proc, timeout_s=60.0)
            time.sleep(0.5)
            hedge_relay.fail("garbage")
            _, err = proc.communicate(timeout=60)
            assert hedge_relay.last_forwarded is not None
            late = relay.moving_after(hedge_relay.last_forwarded)
        assert server.last_command == (0.0, 0.0, 0.0)
    print(f"campaign: moving commands {late * 1e3:.0f} ms after the last good hedgehog packet")
    assert proc.returncode == EXIT_SAFETY_STOP, err
    assert late <= 2 * SCALED_STALL_S
    errors = [line for line in err.splitlines() if line.startswith("omnical: error:")]
    assert len(errors) == 1 and f"hedgehog on {hedge_relay.path}" in errors[0], err
    assert "none valid" in errors[0] and "Traceback" not in err
    assert not (tmp_path / "cal").exists()  # no campaign under the final name
    kept = sorted((tmp_path / "cal.partial" / "recordings").iterdir())  # the stopped run
    assert [p.name for p in kept] == ["iter1-rotation-stopped"], kept
    stopped = read_bag(kept[0])
    assert stopped.has("/cmd_vel") and stopped.has("/beacon_raw_distance")
