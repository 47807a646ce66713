"""``omnical ros2``: the twin as a ROS 2 robot, what omnical knows published on ROS 2 (until
Ctrl-C or SIGTERM), and ``build-tf2-msgs``. Needs the ``[ros2]`` extra (or a sourced system ROS
2); each command re-executes itself once to put the PyPI wheels' libraries on the library path
(docs/ros2.md).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.help_layout import App
from omnical.cli.monitor_options import MonitorOption
from omnical.cli.options import Beacons, Robot, Seed

__all__ = ["app", "build_tf2_msgs", "correct", "env", "locate", "publish_map", "twin"]

app = App(
    name="ros2",
    help="ROS 2: the twin as a ROS 2 robot; calibrated odometry, IPS fixes and maps published.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)

Stamped = Annotated[
    bool,
    typer.Option(
        "--twist-stamped",
        help="/cmd_vel is geometry_msgs/TwistStamped (default: Twist), as --robot ros2 says it.",
    ),
]


@app.command()
def twin(
    robot: Robot = "rosy-mecanum",
    world: Annotated[
        Path | None,
        typer.Option(
            help="Floor plan (map_server YAML, or lab-8x6, warehouse-20x20): /scan from a "
            "simulated LiDAR in it."
        ),
    ] = None,
    twin: Annotated[str, typer.Option(help="Twin YAML, or 'default' / 'ideal'.")] = "default",
    seed: Seed = 0,
    beacons: Beacons = None,
    twist_stamped: Stamped = False,
    cmd_timeout: Annotated[
        float, typer.Option(help="No /cmd_vel for this long (s): the twin is told to stop.")
    ] = 0.5,
    time_scale: Annotated[
        float,
        typer.Option(
            help="Robot seconds per wall second, 0.1–100 (1: real time; > 1 for time-scaled "
            "test campaigns, with the host's hidden --time-scale)."
        ),
    ] = 1.0,
    monitor: MonitorOption = None,
) -> None:
    """Run the digital twin as a ROS 2 robot in real time (and its hedgehog on a pty)."""
    with handled_errors():
        _twin(robot, world, twin, seed, beacons, twist_stamped, cmd_timeout, time_scale, monitor)


def _twin(
    robot: str,
    world: Path | None,
    twin_spec: str,
    seed: int,
    beacons: Path | None,
    stamped: bool,
    cmd_timeout: float,
    time_scale: float,
    monitor: str | None = None,
) -> None:
    import math
    import sys

    from omnical.cli.monitor_options import monitor_link, monitor_target, serve_monitored
    from omnical.errors import ConfigError

    if not (math.isfinite(time_scale) and 0.1 <= time_scale <= 100.0):
        msg = f"--time-scale {time_scale:g}: give robot seconds per wall second from 0.1 to 100"
        raise ConfigError(msg)
    if not (math.isfinite(cmd_timeout) and 0.01 <= cmd_timeout <= 60.0):
        msg = f"--cmd-timeout {cmd_timeout:g}: give seconds from 0.01 to 60"
        raise ConfigError(msg)
    target = monitor_target(monitor)  # a bad --monitor before ROS 2 starts
    from omnical.ros2.runtime import ensure_ros_environment

    ensure_ros_environment()

    from omnical.ips.beacons import load_beacon_map
    from omnical.recording.topics import CMD_VEL, TF
    from omnical.robot.loader import available_presets, load_robot
    from omnical.ros2.twin_node import RosTwin, TwinCollisionError, TwinNodeConfig
    from omnical.twin.params import load_twin

    description = load_robot(robot)
    source = "preset" if robot in available_presets() else f"file {robot}"
    bmap = load_beacon_map(beacons) if beacons is not None else None
    params = load_twin(twin_spec, description, bmap)
    grid = walls = None
    if world is not None:  # read before anything is published
        from omnical.cli.options import twin_start_fix
        from omnical.navigation.inflation import Footprint
        from omnical.navigation.map_io import load_map, resolve_world
        from omnical.twin.world import World, check_start

        world_yaml = resolve_world(world)
        grid = load_map(world_yaml)
        size = description.footprint
        walls = World(grid, Footprint(size.length_m, size.width_m), world_yaml.stem)
        check_start(walls, params.start_pose_map, "the twin's start", twin_start_fix(twin_spec))
    config = TwinNodeConfig(
        cmd_vel_stamped=stamped, cmd_timeout_s=cmd_timeout, time_scale=time_scale
    )
    node = RosTwin(description, params, seed=seed, beacons=bmap, config=config, walls=walls)
    try:
        node.start()  # the odometry flows from here on
        typer.echo(f"robot: {description.name} ({source}), twin: {twin_spec}", err=True)
        # on stdout: the path scripts read
        typer.echo(f"hedgehog: {node.hedge_path}")
        sys.stdout.flush()
        if grid is not None:
            node.attach_world(grid)
        topics = ", ".join(sorted(node.published))
        kind = "TwistStamped" if stamped else "Twist"
        typer.echo(
            f"ROS 2 node {config.node_name}: subscribes {CMD_VEL} ({kind}, "
            f"{cmd_timeout:g} s timeout), publishes {topics}",
            err=True,
        )
        if not node.publishes_tf:
            typer.echo(
                f"omnical: {TF} is not published: tf2_msgs is not installed (`omnical ros2 "
                "build-tf2-msgs` builds it); odom → base_link is in /odom",
                err=True,
            )
        with monitor_link(target, "omnical ros2 twin", reset=False) as link:
            try:
                serve_monitored(node.server, link, bmap, serve=node.serve_forever)
            except TwinCollisionError as err:  # as `simulate --world` ends on one: no result
                from omnical.cli.errors import EXIT_NO_RESULT

                typer.echo(f"omnical: {err}", err=True)
                raise typer.Exit(EXIT_NO_RESULT) from None
    finally:
        node.stop()
        if node.published:  # it ran
            counts = ", ".join(f"{n} {t}" for t, n in sorted(node.published.items()))
            typer.echo(f"received {node.commands_received} {CMD_VEL}; published {counts}", err=True)


@app.command()
def correct(
    factors: Annotated[Path, typer.Option(help="Factors YAML written by `omnical calibrate`.")],
    robot: Robot = "rosy-mecanum",
    source: Annotated[
        str,
        typer.Option(help="What to correct: 'odom' (nav_msgs/Odometry) or 'joint_states'."),
    ] = "odom",
    topic: Annotated[
        str | None, typer.Option(help="Input topic (default: /odom or /joint_states).")
    ] = None,
    monitor: MonitorOption = None,
) -> None:
    """Publish /odom_calibrated: the robot's odometry with the seven factors applied."""
    with handled_errors():
        from omnical.cli.monitor_options import monitor_link, monitor_target
        from omnical.cli.robot_target import topic_name
        from omnical.errors import ConfigError
        from omnical.ros2.runtime import ensure_ros_environment

        target = monitor_target(monitor)  # a bad --monitor before ROS 2 starts
        in_topic = None if topic is None else topic_name(topic)
        if topic is not None and in_topic is None:
            msg = (
                f"--topic {topic!r}: give a ROS 2 topic, e.g. /odom (letters, digits and _ "
                "between slashes)"
            )
            raise ConfigError(msg)
        ensure_ros_environment()
        from omnical.ros2.publishers import run_correct

        with monitor_link(target, "omnical ros2 correct", reset=False) as link:
            run_correct(factors, robot, source, in_topic, link)


