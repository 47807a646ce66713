"""The abort key of serial runs: ``q`` on the controlling terminal stops the robot like Ctrl-C."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from omnical.bags.bag import read_bag
from omnical.robot.loader import load_robot
from omnical.services.hil import abort_keys
from omnical.twin.device import DeviceConfig, TwinDeviceServer
from omnical.twin.params import load_twin

ROBOT = load_robot("rosy-mecanum")


def test_no_terminal_no_watch() -> None:
    # under pytest stdin is not the controlling terminal: the watch stays off
    with abort_keys() as watch:
        assert watch is None


@pytest.mark.alone  # wall clock on pseudo-terminals: see pyproject.toml
def test_q_on_the_terminal_stops_a_serial_run(tmp_path: Path) -> None:
    """On a x2 clock: its limits are 1 s of wall time (omnical.services.hil.SCALED_STALL_S),
    so a loaded machine's stall of the served device does not end the run before the key does
    (on the robot's own clock, 0.15 s: exit 4, not 130)."""
    k = 2.0
    script = tmp_path / "long.yaml"
    script.write_text("name: long\nsteps:\n  - move: {vx_mps: 0.2, duration_s: 20.0}\n")
    master, slave = os.openpty()
    # the child: a session of its own (start_new_session) whose controlling terminal is the pty
    # (a session leader opening a terminal acquires it), as omnical in a terminal window
    child = (
        "import os; os.close(os.open(os.ttyname(0), os.O_RDWR)); "
        "from omnical.cli.main import main; main()"
    )
    config = DeviceConfig(time_scale=k)
    with TwinDeviceServer(ROBOT, load_twin("ideal", ROBOT), config=config) as server:
        proc = subprocess.Popen(
            [
                sys.executable, "-c", child,
                "run", str(script), "--robot", f"serial:{server.vehicle_path}",
                "--hedge", f"serial:{server.hedge_path}", "--beacons", "default", "--yes",
                "--margin", "-100", "--time-scale", f"{k:g}", "--out", str(tmp_path / "run.mcap"),
            ],
            stdin=slave, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            start_new_session=True,
        )  # fmt: skip
        os.close(slave)
        try:
            deadline = time.monotonic() + 30
            while server.last_command != (0.2, 0.0, 0.0) and time.monotonic() < deadline:
                time.sleep(0.05)
            if server.last_command != (0.2, 0.0, 0.0):
                ended = proc.poll() is not None
                said = proc.communicate(timeout=5)[1] if ended else "(still running)"
                pytest.fail(f"the run never started: {said}")
            time.sleep(0.25)
            os.write(master, b"q")
            _, err = proc.communicate(timeout=20)
        finally:
            if proc.poll() is None:
                proc.kill()
            os.close(master)
        assert proc.returncode == 130, err
        assert server.last_command == (0.0, 0.0, 0.0)
    assert "kept the partial run" in err and "Traceback" not in err
    partial = read_bag(tmp_path / "run.partial")
    assert partial.has("/cmd_vel") and partial.has("/odom")
