"""A stalled page does not slow a live twin run (issue 26): the run's loop timed with no page on
the monitor, then with three (two chromium pages and a client that never reads).

The live twin run: the twin served on pseudo-terminals in this process (as ``twin serve``), a
script run on it over serial (as ``omnical run --robot serial:...``), teed to an ``omnical
monitor`` subprocess, the served twin's own feed beside it. Wall-clock timing: ``alone``. The
bound is generous (the median period within 5 %, the run not 5 % behind its schedule;
bench/bench_monitor.py measures the 1 % target): a run slowed by the monitor ends late.
"""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from monitor_procs import figures, new_page, start, start_monitor, wait_until

from omnical.experiment.rig import run_script_on
from omnical.experiment.script import parse_script
from omnical.recording.recording import RecordingBuilder
from omnical.recording.topics import ODOM
from omnical.robot.loader import load_robot
from omnical.services.hil import SCALED_STALL_S, HostClock, SerialRig, serial_devices
from omnical.twin.device import DeviceConfig, TwinDeviceServer
from omnical.twin.params import default_twin
from omnical.web.device_feed import feed_device
from omnical.web.protocol import MonitorTarget
from omnical.web.tee import MonitorLink, MonitorTee
from omnical.web.wsclient import WebSocketClient

ROBOT = load_robot("rosy-mecanum")
SCALE = 2.0
"""The run's clock (and the device's) twice the wall clock: its silence limits are then
SCALED_STALL_S of wall time, which a loaded test machine's stalls stay within (at 1, the
robot's 0.15 s stops the run: what a loaded machine does, not the monitor)."""


def _live_run(port: int, seconds: float) -> tuple[np.ndarray, Any, MonitorLink]:
    """The runner's tick times (s), the recording and the run's link."""
    config = DeviceConfig(time_scale=SCALE)
    server = TwinDeviceServer(ROBOT, default_twin(ROBOT), config=config)
    server.start()
    target = MonitorTarget("127.0.0.1", port)
    feed_link = MonitorLink(target, "twin serve", reset=False).start()
    stop = threading.Event()
    feeder = threading.Thread(target=feed_device, args=(server, feed_link, stop), daemon=True)
    feeder.start()
    link = MonitorLink(target, "run").start()
    script = parse_script(
        {"name": "t", "steps": [{"move": {"vx_mps": 0.2, "vy_mps": 0.1, "duration_s": seconds}}]},
        ROBOT.limits,
    )
    ticks: list[float] = []
    builder = RecordingBuilder()
    clock = HostClock(SCALE)
    try:
        with serial_devices(
            server.vehicle_path, 115200, server.hedge_path, 115200, ROBOT, clock,
            host_watchdog_s=SCALED_STALL_S * SCALE, say=lambda _: None,
        ) as (driver, hedge):  # fmt: skip
            rig = SerialRig(driver, hedge, clock, abort_key=False, flush_every_s=0.05)
            log = run_script_on(
                rig, script, MonitorTee(builder, link), lead_in_s=0.3, tail_s=0.1,
                on_tick=lambda _e, _t: ticks.append(time.perf_counter()),
            )  # fmt: skip
    finally:
        stop.set()
        feeder.join(2.0)
        link.close()
        feed_link.close()
        server.stop()
    assert not log.interrupted
    return np.array(ticks), builder.build(), link


