"""``omnical ros2 map``: a late-joining subscriber gets the map (transient-local), cell for cell."""

from __future__ import annotations

import json
import sys
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
from ros2_env import RosProcess, needs_ros2, omnical_command, private_domain_id, ros_env

from omnical.navigation.map_io import load_map

pytestmark = [needs_ros2, pytest.mark.alone]  # two processes in wall-clock time

LATE_SUBSCRIBER = """
import json, sys, time
from omnical.ros2.runtime import ensure_ros_environment, import_rclpy
ensure_ros_environment()
rclpy = import_rclpy()
from nav_msgs.msg import OccupancyGrid
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
rclpy.init()
node = rclpy.create_node("omnical_test_map_probe")
got = []
qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
node.create_subscription(OccupancyGrid, "/map", got.append, qos)
end = time.monotonic() + 20.0
while not got and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.05)
m = got[0]
print(json.dumps({"width": m.info.width, "height": m.info.height,
                  "resolution": m.info.resolution, "frame": m.header.frame_id,
                  "origin": [m.info.origin.position.x, m.info.origin.position.y],
                  "data": list(m.data)}))
"""


def test_a_late_subscriber_gets_the_map() -> None:
    env = ros_env(private_domain_id(__name__))
    world = Path(str(resources.files("omnical").joinpath("data", "worlds", "lab-8x6.yaml")))
    publisher = RosProcess(omnical_command("ros2", "map", str(world)), env)
    try:
        assert publisher.proc.stderr is not None
        said = publisher.proc.stderr.readline()  # once it has published
        assert "/map" in said, said
        late = RosProcess([sys.executable, "-c", LATE_SUBSCRIBER], env)
        line = late.readline(30.0)
        _, _, late_err = late.stop()
        assert line, late_err
        got = json.loads(line)
    finally:
        status, _, err = publisher.stop()
    grid = load_map(world)
    assert (got["height"], got["width"]) == grid.cells.shape
    assert got["resolution"] == pytest.approx(grid.resolution_m, rel=1e-7)
    assert got["origin"] == pytest.approx(list(grid.origin[:2]))
    assert got["frame"] == "map"
    assert np.array_equal(np.array(got["data"], dtype=np.int8), grid.cells.ravel())
    assert status == 130, err
