"""What omnical knows, published on ROS 2 until stopped: ``/odom_calibrated`` (``ros2 correct``),
``/ips/fix`` (``ros2 locate``), ``/map`` (``ros2 map``, transient-local).

Each ``run_*`` spins a node of its own context on a thread and blocks until Ctrl-C / SIGTERM.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from omnical.errors import ConfigError
from omnical.recording.topics import (
    HEDGE_POS_ANG,
    IPS_FIX,
    JOINT_STATES,
    MAP,
    ODOM,
    ODOM_CALIBRATED,
    TF,
)
from omnical.ros2.correct import (
    CorrectedOdometry,
    correct_pose_step,
    correct_wheel_step,
    factor_sigmas,
    start_corrected,
)
from omnical.ros2.messages import (
    covariance_from_msg,
    ns_from_stamp,
    occupancy_grid_msg,
    odometry_fields,
    odometry_msg,
    planar_covariance,
    pose_with_covariance_msg,
    transform_msg,
)
from omnical.ros2.runtime import import_rclpy
from omnical.ros2.silence import SilenceWatch, domain_id, publisher_types, topic_silence_line

if TYPE_CHECKING:
    from omnical.web.tee import MonitorLink

__all__ = [
    "OdometryCorrector",
    "calibrated_frame",
    "ros_node",
    "run_correct",
    "run_locate",
    "run_map",
    "tf_child",
]


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


@contextlib.contextmanager
def ros_node(name: str) -> Iterator[Any]:
    """A node in a context of its own, spun on a thread; destroyed and shut down on leaving."""
    rclpy = import_rclpy()
    from rclpy.context import Context
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    stop = threading.Event()

    def spin() -> None:
        with contextlib.suppress(ExternalShutdownException):
            while not stop.is_set() and context.ok():
                executor.spin_once(timeout_sec=0.1)

    thread = threading.Thread(target=spin, name=f"ros2-{name}", daemon=True)
    thread.start()
    try:
        yield node
    finally:
        stop.set()
        thread.join(timeout=2.0)
        with contextlib.suppress(Exception):
            executor.shutdown(timeout_sec=1.0)
            node.destroy_node()
        with contextlib.suppress(Exception):
            rclpy.shutdown(context=context)


def calibrated_frame(child_frame_id: str) -> str:
    """The child frame of the corrected odometry (its message and its TF): the raw one +
    ``_calibrated`` (the robot's driver publishes odom → base_link itself: a second parent of
    base_link would break TF)."""
    return f"{child_frame_id or 'base_link'}_calibrated"


def tf_child(raw: Any) -> str:
    """The child frame of the correction of a raw message (``calibrated_frame`` of its own)."""
    return calibrated_frame(raw.child_frame_id)


def _tf_publisher(node: Any, qos: Any) -> tuple[Any, Any] | None:
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError:
        _say(
            f"omnical: {TF} is not published: tf2_msgs is not installed "
            "(`omnical ros2 build-tf2-msgs` builds it)"
        )
        return None
    return node.create_publisher(TFMessage, TF, qos), TFMessage


class OdometryCorrector:
    """Raw odometry (or wheel joint states) in, corrected ``nav_msgs/Odometry`` out.

    An unstamped message (stamp 0) is timed by its receipt; a stamp earlier than the previous
    one (a clock that jumped back, a restarted simulator) restarts the increments there, with
    a warning, and the corrected pose goes on from where it was.

    Args:
        factors, uncertainty, installed: the factors, their 1σ (None: zero) and the factors the
            robot's odometry was already compensated with (None: none).
        J_plus: (3, n) nominal forward kinematics, for wheel joint states.
        radians_per_unit: (n,) JointState position → wheel angle, for wheel joint states.
        joints: the JointState names of the wheels, in the description's order.
        warn: receives the warning line of a backward jump.
    """

    def __init__(
        self,
        factors: Any,
        uncertainty: Any = None,
        installed: Any = None,
        *,
        J_plus: Any = None,
        radians_per_unit: Any = None,
        joints: tuple[str, ...] = (),
        warn: Callable[[str], None] = _say,
    ) -> None:
        self.warn = warn
        self.jumps = 0
        self.factors = factors
        self.installed = installed
        self.sigmas = factor_sigmas(uncertainty)
        self.J_plus = J_plus
        self.radians_per_unit = radians_per_unit
        self.joints = joints
        self.state: CorrectedOdometry | None = None

    def step_pose(self, t_ns: int, pose: Any, rx_ns: int | None = None) -> CorrectedOdometry:
        """The state after a raw odometry pose stamped ``t_ns`` (0: unstamped, timed by
        ``rx_ns``, default now)."""
        t = self._time(t_ns, rx_ns, pose)
        if self.state is None:
            self.state = start_corrected(t, pose, pose)
        else:
            self.state = correct_pose_step(self.state, t, pose, self.factors, self.installed)
        return self.state

    def step_wheels(self, t_ns: int, angles: Any, rx_ns: int | None = None) -> CorrectedOdometry:
        """The state after wheel angles (rad) stamped ``t_ns`` (0: timed by ``rx_ns``)."""
        t = self._time(t_ns, rx_ns, angles)
        if self.state is None:
            self.state = start_corrected(t, angles)
        else:
            self.state = correct_wheel_step(self.state, t, angles, self.J_plus, self.factors)
        return self.state

    def _time(self, t_ns: int, rx_ns: int | None, raw: Any) -> int:
        """The sample's time; a backward jump rebases the state there (the next increment is
        from this sample's raw values)."""
        t = int(t_ns) if t_ns > 0 else (time.time_ns() if rx_ns is None else int(rx_ns))
        s = self.state
        if s is not None and t < s.t_ns:
            self.jumps += 1
            self.warn(
                f"omnical: the odometry's time went back {(s.t_ns - t) / 1e9:.3f} s: the "
                "correction restarts its increments there (the corrected pose goes on)"
            )
            values = tuple(float(v) for v in np.asarray(raw, dtype=np.float64).ravel())
            self.state = replace(s, t_ns=t, raw=values)
        return t

    def from_odometry(self, msg: Any) -> Any:
        """The corrected message of a raw ``nav_msgs/Odometry``."""
        t_ns, pose, _ = odometry_fields(msg)
        self.step_pose(t_ns, pose)
        raw_pose_cov = covariance_from_msg(msg.pose.covariance)
        raw_twist_cov = covariance_from_msg(msg.twist.covariance)
        return self._message(
            msg.header.frame_id, msg.child_frame_id, raw_pose_cov, raw_twist_cov, unused=0.0
        )

    def from_joint_states(self, msg: Any, frame_id: str, child_frame_id: str) -> Any | None:
        """The corrected message of a ``sensor_msgs/JointState`` (None: the wheels are not all
        in it, or it has no positions). The dimensions the wheels do not observe (z, roll,
        pitch) get the variance 1e6, as a driver's ``/odom``."""
        names = list(msg.name)
        try:
            idx = [names.index(j) for j in self.joints]
        except ValueError:
            return None
        if len(msg.position) < len(names):
            return None
        units = np.asarray(msg.position, dtype=np.float64)[idx]
        angles = units * np.asarray(self.radians_per_unit)
        self.step_wheels(ns_from_stamp(msg.header.stamp), angles)
        zero = np.zeros((6, 6))
        return self._message(frame_id, child_frame_id, zero, zero, unused=UNOBSERVED_VARIANCE)

    def _message(
        self, frame: str, child: str, raw_pose_cov: Any, raw_twist_cov: Any, *, unused: float
    ) -> Any:
        """The corrected message: child frame ``calibrated_frame(child)``; covariances the raw
        ones + the factors' (``unused``: the variance of z, roll and pitch, added)."""
        s = self.state
        assert s is not None
        pose_cov = raw_pose_cov + planar_covariance(
            s.pose_covariance(self.sigmas), unused_variance=unused
        )
        twist_cov = raw_twist_cov + planar_covariance(
            s.twist_covariance(self.sigmas), unused_variance=unused
        )
        return odometry_msg(
            s.t_ns,
            s.pose,
            s.twist,
            pose_cov,
            twist_cov,
            frame_id=frame,
            child_frame_id=calibrated_frame(child),
        )


