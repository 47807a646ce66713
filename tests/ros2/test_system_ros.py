"""A sourced system ROS 2 (a Jetson's): rclpy from its prefix, no wheels, nothing re-executed.

The layout is simulated from the wheels (no system ROS here): ``opt/ros/jazzy`` with the ROS
Python packages under ``lib/python3.X/site-packages`` and every ROS library in ``lib``, put on
PYTHONPATH, LD_LIBRARY_PATH and AMENT_PREFIX_PATH as ``setup.bash`` does, and omnical run by the
base interpreter with the venv's other packages (a venv made with --system-site-packages and
installed without the extra).
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from ros2_env import RosProcess, needs_ros2, private_domain_id, ros_env

from omnical.ros2.runtime import REEXEC_GUARD, wheel_library_dirs

pytestmark = [
    needs_ros2,
    pytest.mark.skipif(not wheel_library_dirs(), reason="rclpy is a system ROS 2's here already"),
]

PYTHON = f"python{sys.version_info.major}.{sys.version_info.minor}"
OMNICAL = "from omnical.cli.entry import main; main()"
PROBE = """
import json, os, sys
from omnical.ros2.runtime import ensure_ros_environment, import_rclpy, wheel_library_dirs
ensure_ros_environment()  # with a sourced ROS 2: nothing to do, never an exec
rclpy = import_rclpy()
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
rclpy.init()
node = rclpy.create_node("system_ros_probe")
got = []
node.create_subscription(Odometry, "/odom", got.append, 10)
wait_s = float(sys.argv[1])
executor = SingleThreadedExecutor()
executor.add_node(node)
import time
end = time.monotonic() + wait_s
while time.monotonic() < end and not got:
    executor.spin_once(timeout_sec=0.05)
print(json.dumps({
    "rclpy": rclpy.__file__, "wheel_dirs": wheel_library_dirs(), "node": node.get_name(),
    "reexecuted": os.environ.get(sys.argv[2]), "pid": os.getpid(),
    "odom": [got[0].header.frame_id, got[0].child_frame_id] if got else None,
}))
"""


@dataclass(frozen=True)
class SourcedRos:
    """A simulated ``source /opt/ros/jazzy/setup.bash`` and the interpreter to run omnical."""

    prefix: Path
    python: str
    env: dict[str, str]

    def run(self, *args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [self.python, *args],
            env=self.env,
            capture_output=True,
            text=True,
            timeout=timeout_s,
            check=False,
        )


def _ros_top_levels() -> set[str]:
    """The site-packages entries the ROS 2 wheels installed."""
    tops: set[str] = set()
    for dist in importlib.metadata.distributions():
        if (dist.metadata["Name"] or "").lower().startswith("ros-"):
            tops.update(Path(f).parts[0] for f in dist.files or [] if Path(f).parts[:1] != ("..",))
    return tops


@pytest.fixture(scope="module")
def sourced(tmp_path_factory: pytest.TempPathFactory) -> SourcedRos:
    root = tmp_path_factory.mktemp("system-ros")
    prefix = root / "opt" / "ros" / "jazzy"
    ros_site = prefix / "lib" / PYTHON / "site-packages"
    other_site = root / "venv-site-packages"  # omnical's own dependencies, without ROS
    ros_site.mkdir(parents=True)
    other_site.mkdir()
    site = Path(sys.prefix) / "lib" / PYTHON / "site-packages"
    ros = _ros_top_levels()
    for entry in site.iterdir():
        if entry.name.startswith("ros_wheels_bootstrapper"):
            continue  # the wheels' own re-execution: not in a system ROS 2
        if entry.name.startswith("ros_") and entry.name.endswith(".libs"):
            for lib in entry.iterdir():  # a system ROS 2 keeps its libraries in <prefix>/lib
                if not (prefix / "lib" / lib.name).exists():
                    (prefix / "lib" / lib.name).symlink_to(lib)
        elif entry.name in ros:
            (ros_site / entry.name).symlink_to(entry)
        elif not entry.name.endswith(".pth") and not entry.name.startswith("__editable__"):
            (other_site / entry.name).symlink_to(entry)
    for lib in (Path(sys.prefix) / "lib").iterdir():
        if ".so" in lib.name:
            (prefix / "lib" / lib.name).symlink_to(lib)
    (prefix / "share").symlink_to(Path(sys.prefix) / "share")  # the ament index
    env = ros_env(private_domain_id(__name__))
    for key in (REEXEC_GUARD, "_ROS_WHEELS_BOOTSTRAP_COMPLETE", "VIRTUAL_ENV"):
        env.pop(key, None)
    src = Path(__file__).resolve().parents[2] / "src"
    env |= {
        "PYTHONPATH": os.pathsep.join(map(str, (ros_site, other_site, src))),
        "LD_LIBRARY_PATH": str(prefix / "lib"),
        "AMENT_PREFIX_PATH": str(prefix),
        "ROS_DISTRO": "jazzy",
        "ROS_VERSION": "2",
        "ROS_PYTHON_VERSION": "3",
    }
    python = str(Path(sys.base_prefix) / "bin" / PYTHON)
    return SourcedRos(prefix, python, env)


def test_rclpy_loads_from_the_sourced_prefix_and_ros2_env_sets_nothing(
    sourced: SourcedRos,
) -> None:
    done = sourced.run("-c", PROBE, "0", REEXEC_GUARD)
    assert done.returncode == 0, done.stderr[-2000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["rclpy"].startswith(str(sourced.prefix))  # not the venv's wheels
    assert report["wheel_dirs"] == [] and report["reexecuted"] is None
    assert report["node"] == "system_ros_probe"
    env_line = sourced.run("-c", OMNICAL, "ros2", "env")
    assert env_line.returncode == 0, env_line.stderr
    assert env_line.stdout == "" and "nothing to set" in env_line.stderr


@pytest.mark.alone
def test_ros2_twin_runs_on_the_sourced_ros_without_re_executing(sourced: SourcedRos) -> None:
    """The command path (entry.py's early re-execution check, the command's own, rclpy, the
    node, the message packages) on a sourced ROS 2: /odom reaches a probe of the same layout."""
    twin = RosProcess([sourced.python, "-c", OMNICAL, "ros2", "twin"], sourced.env)
    try:
        line = twin.readline(30.0)
        assert line.startswith("hedgehog: "), (line, twin.stop())
        environ = Path(f"/proc/{twin.pid}/environ").read_bytes().split(b"\0")
        assert not any(v.startswith(REEXEC_GUARD.encode() + b"=") for v in environ)
        probe = sourced.run("-c", PROBE, "10", REEXEC_GUARD, timeout_s=60)
    finally:
        status, _, err = twin.stop()
    assert probe.returncode == 0, probe.stderr[-2000:]
    assert json.loads(probe.stdout.strip().splitlines()[-1])["odom"] == ["odom", "base_link"]
    assert status == 130 and "Traceback" not in err, err
