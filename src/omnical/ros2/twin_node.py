"""The digital twin as a ROS 2 robot (``omnical ros2 twin``): ``/cmd_vel`` in; ``/odom``, ``/imu``,
``/joint_states``, ``/ground_truth``, TF and (with a world) ``/scan`` out, in real time.

:class:`RosTwin` publishes every sample the twin logs from the loop of a TwinDeviceServer.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from omnical.errors import ConfigError, OmnicalError
from omnical.ips.beacons import BeaconMap
from omnical.recording.topics import (
    CMD_VEL,
    GROUND_TRUTH,
    IMU,
    JOINT_STATES,
    ODOM,
    SCAN,
    TF,
    TF_STATIC,
)
from omnical.robot.description import RobotDescription
from omnical.ros2.messages import (
    WHEELTEC_MOVING_COVARIANCE_DIAG,
    WHEELTEC_STOPPED_COVARIANCE_DIAG,
    imu_msg,
    joint_state_msg,
    laser_scan_msg,
    odometry_msg,
    transform_msg,
)
from omnical.ros2.runtime import import_rclpy
from omnical.ros2.silence import SilenceWatch, domain_id, publisher_types, type_mismatch
from omnical.twin.device import DeviceConfig, TwinDeviceServer
from omnical.twin.params import TwinParams
from omnical.twin.simulator import DigitalTwin, ImuColumn, StateColumn

if TYPE_CHECKING:
    from omnical.navigation.grid import OccupancyGrid
    from omnical.twin.lidar import Lidar, LidarParams
    from omnical.twin.world import World

__all__ = ["QOS_DEPTH", "RosTwin", "TwinCollisionError", "TwinNodeConfig", "tf_available"]

QOS_DEPTH = 50
"""History depth of every publisher and of ``/cmd_vel`` (reliable): one second at 50 Hz."""
_SCAN_CATCH_UP_S = 0.5
"""A late tick sends the scans that fell due since, up to this far back (robot s); further
behind (a long stall), the LiDAR starts again from now."""


class TwinCollisionError(OmnicalError):
    """The twin's footprint touched a wall of its world: the twin stops there (it has no
    contact model; a robot would have hit the wall)."""


@dataclass(frozen=True)
class TwinNodeConfig:
    """How the twin presents itself on ROS 2.

    Attributes:
        cmd_vel_stamped: ``/cmd_vel`` is ``geometry_msgs/TwistStamped`` (else ``Twist``).
        cmd_timeout_s: no command for this long → the twin is commanded to stop (it then
            decelerates at its limits).
        odom_frame, base_frame, map_frame, imu_frame: frame ids (REP 105).
        node_name: the ROS 2 node's name.
        time_scale: robot seconds per wall second (tests only; 1 = real time).
    """

    cmd_vel_stamped: bool = False
    cmd_timeout_s: float = 0.5
    odom_frame: str = "odom"
    base_frame: str = "base_link"
    map_frame: str = "map"
    imu_frame: str = "imu_link"
    node_name: str = "omnical_twin"
    time_scale: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.cmd_timeout_s) and 0.01 <= self.cmd_timeout_s <= 60.0):
            msg = f"cmd_vel timeout must be within 0.01–60 s, got {self.cmd_timeout_s}"
            raise ConfigError(msg)


def tf_available() -> bool:
    """Whether ``tf2_msgs`` (the type of ``/tf``) can be imported: a system ROS 2 has it; with
    the PyPI wheels, ``omnical ros2 build-tf2-msgs`` builds it (docs/ros2.md)."""
    try:
        import tf2_msgs.msg  # noqa: F401
    except ImportError:
        return False
    return True


class RosTwin:
    """The twin on ROS 2 (see the module docstring); start, then serve until stopped.

    Args:
        robot, params: the robot and its twin.
        seed: the twin's noise seed (the hedgehog's and the LiDAR's too).
        beacons: the beacon map of the served hedgehog (default: seed 000 Table 3).
        config: topics' types, timeout, frames.
        walls: the floor plan with the robot's footprint: the true pose touching a wall ends
            the loop with :class:`TwinCollisionError` (:meth:`serve_forever` raises it), from
            the first tick on; the start must be free (:meth:`World.collides`).

    A floor plan for ``/scan`` is attached by :meth:`attach_world`, before or after :meth:`start`
    (after: the odometry flows while the plan loads).
    """

    def __init__(
        self,
        robot: RobotDescription,
        params: TwinParams,
        *,
        seed: int = 0,
        beacons: BeaconMap | None = None,
        config: TwinNodeConfig | None = None,
        walls: World | None = None,
    ) -> None:
        self.robot = robot
        self._start_pose = params.start_pose_map
        self.config = cfg = config if config is not None else TwinNodeConfig()
        self.server = TwinDeviceServer(
            robot,
            params,
            seed=seed,
            beacons=beacons,
            config=DeviceConfig(
                vehicle_port=False, watchdog_s=cfg.cmd_timeout_s, time_scale=cfg.time_scale
            ),
            on_tick=self._on_tick,
        )
        self._seed = seed
        self._lidar: tuple[Lidar, LidarParams] | None = None
        self._walls = walls
        enc = robot.encoders
        self._joint_names = enc.joints
        self._joint_scale = enc.radians_per_unit()
        self._wheel_angle = np.zeros(robot.wheel_count)
        self._counts = [0, 0, 0]  # odom, ground truth, imu rows published
        self._last_odom_t = 0.0
        self._next_scan_s = 0.0
        self._rclpy: Any = None
        self._context: Any = None
        self._node: Any = None
        self._watch: SilenceWatch | None = None
        self._executor: Any = None
        self._spin: threading.Thread | None = None
        self._pubs: dict[str, Any] = {}
        self._tf_pub: Any = None
        self._tf_static_pub: Any = None
        self._tf_msg_type: Any = None
        self.commands_received = 0
        self.published: dict[str, int] = {}

    @property
    def hedge_path(self) -> str:
        """The served hedgehog's device path."""
        return self.server.hedge_path

    @property
    def publishes_tf(self) -> bool:
        """Whether TF is published (``tf2_msgs`` importable)."""
        return self._tf_pub is not None

    def start(self) -> None:
        """Create the node, its publishers and ``/cmd_vel`` subscription, start the twin."""
        rclpy = self._rclpy = import_rclpy()
        from geometry_msgs.msg import Twist, TwistStamped
        from nav_msgs.msg import Odometry
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions
        from sensor_msgs.msg import Imu, JointState

        self._context = Context()
        rclpy.init(context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        node = self._node = rclpy.create_node(self.config.node_name, context=self._context)
        qos = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        types: dict[str, Any] = {
            ODOM: Odometry,
            GROUND_TRUTH: Odometry,
            IMU: Imu,
            JOINT_STATES: JointState,
        }
        self._pubs = {t: node.create_publisher(m, t, qos) for t, m in types.items()}
        self.published = dict.fromkeys(types, 0)
        if tf_available():
            from tf2_msgs.msg import TFMessage

            self._tf_msg_type = TFMessage
            self._tf_pub = node.create_publisher(TFMessage, TF, qos)
            self.published[TF] = 0
        cmd_type = TwistStamped if self.config.cmd_vel_stamped else Twist
        # two arguments: rclpy passes the message info (its source timestamp) too
        node.create_subscription(cmd_type, CMD_VEL, self._on_cmd_vel, qos)
        expected = f"geometry_msgs/msg/{cmd_type.__name__}"
        self._watch = SilenceWatch(lambda waited_s: self._cmd_vel_mismatch(expected, waited_s))
        self._watch.start()
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(node)
        self._spin = threading.Thread(target=self._spin_loop, name="ros2-twin-spin", daemon=True)
        self._spin.start()
        self.server.start()
        if self._lidar is not None:
            self._add_scan_publisher()
        self._publish_static_tf()

    def attach_world(self, grid: OccupancyGrid, lidar: LidarParams | None = None) -> None:
        """Publish ``/scan`` from a simulated LiDAR in ``grid`` (the twin's map frame); the
        LiDAR defaults to an RPLidar-like at the robot's LiDAR mount."""
        from omnical.twin.lidar import Lidar, LidarParams

        mount = self.robot.lidar_mount
        lp = lidar or LidarParams(mount_pose=(mount.x_m, mount.y_m, mount.yaw_rad))
        sensor = Lidar(grid, lp, self._seed)
        sensor.scan(self._start_pose)  # compile (or load) the ray caster before serving
        self._lidar = (sensor, lp)
        if self._node is not None:
            self._add_scan_publisher()
            self._publish_static_tf()

    def _publish_static_tf(self) -> None:
        """``/tf_static`` (with ``tf2_msgs``): ``base_link → imu_link`` (the IMU at the base's
        origin) and, with a world, ``base_link → laser`` at the LiDAR's mount (its height
        too); one message with all of them, kept for late subscribers (transient local)."""
        if self._tf_msg_type is None:
            return
        if self._tf_static_pub is None:
            from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

            qos = QoSProfile(
                depth=1,
                reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.TRANSIENT_LOCAL,
            )
            self._tf_static_pub = self._node.create_publisher(self._tf_msg_type, TF_STATIC, qos)
            self.published[TF_STATIC] = 0
        cfg = self.config
        t_ns = time.time_ns()
        transforms = [
            transform_msg(
                t_ns, (0.0, 0.0, 0.0), frame_id=cfg.base_frame, child_frame_id=cfg.imu_frame
            )
        ]
        if self._lidar is not None:
            lp = self._lidar[1]
            transforms.append(
                transform_msg(
                    t_ns,
                    lp.mount_pose,
                    frame_id=cfg.base_frame,
                    child_frame_id=lp.frame_id,
                    z_m=self.robot.lidar_mount.z_m,
                )
            )
        self._tf_static_pub.publish(self._tf_msg_type(transforms=transforms))
        self.published[TF_STATIC] += 1

    def _add_scan_publisher(self) -> None:
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import LaserScan

        if SCAN in self._pubs:
            return
        qos = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        self._pubs[SCAN] = self._node.create_publisher(LaserScan, SCAN, qos)
        self.published[SCAN] = 0

    def serve_forever(self) -> None:
        """Block until :meth:`stop` (from a signal handler or another thread); re-raise the
        server loop's error."""
        self.server.serve_forever()

    def stop(self) -> None:
        """Stop the twin, the node and the context. Idempotent."""
        self.server.stop()
        if self._watch is not None:
            self._watch.stop()
            self._watch = None
        if self._executor is not None:
            with contextlib.suppress(Exception):
                self._executor.shutdown(timeout_sec=1.0)
            self._executor = None
        if self._spin is not None:
            self._spin.join(timeout=2.0)
            self._spin = None
        if self._node is not None:
            with contextlib.suppress(Exception):
                self._node.destroy_node()
            self._node = None
        if self._context is not None and self._rclpy is not None:
            with contextlib.suppress(Exception):
                self._rclpy.shutdown(context=self._context)
            self._context = None

    # ------------------------------------------------------------------ ROS side
    def _spin_loop(self) -> None:
        from rclpy.executors import ExternalShutdownException

        executor, context = self._executor, self._context
        with contextlib.suppress(ExternalShutdownException):
            while context is not None and context.ok() and self._executor is executor:
                executor.spin_once(timeout_sec=0.1)

    def _cmd_vel_mismatch(self, expected: str, waited_s: float) -> str | None:
        """The warning when /cmd_vel is published in another type than the twin takes (None:
        no such publisher; waiting for commands is normal)."""
        node = self._node
        if node is None:
            return None
        others = type_mismatch(publisher_types(node, CMD_VEL), expected)
        if not others:
            return None
        flag = "without" if self.config.cmd_vel_stamped else "with"
        return (
            f"omnical: ros2 twin: no {CMD_VEL} for {waited_s:g} s (ROS_DOMAIN_ID "
            f"{domain_id(node)}): it is published as {', '.join(others)}, the twin takes "
            f"{expected} (start it {flag} --twist-stamped)"
        )

    def _on_cmd_vel(self, msg: Any, info: Any) -> None:
        watch = self._watch  # stop() may clear it from another thread meanwhile
        if watch is not None:
            watch.seen()
        twist = msg.twist if self.config.cmd_vel_stamped else msg
        values = (float(twist.linear.x), float(twist.linear.y), float(twist.angular.z))
        if not all(math.isfinite(v) for v in values):
            return  # a NaN command is no command: the timeout stops the twin
        self.commands_received += 1
        # the DDS source timestamp: its sender's clock when published (this host's here); a
        # stall of this process then does not lengthen a move
        sent = info.get("source_timestamp") if isinstance(info, dict) else None
        self.server.command(*values, sent_wall_ns=int(sent) if sent else None)

    def _stamp_ns(self, t_s: float) -> int:
        return self.server.t0_wall_ns + round(t_s * 1e9)

    def _publish(self, topic: str, msg: Any) -> None:
        self._pubs[topic].publish(msg)
        self.published[topic] += 1

    def _on_tick(self, twin: DigitalTwin, t_s: float) -> None:
        """The server loop's hook: publish every sample logged since the last call."""
        cfg = self.config
        n_odom, n_gt, n_imu = self._counts
        new = twin.log_since(n_odom, n_gt, n_imu)
        self._counts = [n_odom + len(new.odom), n_gt + len(new.ground_truth), n_imu + len(new.imu)]
        walls = self._walls
        if walls is not None and len(new.ground_truth):  # before any of it is published
            poses = new.ground_truth[:, StateColumn.X_M : StateColumn.YAW_RAD + 1]
            hit = walls.first_contact(poses)
            if hit is not None:
                t_hit = float(new.ground_truth[hit, StateColumn.T_S])
                msg = (
                    f"{walls.collision_message(poses[hit])} after {t_hit:.1f} s: the twin stops "
                    "there (it has no contact model: a robot would have hit the wall)"
                )
                raise TwinCollisionError(msg)
        if len(new.odom):
            wheels = np.asarray(twin.read_state().wheel_speeds_radps, dtype=np.float64)
        for row in new.odom:
            t = float(row[StateColumn.T_S])
            pose = row[StateColumn.X_M : StateColumn.YAW_RAD + 1]
            twist = row[StateColumn.VX_MPS : StateColumn.WZ_RADPS + 1]
            moving = bool(np.any(twist != 0.0))
            diag = WHEELTEC_MOVING_COVARIANCE_DIAG if moving else WHEELTEC_STOPPED_COVARIANCE_DIAG
            stamp = self._stamp_ns(t)
            self._publish(
                ODOM,
                odometry_msg(
                    stamp,
                    pose,
                    twist,
                    diag,
                    diag,
                    frame_id=cfg.odom_frame,
                    child_frame_id=cfg.base_frame,
                ),
            )
            self._wheel_angle += wheels * (t - self._last_odom_t)
            self._last_odom_t = t
            self._publish(
                JOINT_STATES,
                joint_state_msg(
                    stamp,
                    self._joint_names,
                    self._wheel_angle / self._joint_scale,
                    wheels / self._joint_scale,
                ),
            )
            if self._tf_pub is not None:
                tf = transform_msg(
                    stamp, pose, frame_id=cfg.odom_frame, child_frame_id=cfg.base_frame
                )
                self._tf_pub.publish(self._tf_msg_type(transforms=[tf]))
                self.published[TF] += 1
        for row in new.ground_truth:
            t = float(row[StateColumn.T_S])
            self._publish(
                GROUND_TRUTH,
                odometry_msg(
                    self._stamp_ns(t),
                    row[StateColumn.X_M : StateColumn.YAW_RAD + 1],
                    row[StateColumn.VX_MPS : StateColumn.WZ_RADPS + 1],
                    np.zeros(6),
                    np.zeros(6),
                    frame_id=cfg.map_frame,
                    child_frame_id=cfg.base_frame,
                ),
            )
        imu = self.robot.imu
        for row in new.imu:
            self._publish(
                IMU,
                imu_msg(
                    self._stamp_ns(float(row[ImuColumn.T_S])),
                    row[ImuColumn.GYRO_X_RADPS : ImuColumn.GYRO_Z_RADPS + 1],
                    row[ImuColumn.ACC_X_MPS2 : ImuColumn.ACC_Z_MPS2 + 1],
                    gyro_variance=imu.gyro_noise_radps**2,
                    accel_variance=imu.accel_noise_mps2**2,
                    frame_id=cfg.imu_frame,
                ),
            )
        attached = self._lidar if SCAN in self._pubs else None
        if attached is None:
            return
        lidar, lp = attached
        if t_s - self._next_scan_s > _SCAN_CATCH_UP_S:  # far behind (a long stall): from now
            self._next_scan_s = t_s
        truth = new.ground_truth
        while t_s >= self._next_scan_s:
            # every scan on the LiDAR's own 10-Hz grid, from the true pose at its time (a late
            # tick of a loaded process sends the scans that fell due since, as a LiDAR would)
            t_scan = self._next_scan_s
            self._next_scan_s += 1.0 / lp.rate_hz
            pose = twin.ground_truth_pose
            if len(truth):
                at = int(np.searchsorted(truth[:, StateColumn.T_S], t_scan, side="right")) - 1
                if at >= 0:
                    pose = tuple(
                        float(v) for v in truth[at, StateColumn.X_M : StateColumn.YAW_RAD + 1]
                    )
            ranges = lidar.scan(pose)
            self._publish(
                SCAN,
                laser_scan_msg(
                    self._stamp_ns(t_scan),
                    ranges,
                    angle_min_rad=lp.angle_min_rad,
                    angle_increment_rad=lp.angle_increment_rad,
                    range_min_m=lp.range_min_m,
                    range_max_m=lp.range_max_m,
                    scan_period_s=1.0 / lp.rate_hz,
                    frame_id=lp.frame_id,
                ),
            )
