"""Loading rclpy: the wheels' library folders found, a library caller told what to export instead
of being re-executed, and a sourced ROS 2 (its path already set) never re-executed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from ros2_env import needs_ros2

from omnical.errors import ConfigError
from omnical.ros2.runtime import REEXEC_GUARD, ensure_ros_environment, wheel_library_dirs

pytestmark = needs_ros2

CHECK = (
    "import os, sys; from omnical.ros2.runtime import ensure_ros_environment, import_rclpy; "
    "ensure_ros_environment(); import_rclpy(); from nav_msgs.msg import Odometry; "
    f"print('guard', os.environ.get({REEXEC_GUARD!r}), 'pid', os.getpid())"
)


def test_the_wheels_library_folders_are_found() -> None:
    dirs = wheel_library_dirs()
    if not dirs:
        pytest.skip("rclpy is not from the PyPI wheels here (a system ROS 2)")
    assert Path(dirs[0], "librcl_interfaces__rosidl_typesupport_c.so").exists()
    assert any(Path(d).name.startswith("ros_rclpy") for d in dirs)


def test_a_library_caller_is_told_what_to_export(monkeypatch: pytest.MonkeyPatch) -> None:
    if not wheel_library_dirs():
        pytest.skip("rclpy is not from the PyPI wheels here (a system ROS 2)")
    monkeypatch.setenv("LD_LIBRARY_PATH", "")
    with pytest.raises(ConfigError, match="export LD_LIBRARY_PATH="):
        ensure_ros_environment(reexec=False)


def test_a_command_re_executes_once_and_a_set_path_is_kept() -> None:
    env = {k: v for k, v in os.environ.items() if k != REEXEC_GUARD}
    env.pop("LD_LIBRARY_PATH", None)
    done = subprocess.run(
        [sys.executable, "-c", CHECK],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    expected = "1" if wheel_library_dirs() else "None"
    assert done.stdout.split()[:2] == ["guard", expected]
    # as after sourcing a ROS 2 install: the library path is set, nothing is re-executed
    env["LD_LIBRARY_PATH"] = os.pathsep.join(wheel_library_dirs())
    done = subprocess.run(
        [sys.executable, "-c", CHECK],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split()[:2] == ["guard", "None"]