UNOBSERVED_VARIANCE = 1e6
"""The variance of what wheel odometry does not observe (z, roll, pitch), as the driver's /odom."""


def _monitor_odometry(link: MonitorLink, out: Any) -> None:
    """A corrected ``nav_msgs/Odometry`` to the monitor, as an ``/odom`` row."""
    t_ns, (x, y, yaw), (vx, vy, wz) = odometry_fields(out)
    link.rows(
        ODOM, [t_ns],
        {"x_m": [x], "y_m": [y], "yaw_rad": [yaw], "vx_mps": [vx], "vy_mps": [vy],
         "wz_radps": [wz]},
    )  # fmt: skip


def _monitor_beacons(link: MonitorLink, beacons: dict[int, tuple[float, float, float]]) -> None:
    """The beacon map the hedgehog streamed, latched on the monitor."""
    from omnical.web.protocol import beacons_payload

    addresses = sorted(beacons)
    link.latch("beacons", beacons_payload(addresses, [beacons[a] for a in addresses]))


def _wait_forever() -> None:
    while True:
        time.sleep(0.5)


def corrector_for(factors_path: Path, robot: str) -> OdometryCorrector:
    """The corrector ``omnical ros2 correct`` runs: the factors (and their 1σ) of
    ``factors_path`` on ``robot`` (preset or YAML), its wheels and encoder joints."""
    from omnical.calibration.factors_io import read_factors
    from omnical.kinematics.jacobian import forward_jacobian, inverse_jacobian
    from omnical.robot.loader import load_robot

    ff = read_factors(factors_path)
    description = load_robot(robot)
    enc = description.encoders
    return OdometryCorrector(
        ff.factors,
        ff.uncertainty,
        J_plus=forward_jacobian(inverse_jacobian(description.wheels)),
        radians_per_unit=enc.radians_per_unit(),
        joints=enc.joints,
    )


