"""The ROS 2 rig (``--robot ros2``): a robot's ROS 2 topics as the serial rig's live devices.

:func:`ros2_devices` opens /cmd_vel, /odom, /imu, /joint_states, /scan and a hedgehog (topic or
port); :class:`~omnical.services.hil.SerialRig` runs on them with its rules and recording.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import statistics
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from omnical.drivers.hedgehog import HedgeFix
from omnical.drivers.watchdog import Silence, Watched, wait_while_silent
from omnical.drivers.wheeltec_serial import SerialRobotState
from omnical.errors import ConfigError, ProtocolError, SafetyStopError
from omnical.estimation.se2 import wrap_angle
from omnical.recording.topics import (
    CMD_VEL,
    GROUND_TRUTH,
    HEDGE_POS_ANG,
    IMU,
    JOINT_STATES,
    ODOM,
    SCAN,
)
from omnical.ros2.messages import yaw_from_quaternion
from omnical.services.hil import (
    SCALED_STALL_S,
    DeviceRows,
    HostClock,
    LiveHedgehog,
    open_serial_hedgehog,
)

if TYPE_CHECKING:
    from omnical.kinematics.correction import CorrectionFactors
    from omnical.robot.description import RobotDescription
    from omnical.twin.lidar import LidarParams

__all__ = [
    "CMD_VEL_TYPES",
    "HEDGE_TOPIC_TYPES",
    "ODOM_MIN_LIMIT_S",
    "SCAN_CLOCK_WINDOW",
    "SCAN_MIN_LIMIT_S",
    "Ros2Lidar",
    "Ros2Link",
    "Ros2Robot",
    "SecondOdomPublisherError",
    "TopicHedgehog",
    "full_circle_ranges",
    "ros2_devices",
    "scaled_limit_s",
    "stream_limit_s",
    "two_robots",
]

HEDGE_TOPIC_TYPES = (
    "geometry_msgs/msg/PointStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
)
"""The standard message types a hedgehog topic may carry (``--hedge topic:/NAME``)."""

_DEPTH = 100

CMD_VEL_TYPES = {False: "geometry_msgs/msg/Twist", True: "geometry_msgs/msg/TwistStamped"}
"""The type of ``/cmd_vel`` without and with ``--twist-stamped``."""

SCAN_MIN_LIMIT_S = 0.5
"""The shortest silence of ``/scan`` that stops a robot navigating on it (three periods of a
10-Hz LiDAR at least, as ``/odom``'s)."""

SCAN_CLOCK_WINDOW = 50
"""Scans (5 s at 10 Hz) whose smallest receipt delay maps a scan's stamp to the host clock."""

ODOM_MIN_LIMIT_S = 0.5
"""The shortest silence of ``/odom`` that stops a moving robot: a robot driver's own ``/cmd_vel``
timeout (0.5 s is common, and the twin's). 0.25 s stopped a campaign on a loaded 2-core machine
(one 0.27-s gap in a 50-Hz stream, two real-time processes beside it)."""


def stream_limit_s(rx_s: list[float], floor_s: float, ceiling_s: float = 1.0) -> float:
    """How long a stream may be silent: three of its periods (the median spacing of its last
    receptions; 0.1 s before there are 4), within ``floor_s`` and ``max(ceiling_s, floor_s)``."""
    period = (
        statistics.median(b - a for a, b in itertools.pairwise(rx_s)) if len(rx_s) >= 4 else 0.1
    )
    return min(max(3.0 * period, floor_s), max(ceiling_s, floor_s))


def scaled_limit_s(limit_s: float, time_scale: float) -> float:
    """A silence limit in robot time on a ``time_scale``-times clock: ``limit_s`` on a robot
    (1); on a faster clock (tests against ``ros2 twin --time-scale``) a scheduling stall is
    ``time_scale`` times longer in robot time, so the limit is wall time, as the serial rig's
    (:data:`~omnical.services.hil.SCALED_STALL_S`, or ``limit_s`` if longer)."""
    if time_scale == 1.0:
        return limit_s
    return max(limit_s, SCALED_STALL_S) * time_scale


_UNKNOWN_NAME = "_NODE_NAME_UNKNOWN_"
"""rmw's node name of an endpoint whose node's graph information is not discovered yet."""
UNNAMED = "a node not named yet"
"""How :func:`two_robots` shows such a node."""


def two_robots(publishers: Sequence[str]) -> str:
    """What to say when more than one node publishes ``/odom`` on this domain: how many, which
    (``publishers``: their nodes, one entry per publisher), and what to do."""
    domain = os.environ.get("ROS_DOMAIN_ID", "0")
    shown = [UNNAMED if _UNKNOWN_NAME in name else name for name in publishers]
    named = ", ".join(
        name if n == 1 else f"{n} nodes named {name}" if name != UNNAMED else f"{n} {name}s"
        for name, n in sorted(Counter(shown).items())
    )
    return (
        f"{len(publishers)} nodes publish {ODOM} on ROS_DOMAIN_ID {domain} ({named}): one robot "
        "per domain: stop the other one, or give each robot a ROS_DOMAIN_ID of its own"
    )


class SecondOdomPublisherError(SafetyStopError):
    """A second node publishing ``/odom``, discovered after the start (Fast DDS's discovery can
    take 2 s): two robots may be following ``/cmd_vel``, so the motion stops (exit 4, the run
    kept) with one line naming the publishers and what to do."""

    def __init__(self, device: str, publishers: Sequence[str], moving: bool = True) -> None:
        super().__init__(device, 0.0, two_robots(publishers), moving=moving)
        self.name_publishers(publishers)

    def name_publishers(self, publishers: Sequence[str]) -> None:
        """Say ``publishers`` (their names, discovered after the endpoints, came later)."""
        self.publishers = tuple(publishers)
        done = "robot stopped" if self.moving else "motion not started"
        self.args = (f"{two_robots(publishers)} (discovered after the start: {done})",)

    def __reduce__(self) -> tuple[type[SecondOdomPublisherError], tuple[str, list[str], bool]]:  # type: ignore[override]
        return (type(self), (self.device, list(self.publishers), self.moving))


def full_circle_ranges(
    ranges_m: NDArray[np.floating[Any]],
    angle_min_rad: float,
    angle_increment_rad: float,
    range_min_m: float,
    range_max_m: float,
) -> tuple[NDArray[np.float64], int]:
    """A LaserScan's ranges on a full circle of evenly spaced beams from ``angle_min_rad`` (what
    :class:`~omnical.twin.lidar.LidarParams` describes): beams the scan does not cover, and
    returns outside [range_min, range_max] (REP 117), are NaN. Returns (ranges, beams).

    Raises:
        ProtocolError: a zero or non-finite angle increment.
    """
    inc = float(angle_increment_rad)
    if not (math.isfinite(inc) and abs(inc) > 1e-6):
        msg = f"/scan: angle_increment {inc!r} is not a usable beam spacing"
        raise ProtocolError(msg)
    beams = max(1, round(2.0 * math.pi / abs(inc)))
    r = np.asarray(ranges_m, dtype=np.float64)
    out = np.full(beams, np.nan)
    spacing = 2.0 * math.pi / beams
    idx = np.round(np.arange(len(r)) * inc / spacing).astype(np.int64) % beams
    ok = (r >= range_min_m) & (r <= range_max_m)
    out[idx[ok]] = r[ok]
    return out, beams


def _fast_executor(context: Any) -> Any:
    """rclpy's events executor where it has one (the Jazzy wheels; not Humble's rclpy), else
    None: it takes the rig's messages with less CPU than the single-threaded executor, which
    loses some on a k-times clock (docs/ros2.md)."""
    try:
        from rclpy.experimental.events_executor import EventsExecutor
    except ImportError:
        return None
    return EventsExecutor(context=context)


class Ros2Link:
    """One rclpy context and node, spun by an executor in a thread (no signal handlers: Ctrl-C
    and SIGTERM stay omnical's). A callback's exception is counted (``callback_errors``) and the
    spin goes on. ``close`` shuts it down; idempotent.

    Raises:
        ConfigError: rclpy is not importable (the one line says how to install it; a command
            calls :func:`~omnical.ros2.runtime.ensure_ros_environment` first).
    """

    def __init__(self, name: str = "omnical_rig") -> None:
        from omnical.ros2.runtime import import_rclpy

        rclpy = import_rclpy()
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self._rclpy = rclpy
        self.context = Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.context)
        self._executor = _fast_executor(self.context) or SingleThreadedExecutor(
            context=self.context
        )
        self._executor.add_node(self.node)
        self._stop = threading.Event()
        self._closed = False
        self.callback_errors = 0
        self.last_callback_error: BaseException | None = None
        self._thread = threading.Thread(target=self._spin, name="ros2-spin", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            try:
                self._executor.spin_once(timeout_sec=0.05)
            except Exception as err:  # a callback's: kept, and the spin goes on
                if self._stop.is_set() or not self.context.ok():
                    return  # shutdown under a wait ends the spin
                self.callback_errors += 1
                self.last_callback_error = err

    def topic_types(self, topic: str) -> list[str]:
        """The message types published on ``topic`` now (empty: no publisher known yet)."""
        infos = self.node.get_publishers_info_by_topic(topic)
        return sorted({str(i.topic_type) for i in infos})

    def wait_for_type(self, topic: str, timeout_s: float) -> list[str]:
        """The types of ``topic`` once a publisher is discovered, or [] after ``timeout_s``."""
        end = time.monotonic() + timeout_s
        while True:
            types = self.topic_types(topic)
            if types or time.monotonic() >= end:
                return types
            time.sleep(0.02)

    def qos_for(self, topic: str) -> Any:
        """A subscription QoS that matches the publishers of ``topic``: reliable when every one
        is (no sample lost), best effort otherwise or when none is known yet (matches both)."""
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        infos = self.node.get_publishers_info_by_topic(topic)
        reliable = bool(infos) and all(
            i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos
        )
        policy = ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT
        return QoSProfile(depth=_DEPTH, reliability=policy)

    def close(self) -> None:
        """Stop spinning, destroy the node, shut the context down."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._thread.join(timeout=1.0)
        with contextlib.suppress(Exception):
            self._executor.shutdown(timeout_sec=0.5)
            self.node.destroy_node()
        with contextlib.suppress(Exception):
            self._rclpy.shutdown(context=self.context)


class _Rows:
    """Rows per topic since the last drain, as a hedgehog keeps them (thread-safe by caller)."""

    def __init__(self) -> None:
        self.rows: dict[str, tuple[list[float], dict[str, list[Any]]]] = {}

    def add(self, topic: str, t_s: float, **values: Any) -> None:
        times, cols = self.rows.setdefault(topic, ([], {k: [] for k in values}))
        times.append(t_s)
        for k, v in values.items():
            cols[k].append(v)

    def take(self) -> DeviceRows:
        rows, self.rows = self.rows, {}
        return {
            topic: (np.asarray(t, dtype=np.float64), {k: _column(v) for k, v in cols.items()})
            for topic, (t, cols) in rows.items()
        }


def _column(values: list[Any]) -> NDArray[Any]:
    """A column of rows: (N,) numbers, or (N, k) for per-row arrays (k the longest; JointState
    names as objects, numbers padded with NaN)."""
    if not values or not isinstance(values[0], np.ndarray):
        return np.asarray(values)
    k = max(len(v) for v in values)
    if values[0].dtype == object:
        out = np.full((len(values), k), "", dtype=object)
    else:
        out = np.full((len(values), k), np.nan, dtype=values[0].dtype)
    for i, v in enumerate(values):
        out[i, : len(v)] = v
    return out


@dataclass
class _Guard:
    """The command being streamed and why it was zeroed (the serial driver's rules)."""

    cmd: tuple[float, float, float] = (0.0, 0.0, 0.0)
    last_call_s: float = 0.0
    tripped: bool = False
    fault: SafetyStopError | None = None


class Ros2Robot:
    """A ROS 2 robot as a :class:`~omnical.services.hil.LiveRobot`: ``/cmd_vel`` out, ``/odom``,
    ``/imu``, ``/joint_states`` (and a simulator's ``/ground_truth``) in, stamped on the host
    clock as they arrive.

    The command is republished at ``rate_hz`` until the next (the robot's own driver stops on a
    silent ``/cmd_vel``); it is zeroed when the host stops calling for ``host_watchdog_s``, and
    a motion stops (:class:`SafetyStopError` from the next motion command) when ``/odom`` or a
    required device is silent beyond its limit. The odometry pose is the robot's own,
    from the last ``reset_odometry``; with a correction set (host-side factors) it integrates
    the counter-compensated ``/odom`` twist instead, as the serial driver does.

    Args:
        link: the node to publish and subscribe on.
        robot: the robot description (derived wheel speeds).
        clock: the host's robot-time clock, s.
        stamped: publish ``geometry_msgs/TwistStamped`` instead of ``Twist``.
        rate_hz: command rate (of the wall clock, on a time-scaled clock too).
        host_watchdog_s: zero the command after this long without a call (None: never).
        min_limit_s: the shortest silence limit of ``/odom`` while moving, s.
    """

    def __init__(
        self,
        link: Ros2Link,
        robot: RobotDescription,
        clock: Callable[[], float] = time.monotonic,
        *,
        stamped: bool = False,
        rate_hz: float = 20.0,
        host_watchdog_s: float | None = 0.5,
        min_limit_s: float = ODOM_MIN_LIMIT_S,
    ) -> None:
        from geometry_msgs.msg import Twist, TwistStamped
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import Imu, JointState

        from omnical.kinematics.jacobian import inverse_jacobian

        if not (math.isfinite(rate_hz) and 5.0 <= rate_hz <= 200.0):
            msg = f"command rate must be within 5–200 Hz, got {rate_hz}"
            raise ConfigError(msg)
        if host_watchdog_s is not None and not (
            math.isfinite(host_watchdog_s) and host_watchdog_s > 0.0
        ):  # a NaN never trips
            msg = f"host_watchdog_s must be finite and > 0 or None, got {host_watchdog_s}"
            raise ConfigError(msg)
        self.name = f"ROS 2 robot ({ODOM})"
        self.link, self._clock, self._period = link, clock, 1.0 / rate_hz
        self._stamped = stamped
        self._msg_type = TwistStamped if stamped else Twist
        self._host_watchdog_s = host_watchdog_s
        self._min_limit_s = min_limit_s
        self._J = np.asarray(inverse_jacobian(robot.wheels), dtype=np.float64)
        self._lock = threading.Lock()
        self._guard = _Guard(last_call_s=clock())
        self._required: list[Watched] = []
        self._rows = _Rows()
        self._rx: deque[float] = deque(maxlen=17)
        self._pose = (0.0, 0.0, 0.0)
        self._twist = (0.0, 0.0, 0.0)
        self._raw_twist = (0.0, 0.0, 0.0)
        self._last_odom: tuple[float, float, float, float] | None = None  # stamp s, x, y, yaw
        self._gyro_z = 0.0
        self._correction: CorrectionFactors | None = None
        self._odom_publishers: list[str] = []
        self.published = 0
        node = link.node
        self._pub = node.create_publisher(self._msg_type, CMD_VEL, 10)
        self._subs = [
            node.create_subscription(Odometry, ODOM, self._on_odom, link.qos_for(ODOM)),
            node.create_subscription(Imu, IMU, self._on_imu, link.qos_for(IMU)),
            node.create_subscription(
                JointState, JOINT_STATES, self._on_joints, link.qos_for(JOINT_STATES)
            ),
            node.create_subscription(
                Odometry, GROUND_TRUTH, self._on_truth, link.qos_for(GROUND_TRUTH)
            ),
        ]
        self._closing = self._closed = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="ros2-cmd-vel", daemon=True)
        self._thread.start()

    # ----------------------------------------------------------------- Robot port
    def send_twist(self, vx_mps: float, vy_mps: float, wz_radps: float) -> None:
        """Command a body twist, published at once and at the fixed rate until the next.

        Raises:
            SafetyStopError: ``/odom`` or a required device fell silent, or the command thread
                failed (robot stopped).
            ProtocolError: a motion after ``close`` (nothing is published).
        """
        twist = (float(vx_mps), float(vy_mps), float(wz_radps))
        moving = twist != (0.0, 0.0, 0.0)
        if self._closing:
            if moving:
                msg = f"{self.name}: closed: motion {twist} not published"
                raise ProtocolError(msg)
            return
        if moving and self._guard.fault is None and self._guard.cmd == (0.0, 0.0, 0.0):
            self._watch_at_start()  # never start blind
        with self._lock:
            if moving and self._guard.fault is not None:
                raise self._guard.fault
            changed = twist != self._guard.cmd
            self._guard.cmd, self._guard.last_call_s = twist, self._clock()
            self._guard.tripped = False
        if changed:
            self._publish(twist)

    def read_state(self) -> SerialRobotState:
        """The latest odometry; ``stale`` when ``/odom`` is silent beyond its limit."""
        now = self._clock()
        silence = self.silence(now)
        with self._lock:
            pose, twist, raw, gyro = self._pose, self._twist, self._raw_twist, self._gyro_z
            tripped, seen = self._guard.tripped, self._last_odom is not None
        wheels = tuple(float(w) for w in self._J @ np.asarray(raw)) if seen else ()
        return SerialRobotState(
            t_s=now,
            odom_pose=pose,
            odom_twist=twist,
            wheel_speeds_radps=wheels,
            gyro_z_radps=gyro,
            stale=silence.exceeded,
            age_s=silence.silent_s,
            host_watchdog_tripped=tripped,
        )

    def stop(self) -> None:
        """Command zero, published at once."""
        with self._lock:
            self._guard.cmd, self._guard.last_call_s = (0.0, 0.0, 0.0), self._clock()
        self._publish((0.0, 0.0, 0.0))

    # ----------------------------------------------------------------- watchdog
    def require(self, device: Watched) -> None:
        """Stop the robot when ``device`` is silent beyond its limit while the robot moves."""
        with self._lock:
            self._required.append(device)

    def release(self, device: Watched) -> None:
        """No longer depend on ``device``."""
        with self._lock:
            if device in self._required:
                self._required.remove(device)

    def silence(self, now_s: float) -> Silence:
        """How long ``/odom`` has been silent, and its limit (three of its periods, at least
        :data:`ODOM_MIN_LIMIT_S`); no valid data at all while two nodes publish it."""
        with self._lock:
            rx, publishers = list(self._rx), self._odom_publishers
        if len(publishers) > 1:
            return Silence(self.name, math.inf, 0.0, two_robots(publishers))
        silent = now_s - rx[-1] if rx else math.inf
        return Silence(self.name, silent, stream_limit_s(rx, self._min_limit_s), "nothing received")

    def named_odom_publishers(self, timeout_s: float = 1.0) -> list[str]:
        """:meth:`odom_publishers` once every one's node name is discovered (it follows the
        endpoint), or as they are after ``timeout_s``."""
        end = time.monotonic() + timeout_s
        while True:
            names = self.odom_publishers()
            if not any(_UNKNOWN_NAME in n for n in names) or time.monotonic() >= end:
                return names
            time.sleep(0.05)

    def odom_publishers(self) -> list[str]:
        """The nodes publishing ``/odom`` now, one entry per publisher (more than one: a motion
        is stopped)."""
        infos = self.link.node.get_publishers_info_by_topic(ODOM)
        names = sorted(_node_path(str(i.node_namespace), str(i.node_name)) for i in infos)
        with self._lock:
            self._odom_publishers = names
        return names

    @property
    def safety_stop(self) -> SafetyStopError | None:
        """The safety stop that ended the motion, if one did."""
        return self._guard.fault

    # ----------------------------------------------------------------- odometry, rows
    def drain_rows(self) -> DeviceRows:
        """``/odom``, ``/imu`` and ``/joint_states`` rows since the last call (host times)."""
        with self._lock:
            return self._rows.take()

    def reset_odometry(self, pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        """Restart the odometry pose at ``pose``."""
        with self._lock:
            self._pose = pose

    def set_odometry_correction(self, factors: CorrectionFactors | None) -> None:
        """Counter-compensate every ``/odom`` twist with ``factors`` and integrate it."""
        with self._lock:
            self._correction = factors

    def wait_for_odom(self, timeout_s: float = 2.0) -> None:
        """Wait for the first ``/odom``.

        Raises:
            ProtocolError: none within ``timeout_s``.
        """
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            with self._lock:
                if self._last_odom is not None:
                    return
            time.sleep(0.01)
        domain = os.environ.get("ROS_DOMAIN_ID", "0")
        msg = (
            f"no {ODOM} from the robot within {timeout_s:.1f} s on ROS_DOMAIN_ID {domain} "
            "(is its driver running, on the same domain and discovery range?)"
        )
        raise ProtocolError(msg)

    def check_cmd_vel(self, timeout_s: float = 2.0) -> None:
        """Before anything moves: ``/cmd_vel`` has a subscriber (within ``timeout_s``: discovery)
        and it takes the type this robot publishes.

        Raises:
            ConfigError: nobody subscribes to it, or it is subscribed as the other Twist type.
        """
        end = time.monotonic() + timeout_s
        while True:
            infos = self.link.node.get_subscriptions_info_by_topic(CMD_VEL)
            if infos or time.monotonic() >= end:
                break
            time.sleep(0.02)
        domain = os.environ.get("ROS_DOMAIN_ID", "0")
        if not infos:
            msg = (
                f"nobody subscribes to {CMD_VEL} on ROS_DOMAIN_ID {domain} (waited "
                f"{timeout_s:.1f} s): the robot's driver would not hear a command"
            )
            raise ConfigError(msg)
        types = sorted({str(i.topic_type) for i in infos})
        if CMD_VEL_TYPES[self._stamped] not in types:
            hint = "omit --twist-stamped" if self._stamped else "use --twist-stamped"
            msg = f"the robot subscribes to {CMD_VEL} as {' and '.join(types)}: {hint}"
            raise ConfigError(msg)

    def close(self, linger_s: float = 0.3, ack_timeout_s: float = 0.5) -> None:
        """Publish zero for ``linger_s`` at the command rate (the robot's driver hears it even
        if a sample is lost), wait (bounded) until the subscribers acknowledged it, stop the
        command thread. A motion commanded later is refused. Idempotent. A stop for a second
        ``/odom`` publisher gets the names of nodes not yet named (≤ 1 s more)."""
        if self._closing:
            return
        self._closing = True
        self.stop()
        self._stop.set()
        self._thread.join(timeout=1.0)
        end = time.monotonic() + linger_s
        while True:
            self._publish((0.0, 0.0, 0.0))
            if time.monotonic() >= end:
                break
            time.sleep(min(self._period, max(0.0, end - time.monotonic())))
        with contextlib.suppress(Exception):  # a context already shut down: nothing to wait for
            from rclpy.duration import Duration

            self._pub.wait_for_all_acked(Duration(nanoseconds=round(ack_timeout_s * 1e9)))
        fault = self._guard.fault
        if isinstance(fault, SecondOdomPublisherError) and UNNAMED in str(fault):
            with contextlib.suppress(Exception):  # the stop stands; only its line is completed
                if len(names := self.named_odom_publishers()) > 1:
                    fault.name_publishers(names)
        self._closed = True

    # ----------------------------------------------------------------- internals
    def _publish(self, twist: tuple[float, float, float]) -> None:
        msg = self._msg_type()
        body = msg.twist if self._stamped else msg
        if self._stamped:
            msg.header.stamp = self.link.node.get_clock().now().to_msg()
            msg.header.frame_id = "base_link"
        body.linear.x, body.linear.y, body.angular.z = twist
        with contextlib.suppress(Exception):  # a context shut down under us: nothing to reach
            self._pub.publish(msg)
            self.published += 1

    def _watch(self, *, moving: bool) -> bool:
        """Trip the stop (zero at once, the reason kept) if a needed device is silent."""
        now = self._clock()
        for device in self._watched():
            s = device.silence(now)
            if s.exceeded:
                with self._lock:
                    self._guard.cmd = (0.0, 0.0, 0.0)
                    publishers = self._odom_publishers if device is self else []
                    self._guard.fault = (
                        SecondOdomPublisherError(s.device, publishers, moving)
                        if len(publishers) > 1
                        else SafetyStopError(s.device, s.silent_s, s.detail, moving=moving)
                    )
                self._publish((0.0, 0.0, 0.0))
                return True
        return False

    def _watch_at_start(self) -> None:
        """Before a motion: every needed device within its limit, given one limit to catch up."""
        self.odom_publishers()
        wait_while_silent(self._watched, self._clock, self.silence(self._clock()).limit_s)
        self._watch(moving=False)

    def _watched(self) -> list[Watched]:
        """The devices a motion needs: ``/odom`` and the required ones."""
        with self._lock:
            return [self, *self._required]

    def _loop(self) -> None:
        # paced by the wall clock: on a k-times clock (tests) the robot's driver times out in
        # its own robot time, which the test scales with it; k times the rate would load the
        # machine without reaching a robot any sooner
        next_w = time.monotonic()
        ticks = 0
        while not self._stop.wait(max(0.0, next_w - time.monotonic())):
            next_w += self._period
            wall = time.monotonic()
            if wall > next_w:  # this process stalled: realign
                next_w = wall + self._period
            ticks += 1
            try:
                self._tick(self._clock(), ticks)
            except Exception as err:  # the stream goes on, at zero; the next motion raises
                self._fail(err)

    def _tick(self, now: float, ticks: int) -> None:
        g = self._guard
        if ticks % 10 == 0:  # a second robot on the domain, discovered late
            self.odom_publishers()
        if g.cmd != (0.0, 0.0, 0.0) and g.fault is None:
            self._watch(moving=True)
        with self._lock:
            wd = self._host_watchdog_s
            if wd is not None and g.cmd != (0.0, 0.0, 0.0) and now - g.last_call_s > wd:
                g.cmd, g.tripped = (0.0, 0.0, 0.0), True
            cmd = g.cmd
        self._publish(cmd)

    def _fail(self, err: BaseException) -> None:
        """The command thread failed a tick: zero at once, the fault kept for the next motion."""
        with self._lock:
            moving = self._guard.cmd != (0.0, 0.0, 0.0)
            self._guard.cmd = (0.0, 0.0, 0.0)
            if self._guard.fault is None:
                age = self._clock() - self._rx[-1] if self._rx else math.inf
                self._guard.fault = SafetyStopError(
                    self.name, age, f"command thread failed: {err!r}", moving=moving
                )
        self._publish((0.0, 0.0, 0.0))

    def _on_odom(self, msg: Any) -> None:
        t = self._clock()
        p, q, tw = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
        yaw = yaw_from_quaternion(q.x, q.y, q.z, q.w)
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9 or t  # unstamped: rx
        raw = (float(tw.linear.x), float(tw.linear.y), float(tw.angular.z))
        with self._lock:
            factors, last = self._correction, self._last_odom
            twist = raw
            if factors is not None:
                from omnical.kinematics.correction import counter_compensate_twist_scalar

                twist = counter_compensate_twist_scalar(*raw, factors)
            x, y, th = self._pose
            if last is not None and factors is None:  # the robot's own pose change
                dx, dy = p.x - last[1], p.y - last[2]
                c, s = math.cos(last[3]), math.sin(last[3])
                bx, by = c * dx + s * dy, -s * dx + c * dy
                c, s = math.cos(th), math.sin(th)
                x, y, th = x + c * bx - s * by, y + s * bx + c * by, th + wrap_angle(yaw - last[3])
            elif last is not None:  # the counter-compensated twist, over the robot's time step
                dt = stamp - last[0] if stamp > last[0] else 0.0
                dt = dt if dt < 1.0 else 0.0
                mid = th + 0.5 * twist[2] * dt
                vx, vy = twist[0], twist[1]
                x += (vx * math.cos(mid) - vy * math.sin(mid)) * dt
                y += (vx * math.sin(mid) + vy * math.cos(mid)) * dt
                th += twist[2] * dt
            self._pose, self._twist, self._raw_twist = (x, y, th), twist, raw
            self._last_odom = (stamp, float(p.x), float(p.y), yaw)
            self._rx.append(t)
            self._rows.add(
                ODOM, t, x_m=x, y_m=y, yaw_rad=th,
                vx_mps=twist[0], vy_mps=twist[1], wz_radps=twist[2],
            )  # fmt: skip

    def _on_truth(self, msg: Any) -> None:
        """A simulator's true pose (``omnical ros2 twin``), recorded as it came."""
        t = self._clock()
        p, q, tw = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
        with self._lock:
            self._rows.add(
                GROUND_TRUTH, t, x_m=p.x, y_m=p.y, yaw_rad=yaw_from_quaternion(q.x, q.y, q.z, q.w),
                vx_mps=tw.linear.x, vy_mps=tw.linear.y, wz_radps=tw.angular.z,
            )  # fmt: skip

    def _on_imu(self, msg: Any) -> None:
        t = self._clock()
        g, a = msg.angular_velocity, msg.linear_acceleration
        with self._lock:
            self._gyro_z = float(g.z)
            self._rows.add(
                IMU, t, gyro_x_radps=g.x, gyro_y_radps=g.y, gyro_z_radps=g.z,
                acc_x_mps2=a.x, acc_y_mps2=a.y, acc_z_mps2=a.z,
            )  # fmt: skip

    def _on_joints(self, msg: Any) -> None:
        t = self._clock()
        with self._lock:
            self._rows.add(
                JOINT_STATES,
                t,
                name=np.array(list(msg.name), dtype=object),
                position_rad=np.asarray(msg.position, dtype=np.float64),
                velocity_radps=np.asarray(msg.velocity, dtype=np.float64),
                effort_nm=np.asarray(msg.effort, dtype=np.float64),
            )


def _node_path(namespace: str, name: str) -> str:
    """A node's full name (``/ns/name``) from its namespace and name."""
    return f"{namespace.rstrip('/')}/{name}"


class Ros2Lidar:
    """A robot's ``/scan`` as a :class:`~omnical.services.hil.LiveLidar`: the beams of its
    newest scan on a full circle at the description's mounting, its rows recorded. It is
    watched (``silence``: three of its periods, at least ``min_limit_s``), and a scan older than
    that is refused: a robot localised on it must not go on with a dead LiDAR."""

    def __init__(
        self,
        link: Ros2Link,
        robot: RobotDescription,
        clock: Callable[[], float],
        *,
        min_limit_s: float = SCAN_MIN_LIMIT_S,
    ) -> None:
        from sensor_msgs.msg import LaserScan

        self.name = f"LiDAR ({SCAN})"
        self._robot, self._clock, self._min_limit_s = robot, clock, min_limit_s
        self._lock = threading.Lock()
        self._rows = _Rows()
        self._rx: deque[float] = deque(maxlen=17)
        self._latest: Any = None
        self._latest_s = math.nan  # the newest scan's mean ray time, robot's clock
        self._offsets: deque[float] = deque(maxlen=SCAN_CLOCK_WINDOW)  # receipt − ray time
        self._sub = link.node.create_subscription(
            LaserScan, SCAN, self._on_scan, link.qos_for(SCAN)
        )

    def wait_for_scan(self, timeout_s: float) -> bool:
        """True once a scan has arrived (within ``timeout_s``)."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if self._latest is not None:
                return True
            time.sleep(0.01)
        return self._latest is not None

    def lidar_params(self) -> LidarParams:
        """The newest scan's beams (a full circle), range limits and rate, at the mounting of
        the robot description (ConfigError: no scan yet)."""
        from omnical.twin.lidar import LidarParams

        with self._lock:
            m, rx = self._latest, list(self._rx)
        if m is None:
            msg = f"no {SCAN} from the robot yet: it cannot be localised on its LiDAR"
            raise ConfigError(msg)
        _, beams = full_circle_ranges(
            np.zeros(0), m.angle_min, m.angle_increment, m.range_min, m.range_max
        )
        rate = 1.0 / m.scan_time if m.scan_time > 0 else 3.0 / stream_limit_s(rx, 0.0, 1e9)
        mount = self._robot.lidar_mount
        return LidarParams(
            beams=beams,
            angle_min_rad=float(m.angle_min),
            range_min_m=float(m.range_min),
            range_max_m=float(m.range_max),
            range_sigma_m=0.0,
            range_resolution_m=0.0,
            dropout_probability=0.0,
            rate_hz=float(rate),
            mount_pose=(mount.x_m, mount.y_m, mount.yaw_rad),
            frame_id=str(m.header.frame_id) or "laser",
        )

    def silence(self, now_s: float) -> Silence:
        """Time since the last scan; three of its periods, within ``min_limit_s`` and 2 s."""
        with self._lock:
            rx = list(self._rx)
        silent = now_s - rx[-1] if rx else math.inf
        limit = stream_limit_s(rx, self._min_limit_s, 2.0)
        return Silence(self.name, silent, limit, "nothing received")

    def scan_now(self) -> NDArray[np.float64]:
        """The newest scan's ranges on the full circle, m (NaN: no valid return).

        Raises:
            ConfigError: no scan yet.
            SafetyStopError: the newest is older than the silence limit (the LiDAR died).
        """
        with self._lock:
            m = self._latest
        if m is None:
            self.lidar_params()  # raises: no scan yet
        s = self.silence(self._clock())
        if s.exceeded:
            raise SafetyStopError(s.device, s.silent_s, s.detail)
        ranges, _ = full_circle_ranges(
            np.asarray(m.ranges), m.angle_min, m.angle_increment, m.range_min, m.range_max
        )
        return ranges

    def scan_age_s(self) -> float:
        """How long ago (host clock, s) the newest scan's rays were taken: from its stamp (plus
        half its sweep when ``time_increment`` says the rays are spread), on the host clock by
        the smallest receipt delay of the last :data:`SCAN_CLOCK_WINDOW` scans (the robot's
        clock and the host's differ by a constant; the smallest delay is the transport's).
        0 before a scan or for an unstamped one (timed by its receipt)."""
        with self._lock:
            if not self._offsets or not math.isfinite(self._latest_s):
                return 0.0
            taken = self._latest_s + min(self._offsets)
        return max(0.0, self._clock() - taken)

    def drain(self) -> DeviceRows:
        """The ``/scan`` rows since the last call (host times)."""
        with self._lock:
            return self._rows.take()

    def _on_scan(self, m: Any) -> None:
        t = self._clock()
        stamp = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        sweep = max(0.0, float(m.time_increment)) * max(0, len(m.ranges) - 1)
        with self._lock:
            self._latest = m
            if stamp > 0.0:
                self._latest_s = stamp + 0.5 * sweep
                self._offsets.append(t - self._latest_s)
            else:
                self._latest_s = math.nan
            self._rx.append(t)
            self._rows.add(
                SCAN, t,
                angle_min_rad=m.angle_min, angle_max_rad=m.angle_max,
                angle_increment_rad=m.angle_increment, time_increment_s=m.time_increment,
                scan_time_s=m.scan_time, range_min_m=m.range_min, range_max_m=m.range_max,
                ranges_m=np.asarray(m.ranges, dtype=np.float32),
                intensities=np.asarray(m.intensities, dtype=np.float32),
            )  # fmt: skip


class TopicHedgehog:
    """A hedgehog's positions from a ROS 2 topic (``PointStamped`` or
    ``PoseWithCovarianceStamped``) as a :class:`~omnical.services.hil.LiveHedgehog`, recorded as
    ``/hedge_pos_ang`` rows (address 0, flags 0; no raw distances: the campaign needs the
    hedgehog's serial stream). The beacon map comes from ``--beacons``."""

    def __init__(
        self,
        link: Ros2Link,
        topic: str,
        clock: Callable[[], float],
        *,
        timeout_s: float = 2.0,
        min_limit_s: float = 0.3,
    ) -> None:
        from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped

        types = link.wait_for_type(topic, timeout_s)
        if not types:
            msg = f"--hedge topic:{topic}: nobody publishes it (waited {timeout_s:.1f} s)"
            raise ProtocolError(msg)
        if types[0] not in HEDGE_TOPIC_TYPES:
            msg = f"--hedge topic:{topic} carries {types[0]}; use {' or '.join(HEDGE_TOPIC_TYPES)}"
            raise ConfigError(msg)
        self.name = f"hedgehog on {topic}"
        self._clock, self._min_limit_s = clock, min_limit_s
        self._lock = threading.Lock()
        self._rows = _Rows()
        self._rx: deque[float] = deque(maxlen=17)
        self._latest: HedgeFix | None = None
        kind = PointStamped if types[0] == HEDGE_TOPIC_TYPES[0] else PoseWithCovarianceStamped
        self._sub = link.node.create_subscription(kind, topic, self._on_fix, link.qos_for(topic))

    @property
    def beacons(self) -> dict[int, tuple[float, float, float]]:
        """None streamed: a position topic carries no beacon map."""
        return {}

    def latest_fix(self) -> HedgeFix | None:
        """The newest position."""
        with self._lock:
            return self._latest

    def silence(self, now_s: float) -> Silence:
        """Time since the last position; three of its periods at least ``min_limit_s``."""
        with self._lock:
            rx = list(self._rx)
        silent = now_s - rx[-1] if rx else math.inf
        return Silence(self.name, silent, stream_limit_s(rx, self._min_limit_s), "nothing received")

    def drain(self) -> DeviceRows:
        """The ``/hedge_pos_ang`` rows since the last call (host times)."""
        with self._lock:
            return self._rows.take()

    def close(self) -> None:
        """Nothing of its own: the link closes the node."""

    def _on_fix(self, m: Any) -> None:
        t = self._clock()
        p = m.pose.pose.position if hasattr(m, "pose") else m.point
        stamp_ms = m.header.stamp.sec * 1000 + m.header.stamp.nanosec // 1_000_000
        fix = HedgeFix(t, float(p.x), float(p.y), float(p.z), int(stamp_ms))
        with self._lock:
            self._latest = fix
            self._rx.append(t)
            self._rows.add(
                HEDGE_POS_ANG, t, address=0, timestamp_ms=int(stamp_ms),
                x_m=fix.x_m, y_m=fix.y_m, z_m=fix.z_m, flags=0, angle_deg=0.0,
            )  # fmt: skip


@contextlib.contextmanager
def ros2_devices(
    robot: RobotDescription,
    clock: HostClock,
    *,
    hedge_port: str | None = None,
    hedge_topic: str | None = None,
    hedge_baud: int = 115200,
    stamped: bool = False,
    host_watchdog_s: float | None = 0.5,
    lidar: bool = True,
    say: Callable[[str], None] = print,
) -> Iterator[tuple[Ros2Robot, LiveHedgehog | None, Ros2Lidar | None]]:
    """The ROS 2 robot, its hedgehog (on a serial port, a topic, or none) and its LiDAR (None:
    ``lidar`` off, or no ``/scan`` within 1 s), checked before anything moves: ``/odom`` within
    2 s, a ``/cmd_vel`` subscriber of the type published. Leaving publishes zero and closes
    everything, whatever happened.

    Raises:
        ConfigError: rclpy missing; a hedgehog topic of another type; two ``/odom`` publishers;
            nobody subscribes to ``/cmd_vel``, or as the other Twist type.
        ProtocolError: no ``/odom``, or nobody publishes the hedgehog topic.
        DriverError: the hedgehog's port cannot be opened.
    """
    started = time.monotonic()
    link = Ros2Link()
    driver: Ros2Robot | None = None
    hedge: LiveHedgehog | None = None
    try:
        link.wait_for_type(ODOM, 2.0)  # its QoS known before subscribing (reliable if it is)
        for topic in (IMU, JOINT_STATES, *([SCAN] if lidar else [])):
            link.wait_for_type(topic, 0.2)
        k = clock.time_scale
        driver = Ros2Robot(
            link,
            robot,
            clock.now_s,
            stamped=stamped,
            host_watchdog_s=None if host_watchdog_s is None else host_watchdog_s * k,
            min_limit_s=scaled_limit_s(ODOM_MIN_LIMIT_S, k),
        )
        driver.wait_for_odom(2.0)
        driver.check_cmd_vel(3.0)  # time for discovery (docs/ros2.md)
        while True:  # two robots (or a robot and a test) on one domain: whose /cmd_vel?
            if len(driver.odom_publishers()) > 1:
                raise ConfigError(two_robots(driver.named_odom_publishers()))
            if time.monotonic() >= started + 1.0:  # discovery may take longer: watched later
                break
            time.sleep(0.02)
        scanner = None
        if lidar and link.topic_types(SCAN):
            scanner = Ros2Lidar(
                link, robot, clock.now_s, min_limit_s=scaled_limit_s(SCAN_MIN_LIMIT_S, k)
            )
            if not scanner.wait_for_scan(1.0):
                scanner = None
        have = [t for t in (IMU, JOINT_STATES, GROUND_TRUTH) if link.topic_types(t)]
        kind = "TwistStamped" if stamped else "Twist"
        laser = f", {SCAN} ({scanner.lidar_params().beams} beams)" if scanner else f", no {SCAN}"
        say(
            f"ROS 2 robot: {ODOM}{''.join(', ' + t for t in have)}{laser}; "
            f"commanding {CMD_VEL} ({kind})"
        )
        if hedge_port is not None:
            hedge = open_serial_hedgehog(hedge_port, hedge_baud, clock)
        elif hedge_topic is not None:
            hedge = TopicHedgehog(
                link, hedge_topic, clock.now_s, min_limit_s=scaled_limit_s(0.3, k)
            )
        yield driver, hedge, scanner
    finally:
        if driver is not None:
            driver.close()
        if hedge is not None:
            hedge.close()
        link.close()
