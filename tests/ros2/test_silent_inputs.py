"""Silent inputs said once on stderr, the commands going on: ``ros2 correct --topic /imu`` on an
Imu topic, ``ros2 locate`` on a pty that sends nothing, ``ros2 twin`` given TwistStamped on
/cmd_vel; three processes and one rclpy publisher on a private domain (≈ 8 s)."""

from __future__ import annotations

import os
import select
import sys
import time
from collections.abc import Iterator

import pytest
from ros2_env import RosProcess, needs_ros2, omnical_command, private_domain_id, ros_env

from omnical.calibration.factors_io import write_factors
from omnical.kinematics.correction import CorrectionFactors
from omnical.ros2.runtime import library_path_line
from omnical.ros2.silence import SILENCE_WARN_S

pytestmark = [needs_ros2, pytest.mark.alone]  # wall clock, processes: see pyproject.toml

PUBLISHER = """
import time, rclpy
from geometry_msgs.msg import TwistStamped
from sensor_msgs.msg import Imu
rclpy.init()
node = rclpy.create_node("wrong_types")
imu = node.create_publisher(Imu, "/imu", 10)
cmd = node.create_publisher(TwistStamped, "/cmd_vel", 10)
print("ready", flush=True)
while True:
    imu.publish(Imu())
    cmd.publish(TwistStamped())
    time.sleep(0.1)
"""


def stderr_lines(process: RosProcess, until_s: float, wanted: str) -> list[str]:
    """stderr lines until one contains ``wanted`` or ``until_s`` (monotonic) passes (read from
    the descriptor: the text stream's buffer would hide lines from ``select``)."""
    stream = process.proc.stderr
    assert stream is not None
    fd = stream.fileno()
    data = b""
    while wanted.encode() not in data and time.monotonic() < until_s:
        ready, _, _ = select.select([fd], [], [], max(0.0, until_s - time.monotonic()))
        if not ready:
            break
        chunk = os.read(fd, 65536)
        if not chunk:
            break
        data += chunk
    return data.decode(errors="replace").splitlines(keepends=True)


@pytest.fixture(scope="module")
def said(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, object]]:
    domain = private_domain_id(__name__)
    env = ros_env(domain)
    factors = tmp_path_factory.mktemp("silent") / "factors.yaml"
    write_factors(factors, CorrectionFactors.seed000_table2())
    master, slave = os.openpty()  # a pty nobody writes to: a hedgehog asleep
    user_env = dict(env)
    line = library_path_line()
    if line is not None:
        user_env["LD_LIBRARY_PATH"] = line
    publisher = RosProcess([sys.executable, "-c", PUBLISHER], user_env)
    processes = [publisher]
    try:
        assert publisher.readline(30.0).strip() == "ready", publisher.stop()
        names = ("correct", "locate", "twin")
        argvs = (
            ("ros2", "correct", "--factors", str(factors), "--topic", "/imu"),
            ("ros2", "locate", "--hedge", f"serial:{os.ttyname(slave)}"),
            ("ros2", "twin", "--robot", "rosy-mecanum"),
        )
        started = {
            n: RosProcess(omnical_command(*a), env) for n, a in zip(names, argvs, strict=True)
        }
        processes += started.values()
        wanted = {"correct": "nothing on /imu", "locate": "no byte", "twin": "no /cmd_vel"}
        deadline = time.monotonic() + SILENCE_WARN_S + 25.0
        lines = {n: stderr_lines(p, deadline, wanted[n]) for n, p in started.items()}
        running = {n: p.proc.poll() is None for n, p in started.items()}
        stops = {n: p.stop() for n, p in started.items()}
        yield {"lines": lines, "running": running, "stops": stops, "domain": domain}
    finally:
        for p in processes:
            p.stop()
        os.close(master)
        os.close(slave)


def one(said: dict[str, object], name: str, wanted: str) -> str:
    lines = said["lines"][name]  # type: ignore[index]
    hits = [line for line in lines if wanted in line]
    assert len(hits) == 1, (lines, said["stops"][name])  # type: ignore[index]
    assert said["running"][name], said["stops"][name]  # type: ignore[index]  # it goes on
    status, _, err = said["stops"][name]  # type: ignore[index]
    assert status == 130 and "Traceback" not in err, err
    assert wanted not in err  # said once: not again before the stop
    return str(hits[0])


def test_correct_on_a_topic_of_another_type_names_both_types(said: dict[str, object]) -> None:
    line = one(said, "correct", "nothing on /imu")
    assert f"ROS_DOMAIN_ID {said['domain']}" in line
    assert "published as sensor_msgs/msg/Imu" in line and "nav_msgs/msg/Odometry" in line


def test_locate_on_a_silent_port_names_the_port(said: dict[str, object]) -> None:
    line = one(said, "locate", "no byte")
    assert "/dev/pts/" in line and f"ROS_DOMAIN_ID {said['domain']}" in line


def test_a_stamped_cmd_vel_to_a_twist_twin_is_named(said: dict[str, object]) -> None:
    line = one(said, "twin", "no /cmd_vel")
    assert "geometry_msgs/msg/TwistStamped" in line and "--twist-stamped" in line