def run_correct(
    factors_path: Path,
    robot: str,
    source: str,
    topic: str | None,
    link: MonitorLink | None = None,
) -> None:
    """``omnical ros2 correct``: ``/odom_calibrated`` from the robot's odometry, and on TF the
    corrected pose as odom → base_link_calibrated (never odom → base_link: the driver's);
    with ``link`` (``--monitor``) the corrected odometry is streamed as the run's odometry."""
    if source not in ("odom", "joint_states"):
        msg = f"--source {source!r}: 'odom' or 'joint_states'"
        raise ConfigError(msg)
    corrector = corrector_for(factors_path, robot)
    in_topic = topic or (ODOM if source == "odom" else JOINT_STATES)
    from nav_msgs.msg import Odometry
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    with ros_node("omnical_correct") as node:
        out_qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        in_qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.BEST_EFFORT)
        pub = node.create_publisher(Odometry, ODOM_CALIBRATED, out_qos)
        tf = _tf_publisher(node, out_qos)

        def publish(out: Any) -> None:
            pub.publish(out)
            if link is not None:
                _monitor_odometry(link, out)
            if tf is not None:
                t_ns = ns_from_stamp(out.header.stamp)
                _, pose, _ = odometry_fields(out)
                stamped = transform_msg(
                    t_ns, pose, frame_id=out.header.frame_id, child_frame_id=out.child_frame_id
                )
                tf[0].publish(tf[1](transforms=[stamped]))

        expected = "nav_msgs/msg/Odometry" if source == "odom" else "sensor_msgs/msg/JointState"
        watch = SilenceWatch(
            lambda waited_s: topic_silence_line(
                "ros2 correct",
                in_topic,
                expected,
                publisher_types(node, in_topic),
                domain_id(node),
                waited_s,
            )
        )
        if source == "odom":

            def on_odom(m: Any) -> None:
                watch.seen()
                publish(corrector.from_odometry(m))

            node.create_subscription(Odometry, in_topic, on_odom, in_qos)
        else:

            def on_joints(m: Any) -> None:
                watch.seen()
                out = corrector.from_joint_states(m, "odom", "base_link")
                if out is not None:
                    publish(out)

            node.create_subscription(JointState, in_topic, on_joints, in_qos)
        tf_line = "; TF: odom → base_link_calibrated" if tf is not None else ""
        _say(f"omnical: {in_topic} → {ODOM_CALIBRATED} with the factors of {factors_path}{tf_line}")
        watch.start()
        try:
            _wait_forever()
        finally:
            watch.stop()


