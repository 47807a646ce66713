"""How ``omnical ros2 twin`` takes a /cmd_vel message (in process, no ROS 2 needed): Twist or
TwistStamped by the configuration, a non-finite command ignored, each one counted."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from omnical.errors import ConfigError
from omnical.robot.loader import load_robot
from omnical.ros2.twin_node import RosTwin, TwinNodeConfig
from omnical.twin.params import load_twin


def twist(vx: float, vy: float, wz: float) -> SimpleNamespace:
    return SimpleNamespace(
        linear=SimpleNamespace(x=vx, y=vy, z=0.0), angular=SimpleNamespace(x=0.0, y=0.0, z=wz)
    )


def node(stamped: bool) -> RosTwin:
    robot = load_robot("rosy-mecanum")
    return RosTwin(robot, load_twin("ideal", robot), config=TwinNodeConfig(cmd_vel_stamped=stamped))


def test_a_twist_reaches_the_device_server() -> None:
    twin = node(stamped=False)
    twin._on_cmd_vel(twist(0.3, -0.1, 0.5), {"source_timestamp": 0})
    assert twin.server._external == [(0.3, -0.1, 0.5, None)]
    assert twin.commands_received == 1


def test_a_stamped_twist_is_unwrapped() -> None:
    twin = node(stamped=True)
    twin._on_cmd_vel(SimpleNamespace(header=None, twist=twist(0.2, 0.0, -1.0)), None)
    assert twin.server._external == [(0.2, 0.0, -1.0, None)]


def test_a_non_finite_command_is_no_command() -> None:
    twin = node(stamped=False)
    twin._on_cmd_vel(twist(math.nan, 0.0, 0.0), None)
    twin._on_cmd_vel(twist(0.0, math.inf, 0.0), None)
    assert twin.server._external == []
    assert twin.commands_received == 0


def test_the_timeout_is_checked() -> None:
    with pytest.raises(ConfigError, match="timeout"):
        TwinNodeConfig(cmd_timeout_s=0.0)
    assert node(stamped=False).server.config.watchdog_s == 0.5
    assert node(stamped=False).server.config.vehicle_port is False


def test_a_command_is_timed_by_its_source_timestamp() -> None:
    """Sent 2 s after the twin started (by the sender's wall clock), on a x4 clock: applied
    at 8 s of the twin's device time, if the loop has not simulated past it."""
    robot = load_robot("rosy-mecanum")
    twin = RosTwin(robot, load_twin("ideal", robot), config=TwinNodeConfig(time_scale=4.0))
    server = twin.server
    server.t0_mono, server.t0_wall_ns = 100.0, 1_000_000_000_000
    twin._on_cmd_vel(twist(0.1, 0.0, 0.0), {"source_timestamp": server.t0_wall_ns + 2 * 10**9})
    assert server._external == [(0.1, 0.0, 0.0, pytest.approx(108.0))]
