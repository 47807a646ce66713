"""What ``--robot`` / ``--hedge`` name: the twin, a serial port, ROS 2, or a robot description.

:func:`parse_robot_target` and :func:`parse_hedge` read them for every command that can drive a
robot; :func:`live_rig` opens a real one; :func:`load_said_robot` says which description is used.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal, TypeAlias

import typer

from omnical.errors import ConfigError

if TYPE_CHECKING:
    from omnical.cli.serial_options import LiveOptions
    from omnical.robot.description import RobotDescription
    from omnical.services.hil import SerialRig

__all__ = [
    "DEFAULT_MODEL",
    "HedgeTarget",
    "RobotTarget",
    "TwistStamped",
    "check_live_options",
    "live_rig",
    "load_said_robot",
    "parse_hedge",
    "parse_robot_target",
    "topic_name",
]

TwistStamped: TypeAlias = Annotated[
    bool,
    typer.Option(
        "--twist-stamped",
        help="ROS 2: publish /cmd_vel as TwistStamped, not Twist (--robot ros2).",
    ),
]

DEFAULT_MODEL = "rosy-mecanum"
_SERIAL = "serial:"
_TOPIC = "topic:"


@dataclass(frozen=True)
class RobotTarget:
    """The robot a command drives.

    Attributes:
        kind: ``twin`` (in process, simulated time), ``serial`` (a vehicle controller) or
            ``ros2`` (a robot's ROS 2 topics: /cmd_vel, /odom, /imu, /joint_states, /scan).
        model: the robot description: a preset name or a robot YAML path.
        port: the serial device (``serial`` only, else None).
    """

    kind: Literal["twin", "serial", "ros2"]
    model: str
    port: str | None = None

    @property
    def is_serial(self) -> bool:
        """True for a vehicle controller on a serial port."""
        return self.kind == "serial"

    @property
    def is_live(self) -> bool:
        """True for a real robot in wall-clock time (serial or ROS 2), False for the twin."""
        return self.kind != "twin"

    @property
    def where(self) -> str:
        """The robot as the messages name it: "over serial", "over ROS 2", "in process"."""
        return {"serial": "over serial", "ros2": "over ROS 2"}.get(self.kind, "in process")


@dataclass(frozen=True)
class HedgeTarget:
    """The hedgehog: ``twin`` (simulated with the twin), ``serial`` (on ``port``), ``topic`` (a
    ROS 2 topic of positions, geometry_msgs PointStamped or PoseWithCovarianceStamped) or
    ``none``."""

    kind: Literal["twin", "serial", "topic", "none"]
    port: str | None = None
    topic: str | None = None


def _serial_port(option: str, value: str) -> str | None:
    if not value.startswith(_SERIAL):
        return None
    port = value[len(_SERIAL) :]
    if not port:
        msg = f"{option} {value!r}: give the device after 'serial:', e.g. serial:/dev/ttyUSB0"
        raise ConfigError(msg)
    return port


def parse_robot_target(robot: str, model: str | None = None) -> RobotTarget:
    """Parse ``--robot`` (``twin``, ``serial:PORT``, ``ros2``, a preset or a robot YAML) and
    ``--model``.

    Raises:
        ConfigError: an empty port, or ``--model`` with a ``--robot`` that already names the
            robot description.
    """
    port = _serial_port("--robot", robot)
    if port is not None:
        return RobotTarget("serial", model or DEFAULT_MODEL, port)
    if robot in {"twin", "ros2"}:
        return RobotTarget("twin" if robot == "twin" else "ros2", model or DEFAULT_MODEL)
    if robot.startswith("ros2:"):
        msg = f"--robot {robot!r}: give 'ros2' (the topics /cmd_vel, /odom, ... of ROS_DOMAIN_ID)"
        raise ConfigError(msg)
    if model is not None and model != robot:
        msg = (
            f"--robot {robot} already names the robot description; --model {model} applies "
            "only with --robot twin, serial:PORT or ros2"
        )
        raise ConfigError(msg)
    return RobotTarget("twin", robot)


def topic_name(name: str) -> str | None:
    """``name`` as an absolute ROS 2 topic (``odom`` → ``/odom``), None where ROS 2 would
    refuse it (letters, digits and _ between slashes, no part starting with a digit)."""
    import re

    name = name if name.startswith("/") else f"/{name}"
    return name if re.fullmatch(r"(/[A-Za-z_][A-Za-z0-9_]*)+", name) else None


def parse_hedge(hedge: str) -> HedgeTarget:
    """Parse ``--hedge``: ``twin``, ``serial:PORT``, ``topic:/NAME`` (ROS 2) or ``none``.

    Raises:
        ConfigError: anything else, or a topic name ROS 2 would refuse.
    """
    if hedge in {"twin", "none"}:
        return HedgeTarget("twin" if hedge == "twin" else "none")
    if hedge.startswith(_TOPIC):
        name = topic_name(hedge[len(_TOPIC) :])
        if name is None:
            msg = (
                f"--hedge {hedge!r}: give a ROS 2 topic after 'topic:', e.g. topic:/hedge_pos "
                "(letters, digits and _ between slashes)"
            )
            raise ConfigError(msg)
        return HedgeTarget("topic", topic=name)
    port = _serial_port("--hedge", hedge)
    if port is None:
        msg = f"--hedge {hedge!r}: use 'twin', 'serial:PORT', 'topic:/NAME' (ROS 2) or 'none'"
        raise ConfigError(msg)
    return HedgeTarget("serial", port)


def load_said_robot(name_or_path: str | Path) -> RobotDescription:
    """The robot description of a preset or YAML file, and one printed line naming it: what
    the command computes with (a wrong or default robot otherwise goes unnoticed)."""
    from omnical.cli.output import say
    from omnical.robot.loader import available_presets, load_robot

    description = load_robot(name_or_path)
    text = str(name_or_path)
    source = "preset" if text in available_presets() else f"file {text}"
    encoders = description.wheel_encoders
    counts = (
        f", wheel encoders {encoders.counts_per_rev:g} counts/rev"
        if encoders is not None and encoders.counts_per_rev is not None
        else ""
    )
    say(f"robot: {description.name} ({source}{counts})")
    return description


def check_live_options(
    target: RobotTarget, hedge: HedgeTarget, twist_stamped: bool, beacons: object = ""
) -> None:
    """Refuse a hedgehog or an option the robot cannot have; on a ROS 2 robot, make rclpy
    loadable first (this may re-execute the command once: call it before any output).

    Raises:
        ConfigError: another hedgehog than ``twin`` on the twin, ``--hedge twin`` on a real
            robot, a hedgehog topic off ROS 2 or without a beacon map (``beacons`` None:
            ``--beacons`` not given), ``--twist-stamped`` off ROS 2, or ROS 2 not installed.
    """
    if target.is_live and hedge.kind == "twin":
        msg = f"--robot {target.kind}: give --hedge serial:PORT"
        msg += ", topic:/NAME or none" if target.kind == "ros2" else " or none"
        raise ConfigError(msg)
    if hedge.kind == "topic" and target.kind != "ros2":
        msg = f"--hedge topic:{hedge.topic} is a ROS 2 topic: it needs --robot ros2"
        raise ConfigError(msg)
    if hedge.kind == "topic" and beacons is None:
        msg = (
            f"--hedge topic:{hedge.topic} carries positions only: give the beacon map with "
            "--beacons (the paths are checked against its coverage)"
        )
        raise ConfigError(msg)
    if twist_stamped and target.kind != "ros2":
        msg = "--twist-stamped applies to --robot ros2 only"
        raise ConfigError(msg)
    if not target.is_live and hedge.kind != "twin":
        msg = "--robot twin runs the twin's own simulated hedgehog: use --hedge twin"
        raise ConfigError(msg)
    if target.kind == "ros2":
        from omnical.ros2.runtime import ensure_ros_environment

        ensure_ros_environment()


@contextmanager
def live_rig(
    target: RobotTarget,
    hedge: HedgeTarget,
    description: RobotDescription,
    options: LiveOptions,
    *,
    on_warning: Callable[[str], None] | None = None,
    flush_every_s: float = 0.5,
) -> Iterator[SerialRig]:
    """The real robot as a rig on the host clock at ``options.time_scale``, its devices opened
    and checked before anything moves: the vehicle controller on its serial port, or the ROS 2
    robot's topics (its LiDAR if it publishes ``/scan``), with the hedgehog. Leaving stops the
    robot and closes them all. ``flush_every_s``: how often (robot time) the rows reach the
    sink while a script runs."""
    from omnical.cli.output import say
    from omnical.services.hil import HostClock, SerialRig, serial_devices

    clock = HostClock(options.time_scale)
    if target.kind == "serial":
        assert target.port is not None
        with serial_devices(
            target.port, options.baud, hedge.port, options.hedge_baud, description, clock,
            host_watchdog_s=options.host_watchdog_s, say=say,
        ) as (driver, hedgehog):  # fmt: skip
            yield SerialRig(
                driver, hedgehog, clock, on_warning=on_warning, flush_every_s=flush_every_s
            )
        return
    from omnical.ros2.rig import ros2_devices

    with ros2_devices(
        description, clock, hedge_port=hedge.port, hedge_topic=hedge.topic,
        hedge_baud=options.hedge_baud, stamped=options.twist_stamped,
        host_watchdog_s=options.host_watchdog_s, say=say,
    ) as (robot, hedgehog, lidar):  # fmt: skip
        yield SerialRig(
            robot, hedgehog, clock, on_warning=on_warning, lidar=lidar, flush_every_s=flush_every_s
        )
