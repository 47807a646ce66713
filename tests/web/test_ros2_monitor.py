"""``omnical ros2 twin --monitor PORT`` streams the twin's ``/ground_truth`` to ``omnical monitor``.

Two processes (the monitor, the ROS 2 twin on a private domain, tests/ros2/ros2_env.py); wall
clock, so ``alone``; a page's socket reads the frames the monitor serves.
"""

from __future__ import annotations

import importlib.util
import time
from pathlib import Path
from typing import Any

import pytest
from monitor_procs import page_frames, start_monitor

from omnical.ros2.runtime import rclpy_available
from omnical.web.wsclient import WebSocketClient


def _ros2_env() -> Any:
    """tests/ros2/ros2_env.py (another test directory's helper, by its path)."""
    path = Path(__file__).parents[1] / "ros2" / "ros2_env.py"
    spec = importlib.util.spec_from_file_location("ros2_env", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.alone
@pytest.mark.skipif(not rclpy_available(), reason="the [ros2] extra is not installed")
def test_ros2_twin_streams_its_ground_truth_to_the_monitor() -> None:
    env = _ros2_env()
    mon = start_monitor()
    twin = None
    try:
        domain = env.private_domain_id(__name__)
        twin = env.RosProcess(
            env.omnical_command("ros2", "twin", "--monitor", str(mon.port)), env.ros_env(domain)
        )
        page = WebSocketClient.connect("127.0.0.1", mon.port, "/ws")
        page.sock.settimeout(5)
        truth: dict[str, Any] = {}
        source = ""
        deadline = time.monotonic() + 60  # ROS 2 starts in a re-executed process
        while not (truth and source) and time.monotonic() < deadline and twin.proc.poll() is None:
            for frame in page_frames(page):
                if frame["s"] == "truth":
                    truth = frame["d"]
                elif frame["s"] == "source":
                    source = frame["d"]["source"]
        page.close()
        assert source == "omnical ros2 twin"
        assert truth["x"] and abs(truth["t"][-1] - time.time()) < 10  # wall-clock stamped
        status, _, err = twin.stop()
        twin = None
        assert status == 130 and "Traceback" not in err, err  # SIGINT
    finally:
        if twin is not None:
            twin.stop()
        mon.proc.stop()
