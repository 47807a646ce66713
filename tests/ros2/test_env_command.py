"""``omnical ros2 env``: the line a user evals so that their own rclpy program loads the PyPI
wheels (without it: ``librcl_action.so`` not found); a corrected JointState's frames and
covariances, computed in such a program."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from ros2_env import HERE, needs_ros2, omnical_command, private_domain_id, ros_env

from omnical.calibration.factors_io import write_factors
from omnical.kinematics.correction import CorrectionFactors
from omnical.ros2.runtime import library_path_line, wheel_library_dirs

pytestmark = needs_ros2
USER_NODE = HERE / "ros2_user_node.py"
CREATE_NODE = "import rclpy; rclpy.init(); n = rclpy.create_node('probe'); print(n.get_name())"


def plain_env() -> dict[str, str]:
    """A user's shell: a private domain, no library path set by omnical."""
    env = ros_env(private_domain_id(__name__))
    env.pop("LD_LIBRARY_PATH", None)
    for key in ("OMNICAL_ROS2_LIBRARY_PATH_SET", "_ROS_WHEELS_BOOTSTRAP_COMPLETE"):
        env.pop(key, None)
    return env


def in_shell(script: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["bash", "-c", script], env=env, capture_output=True, text=True, timeout=120, check=False
    )


def quoted(argv: list[str]) -> str:
    import shlex

    return " ".join(shlex.quote(a) for a in argv)


def test_the_line_puts_the_wheels_first_and_keeps_the_rest() -> None:
    dirs = wheel_library_dirs()
    line = library_path_line("/opt/mine:" + (dirs[0] if dirs else "/x"))
    if not dirs:
        assert line is None
        return
    assert line is not None
    parts = line.split(":")
    assert parts[: len(dirs)] == dirs and parts[len(dirs)] == "/opt/mine"
    assert len(parts) == len(dirs) + 1  # a wheel folder already there is not repeated


@pytest.mark.skipif(not wheel_library_dirs(), reason="rclpy from a system ROS 2: nothing to set")
def test_without_the_line_a_users_rclpy_does_not_load() -> None:
    done = in_shell(quoted([sys.executable, "-c", CREATE_NODE]), plain_env())
    assert done.returncode != 0
    assert "ImportError" in done.stderr and ".so" in done.stderr, done.stderr[-500:]


@pytest.mark.skipif(not wheel_library_dirs(), reason="rclpy from a system ROS 2: nothing to set")
def test_with_the_line_a_users_program_creates_a_node(tmp_path: Path) -> None:
    factors = tmp_path / "factors.yaml"
    sigma = CorrectionFactors(0.002, 0.003, 0.004, 0.001, 0.001, 0.002, 0.002)
    write_factors(factors, CorrectionFactors.seed000_table2(), sigma)
    script = (
        f'eval "$({quoted(omnical_command("ros2", "env"))})" && '
        f"{quoted([sys.executable, str(USER_NODE), str(factors)])}"
    )
    done = in_shell(script, plain_env())
    assert done.returncode == 0, done.stderr[-2000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["node"] == "a_users_node"
    # the corrected odometry's child frame is its TF's (odom → base_link_calibrated)
    assert (report["frame_id"], report["child_frame_id"]) == ("odom", "base_link_calibrated")
    pose = report["pose_covariance"]
    twist = report["twist_covariance"]
    # z, roll, pitch: not observed by wheels (1e6, as the driver's /odom); x, y, yaw: the factors'
    assert [pose[7 * i] for i in (2, 3, 4)] == [1e6, 1e6, 1e6]
    assert [twist[7 * i] for i in (2, 3, 4)] == [1e6, 1e6, 1e6]
    assert all(0.0 < pose[7 * i] < 1.0 for i in (0, 1, 5)), pose
    assert all(0.0 < twist[7 * i] < 1.0 for i in (0, 1, 5)), twist


def test_env_says_nothing_to_set_or_prints_one_export() -> None:
    done = subprocess.run(
        omnical_command("ros2", "env"), capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 0, done.stderr
    if wheel_library_dirs():
        assert done.stdout.startswith("export LD_LIBRARY_PATH=")
        assert done.stdout.count("\n") == 1
    else:
        assert done.stdout == "" and "nothing to set" in done.stderr
