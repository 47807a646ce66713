"""A stall of ``omnical ros2 twin``'s process does not lengthen a move: a ``/cmd_vel`` sent while
it is stopped is applied at its DDS source timestamp (tests/ros2/ros2_stall_probe.py)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from ros2_env import RosProcess, needs_ros2, omnical_command, private_domain_id, ros_env

pytestmark = [needs_ros2, pytest.mark.alone]  # wall clock, two processes

PROBE = Path(__file__).with_name("ros2_stall_probe.py")


def test_a_zero_command_sent_during_a_stall_stops_the_twin_at_its_send_time() -> None:
    """Stopped 0.35 s around the zero command at 0.2 m/s: applied when it arrived, the move was
    7 cm longer (0.2 m/s × the 0.2 s from the command to SIGCONT, plus the next control tick);
    at its send time, within 1 cm of the same drive without a stall."""
    env = ros_env(private_domain_id(__name__))
    twin = RosProcess(omnical_command("ros2", "twin", "--twin", "ideal"), env)
    try:
        line = twin.readline(30.0)
        assert line.startswith("hedgehog: "), (line, twin.stop())
        probe = RosProcess([sys.executable, str(PROBE), str(twin.pid)], env)
        probe.proc.wait(timeout=60)
        status, out, err = probe.stop()
    finally:
        twin.stop()
    assert status == 0, err
    got = json.loads(out.strip().splitlines()[-1])
    # a stall of the probe (a loaded machine) lengthens its drive as sent: the twin drives on
    # at 0.2 m/s for that long, whenever it applies the commands (measured by the probe)
    longer_m = 0.2 * (got["stalled_s"] - got["plain_s"])
    print(
        f"the same drive: {got['plain_m']:.4f} m, {got['stalled_m']:.4f} m with the stall; "
        f"sent {got['plain_s']:.3f} s and {got['stalled_s']:.3f} s"
    )
    assert got["plain_m"] > 0.3  # it moved
    assert abs(got["stalled_m"] - got["plain_m"] - longer_m) < 0.01, got
