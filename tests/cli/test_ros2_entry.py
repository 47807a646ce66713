"""``--robot ros2`` re-executes for the ROS 2 wheels' library path before the command starts, so
nothing it prints (``--monitor``'s line) is said twice (review of issue 25/26's merge)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "ros2"))
from ros2_env import needs_ros2, omnical_command, private_domain_id, ros_env


@needs_ros2
@pytest.mark.parametrize("robot", [["--robot", "ros2"], ["--robot=ros2"]])
def test_the_monitor_line_is_said_once(robot: list[str], tmp_path: Path) -> None:
    env = ros_env(private_domain_id(f"entry{robot[0]}"))
    done = subprocess.run(
        omnical_command(
            "run", "tour", "-o", str(tmp_path / "x.mcap"), *robot, "--hedge", "none", "--yes",
            "--monitor", "127.0.0.1:9",
        ),
        env=env, capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    said = done.stdout + done.stderr
    assert done.returncode == 2, said  # no robot on this private domain: no /odom
    assert "/odom" in said, said
    assert said.count("streaming to the monitor") == 1, said
    assert "Traceback" not in said