@app.command()
def locate(
    hedge: Annotated[str, typer.Option(help="The hedgehog: serial:PORT.")],
    frame: Annotated[str, typer.Option(help="Frame of the fixes.")] = "map",
    baud: Annotated[int, typer.Option(help="Hedgehog baud rate.")] = 115200,
    sigma: Annotated[
        float,
        typer.Option(min=0.0, max=10.0, help="1σ of a fix per axis in the plane, m (covariance)."),
    ] = 0.02,
    monitor: MonitorOption = None,
) -> None:
    """Publish the live hedgehog's fixes as /ips/fix (PoseWithCovarianceStamped)."""
    with handled_errors():
        from omnical.cli.monitor_options import monitor_link, monitor_target
        from omnical.ros2.runtime import ensure_ros_environment

        target = monitor_target(monitor)  # a bad --monitor before ROS 2 starts
        ensure_ros_environment()
        from omnical.ros2.publishers import run_locate

        with monitor_link(target, "omnical ros2 locate", reset=False) as link:
            run_locate(hedge, frame, baud, sigma, link)


@app.command(name="map")
def publish_map(
    map_yaml: Annotated[Path, typer.Argument(help="Map YAML written by `omnical map`.")],
    frame: Annotated[str, typer.Option(help="Frame of the map.")] = "map",
    monitor: MonitorOption = None,
) -> None:
    """Publish a map as /map (nav_msgs/OccupancyGrid, transient-local) until stopped."""
    with handled_errors():
        from omnical.cli.monitor_options import monitor_link, monitor_target
        from omnical.navigation.map_io import load_map, resolve_world
        from omnical.ros2.runtime import ensure_ros_environment

        target = monitor_target(monitor)  # a bad --monitor before ROS 2 starts
        map_yaml = resolve_world(map_yaml)  # a shipped world's name too, as navigate takes it
        load_map(map_yaml)  # read before ROS 2 starts: a bad map is one line
        ensure_ros_environment()
        from omnical.ros2.publishers import run_map

        with monitor_link(target, "omnical ros2 map", reset=False) as link:
            run_map(map_yaml, frame, link)


@app.command()
def env() -> None:
    """Print the shell line that lets your own rclpy programs load the ROS 2 wheels:
    eval "$(omnical ros2 env)"."""
    with handled_errors():
        import shlex

        from omnical.ros2.runtime import library_path_line

        line = library_path_line()
        if line is None:
            typer.echo(
                "# rclpy comes from a sourced ROS 2 (no wheels here): nothing to set", err=True
            )
            return
        typer.echo(f"export LD_LIBRARY_PATH={shlex.quote(line)}")


@app.command(name="build-tf2-msgs")
def build_tf2_msgs(
    force: Annotated[
        bool, typer.Option("--force", help="Build even if tf2_msgs is installed.")
    ] = False,
) -> None:
    """Build tf2_msgs (the type of /tf, missing from the PyPI wheels) into this venv, with ROS
    2's own toolchain from the [ros2] extra, C and C++ compilers and the Python headers; then
    `ros2 twin` and `ros2 correct` publish TF. `make` runs it. Run again after upgrading the
    ROS 2 wheels: it builds again if they changed. A system ROS 2 has tf2_msgs."""
    with handled_errors():
        from omnical.ros2.interfaces import build_tf2_msgs as build
        from omnical.ros2.interfaces import (
            check_tf2_msgs_loads,
            tf2_msgs_installed,
            tf2_msgs_stale,
        )
        from omnical.ros2.runtime import ensure_ros_environment

        ensure_ros_environment()
        stale = tf2_msgs_stale()
        if tf2_msgs_installed() and not force and stale is None:
            typer.echo("tf2_msgs is installed: nothing to build (--force to build it again)")
            return
        if stale is not None and not force:
            typer.echo(f"tf2_msgs is built again ({stale})", err=True)
        prefix = build(say=lambda line: typer.echo(line, err=True))
        check_tf2_msgs_loads()
        typer.echo(f"tf2_msgs built into {prefix}: its type support loads")