def run_locate(
    hedge: str,
    frame: str,
    baud: int,
    sigma_m: float = 0.02,
    link: MonitorLink | None = None,
) -> None:
    """``omnical ros2 locate``: the live hedgehog's fixes as ``/ips/fix``; with ``link``
    (``--monitor``) each fix, and the beacon map once the hedgehog has streamed it."""
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from omnical.drivers.hedgehog import SerialHedgehog

    if not hedge.startswith("serial:") or len(hedge) <= len("serial:"):
        msg = f"--hedge {hedge!r}: serial:PORT"
        raise ConfigError(msg)
    port = hedge.removeprefix("serial:")
    # a fix's covariance: σ per axis in the plane, height and heading not measured
    cov = np.diag([sigma_m**2, sigma_m**2, 1e6, 1e6, 1e6, 1e6])
    wall_minus_mono_ns = time.time_ns() - time.monotonic_ns()
    with ros_node("omnical_locate") as node, SerialHedgehog.open(port, baud) as hedgehog:
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        pub = node.create_publisher(PoseWithCovarianceStamped, IPS_FIX, qos)
        _say(f"omnical: the fixes of the hedgehog on {port} → {IPS_FIX} (frame {frame})")
        domain = domain_id(node)

        def silent(waited_s: float) -> str:
            got = hedgehog.reader.stats.bytes_received
            what = f"no position ({got} bytes in all)" if got else "no byte"
            return (
                f"omnical: ros2 locate: {what} from the hedgehog on {port} for {waited_s:g} s "
                f"(ROS_DOMAIN_ID {domain}, nothing on {IPS_FIX}): is it the hedgehog's "
                f"port, awake, at {baud} baud? still waiting"
            )

        watch = SilenceWatch(silent).start()
        try:
            _publish_fixes(hedgehog, port, pub, frame, cov, wall_minus_mono_ns, link, watch)
        finally:
            watch.stop()


def _publish_fixes(
    hedgehog: Any,
    port: str,
    pub: Any,
    frame: str,
    cov: Any,
    wall_minus_mono_ns: int,
    link: MonitorLink | None,
    watch: SilenceWatch,
) -> None:
    """Each new fix of ``hedgehog`` on ``pub`` (and the monitor) until stopped."""
    last = None
    beacons = 0
    while True:
        if hedgehog.error is not None:
            msg = f"hedgehog on {port}: {hedgehog.error}"
            raise ConfigError(msg)
        fix = hedgehog.latest_fix()
        if fix is not None and fix is not last:
            last = fix
            watch.seen()
            t_ns = wall_minus_mono_ns + round(fix.t_s * 1e9)
            pub.publish(
                pose_with_covariance_msg(
                    t_ns, (fix.x_m, fix.y_m, 0.0), cov, frame_id=frame, z_m=fix.z_m
                )
            )
            if link is not None:
                link.rows(
                    HEDGE_POS_ANG, [t_ns],
                    {"x_m": [fix.x_m], "y_m": [fix.y_m], "z_m": [fix.z_m], "flags": [0]},
                )  # fmt: skip
        if link is not None and len(hedgehog.beacons) > beacons:  # streamed: a new one
            beacons = len(hedgehog.beacons)
            _monitor_beacons(link, hedgehog.beacons)
        time.sleep(0.005)


def run_map(map_yaml: Path, frame: str, link: MonitorLink | None = None) -> None:
    """``omnical ros2 map``: a map_server map as ``/map``, transient-local (late joiners get it);
    with ``link`` (``--monitor``) the map latched on the monitor too."""
    from nav_msgs.msg import OccupancyGrid
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from omnical.navigation.map_io import load_map

    grid = load_map(map_yaml)
    msg = occupancy_grid_msg(
        time.time_ns(), grid.cells, grid.resolution_m, grid.origin, frame_id=frame
    )
    with ros_node("omnical_map") as node:
        qos = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        node.create_publisher(OccupancyGrid, MAP, qos).publish(msg)
        if link is not None:
            from omnical.web.protocol import map_payload

            link.latch("map", map_payload(grid.cells, grid.resolution_m, grid.origin))
        rows, cols = grid.cells.shape
        _say(f"omnical: {map_yaml} → {MAP} ({cols} × {rows} cells of {grid.resolution_m:g} m)")
        _wait_forever()