@pytest.mark.alone
def test_a_stalled_page_does_not_slow_a_live_twin_run(browser: Any) -> None:
    mon = start_monitor("--beacons", "default")
    try:
        ticks0, rec0, _ = _live_run(mon.port, 6.0)
        pages = [new_page(browser, mon.url) for _ in range(2)]
        for page, _ in pages:
            wait_until(page, "m.connected", 10)
        stalled = WebSocketClient.connect("127.0.0.1", mon.port, "/ws")
        stalled.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        ticks3, rec3, link = _live_run(mon.port, 6.0)
        # The loop keeps absolute wake times: a stall of the machine at the start is caught up
        # by shorter periods after it (a mean below the period), so the period is the median,
        # and a run the monitor slowed is one that ends behind its schedule.
        period = float(np.median(np.diff(ticks0)))
        assert float(np.median(np.diff(ticks3))) == pytest.approx(period, rel=0.05), period
        behind_s = (ticks3[-1] - ticks3[0]) - (len(ticks3) - 1) * period
        assert behind_s < 0.05 * (len(ticks3) - 1) * period, (behind_s, period)
        assert len(ticks3) == len(ticks0)
        assert len(rec3.topic(ODOM)) >= 0.8 * len(rec0.topic(ODOM))  # the run's own record whole
        assert link.sent > 50
        # the healthy pages kept receiving: how much is not the subject (a page that falls
        # behind, as chromium can beside a loaded machine's other work, has its oldest
        # odometry dropped by the server, by design: test_hub); 45 seen at load 4 on 2 cores
        for page, errors in pages:
            f = figures(page)
            assert f["byStream"].get("odom", 0) > 10 and errors == [] and f["errors"] == []
        stalled.sock.close()
    finally:
        mon.proc.stop()


@pytest.mark.alone
def test_the_page_reconnects_within_2_s_after_a_server_restart(browser: Any) -> None:
    with socket.socket() as s:  # a free port to restart on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    mon = start_monitor("--beacons", "default", port=port)
    page, errors = new_page(browser, mon.url)
    try:
        wait_until(page, "m.connects === 1 && m.latched.beacons", 10)
        assert mon.proc.stop() == 130
        wait_until(page, "!m.connected", 5)
        assert page.inner_text("#badge") == "reconnecting"
        mon = start_monitor("--beacons", "default", port=port)
        listening = time.monotonic()
        wait_until(page, "m.connects === 2", 5)
        assert time.monotonic() - listening < 2.0
        assert page.inner_text("#badge") == "live"
        # chromium logs each refused attempt while the server was away; nothing else
        assert [e for e in errors if "ERR_CONNECTION_REFUSED" not in e] == []
        assert figures(page)["errors"] == []
    finally:
        mon.proc.stop()


@pytest.mark.alone
def test_a_serial_run_streams_while_the_robot_moves(browser: Any, tmp_path: Path) -> None:
    """``run --robot serial:... --monitor``: the odometry and the fixes reach the page during
    the run (drained every 50 ms), the progress too; the bag is whole."""
    script = tmp_path / "short.yaml"
    script.write_text(
        "name: short\nsteps:\n  - move: {vx_mps: 0.2, duration_s: 4.0}\n"
        "  - move: {vy_mps: 0.2, duration_s: 4.0}\n"
    )
    mon = start_monitor("--beacons", "default")
    served = start("twin", "serve", "--time-scale", str(SCALE))
    try:
        vehicle = served.wait_for(r"vehicle controller: (\S+)").group(1)
        hedge = served.wait_for(r"hedgehog: (\S+)").group(1)
        page, errors = new_page(browser, mon.url)
        wait_until(page, "m.connected", 10)
        run = start(
            "run", str(script), "--robot", f"serial:{vehicle}", "--hedge", f"serial:{hedge}",
            "--beacons", "default", "--yes", "--time-scale", str(SCALE),
            "--out", str(tmp_path / "r.mcap"), "--monitor", str(mon.port),
        )  # fmt: skip
        wait_until(page, "(m.byStream.odom || 0) > 20 && (m.byStream.fix || 0) > 5", 30)
        assert run.popen.poll() is None  # while the robot still moves
        assert "short" in page.inner_text("#step")
        wait_until(page, "m.state.status && m.state.status.watchdog", 5)  # the run's driver
        assert page.inner_text("#watchdog").startswith("host ")
        assert page.inner_text("#battery") == "12.3 V"
        assert run.popen.wait(60) == 0
        wait_until(page, "(m.byStream.cmd || 0) > 0", 10)  # a serial run's commands: at its end
        assert figures(page)["latched"].get("origin")
        assert errors == []
    finally:
        served.stop()
        mon.proc.stop()
