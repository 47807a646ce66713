"""``omnical ros2 twin --world``: the twin's footprint against the floor plan's walls. A start in
a wall is refused before anything starts; driving into one ends the twin with the same line as
``simulate --world`` (exit 3): it has no contact model (a new user drove it through a wall, its
/scan all inf outside the map, and nothing was said)."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import pytest
from ros2_env import PROBE, RosProcess, needs_ros2, omnical_command, private_domain_id, ros_env

pytestmark = [needs_ros2, pytest.mark.alone]  # wall clock, two processes: see pyproject.toml


def _twin_file(folder: Path, x_m: float, y_m: float, yaw_rad: float) -> Path:
    path = folder / "twin.yaml"
    path.write_text(f"start_pose_map: [{x_m}, {y_m}, {yaw_rad}]\n", encoding="utf-8")
    return path


def test_a_start_in_a_wall_is_refused_before_the_twin_starts(tmp_path: Path) -> None:
    done = subprocess.run(
        omnical_command("ros2", "twin", "--world", "lab-8x6",
                        "--twin", str(_twin_file(tmp_path, 0.05, 3.0, 0.0))),
        env=ros_env(private_domain_id("walls-start")), capture_output=True, text=True,
        timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert done.stdout == ""  # no hedgehog line: nothing was started
    said = (
        "omnical: error: the twin's start (0.05, 3) m puts the robot in a wall of lab-8x6 or "
        "outside it: give a free start_pose_map in the --twin file"
    )
    assert done.stderr.strip().splitlines() == [said]


def test_driving_into_a_wall_ends_the_twin_there(tmp_path: Path) -> None:
    # 0.7 m from the room's west wall facing it: the 0.6-m footprint touches it at x < 0.4 m;
    # the probe drives 0.4 m/s for 2.5 s
    env = ros_env(private_domain_id("walls-drive"))
    probe = RosProcess(
        [sys.executable, str(PROBE), "--vx", "0.4", "--rest-s", "0.5", "--drive-s", "2.5",
         "--after-s", "0.5", "--wait", "/odom"],
        env,
    )  # fmt: skip
    twin = None
    try:
        assert probe.readline(30.0).strip() == "ready", probe.stop()
        twin = RosProcess(
            omnical_command("ros2", "twin", "--world", "lab-8x6",
                            "--twin", str(_twin_file(tmp_path, 0.7, 3.0, math.pi))),
            env, priority=True,
        )  # fmt: skip
        assert twin.readline(30.0).startswith("hedgehog: "), twin.stop()
        status = twin.proc.wait(timeout=60)
        _, _, err = twin.stop()
    finally:
        probe.stop()
        if twin is not None:
            twin.stop()
    assert status == 3, err
    line = next(line for line in err.splitlines() if "collision" in line)
    m = re.match(r"omnical: collision: the footprint touches an occupied cell of lab-8x6 "
                 r"at x=([\d.]+) m, y=([\d.]+) m, yaw=([\d.]+)° after [\d.]+ s: ", line)  # fmt: skip
    assert m is not None, line
    # the wall's edge: x = 0.40 m (a pose of the 50-Hz truth, 8 mm apart at 0.4 m/s)
    assert 0.38 <= float(m[1]) <= 0.41 and float(m[2]) == pytest.approx(3.0, abs=0.05), line
    assert "the twin stops there (it has no contact model" in line
    assert "Traceback" not in err
