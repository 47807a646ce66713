"""``--robot ros2`` re-executes for the ROS 2 wheels' library path before the command starts, so
nothing it prints (``--monitor``'s line) is said twice (review of issue 25/26's merge)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parents[1] / "ros2"))
from ros2_env import needs_ros2, omnical_command, private_domain_id, ros_env


@needs_ros2
def test_the_monitor_line_is_said_once(tmp_path: Path) -> None:
    """Both spellings of the option, side by side (each waits ≈ 4.5 s for a robot's /odom on
    its own private domain, where there is none)."""
    procs = {}
    for i, robot in enumerate((["--robot", "ros2"], ["--robot=ros2"])):
        procs[robot[0]] = subprocess.Popen(
            omnical_command(
                "run", "tour", "-o", str(tmp_path / f"x{i}.mcap"), *robot, "--hedge", "none",
                "--yes", "--monitor", "127.0.0.1:9",
            ),
            env=ros_env(private_domain_id(f"entry{robot[0]}")),
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
    try:
        for spelling, proc in procs.items():
            said, _ = proc.communicate(timeout=60)
            assert proc.returncode == 2, (spelling, said)  # no robot on this domain: no /odom
            assert "/odom" in said, said
            assert said.count("streaming to the monitor") == 1, said
            assert "Traceback" not in said
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
