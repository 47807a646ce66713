"""omnical's values as ROS 2 messages and back: stamps, yaw quaternions, 6×6 covariances, Odometry,
Imu, JointState, LaserScan, PoseWithCovarianceStamped, OccupancyGrid, TransformStamped.

Message classes are imported inside the functions (after :func:`omnical.ros2.runtime.import_rclpy`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError

__all__ = [
    "WHEELTEC_MOVING_COVARIANCE_DIAG",
    "WHEELTEC_STOPPED_COVARIANCE_DIAG",
    "covariance_from_msg",
    "covariance_to_msg",
    "imu_msg",
    "joint_state_msg",
    "laser_scan_msg",
    "ns_from_stamp",
    "occupancy_grid_msg",
    "odometry_fields",
    "odometry_msg",
    "planar_covariance",
    "pose_with_covariance_msg",
    "quaternion_from_yaw",
    "stamp_from_ns",
    "transform_msg",
    "yaw_from_quaternion",
]

WHEELTEC_MOVING_COVARIANCE_DIAG = (1e-3, 1e-3, 1e6, 1e6, 1e6, 1e3)
"""The diagonal the Wheeltec ROS driver publishes in /odom's pose and twist covariances while
the robot moves (x, y, z, roll, pitch, yaw; docs: shared/reference/wheeltec.md §3.1)."""
WHEELTEC_STOPPED_COVARIANCE_DIAG = (1e-9, 1e-3, 1e6, 1e6, 1e6, 1e-9)
"""The same while the reported velocity is zero."""


def stamp_from_ns(t_ns: int) -> Any:
    """``builtin_interfaces/Time`` of a time in ns (sec, nanosec; negative times refused)."""
    from builtin_interfaces.msg import Time

    t = int(t_ns)
    if t < 0:
        msg = f"ROS 2 stamp: negative time {t} ns"
        raise ConfigError(msg)
    return Time(sec=t // 1_000_000_000, nanosec=t % 1_000_000_000)


def ns_from_stamp(stamp: Any) -> int:
    """Nanoseconds of a ``builtin_interfaces/Time``."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def quaternion_from_yaw(yaw_rad: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw_rad`` about z."""
    half = 0.5 * float(yaw_rad)
    return (0.0, 0.0, math.sin(half), math.cos(half))


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """Yaw (rad, in (-π, π]) of a quaternion (its rotation's heading about z)."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def planar_covariance(
    cov_xy_yaw: ArrayLike, *, unused_variance: float = 1e6
) -> NDArray[np.float64]:
    """The 6×6 ROS covariance (x, y, z, roll, pitch, yaw) of a 3×3 (x, y, yaw) covariance, the
    out-of-plane variances set to ``unused_variance`` (REP 105 robots: "not measured")."""
    c = np.asarray(cov_xy_yaw, dtype=np.float64)
    if c.shape != (3, 3) or not np.all(np.isfinite(c)):
        msg = f"planar covariance: expected a finite 3×3 matrix, got shape {c.shape}"
        raise ConfigError(msg)
    out = np.zeros((6, 6))
    idx = (0, 1, 5)
    for i, a in enumerate(idx):
        for j, b in enumerate(idx):
            out[a, b] = c[i, j]
    out[2, 2] = out[3, 3] = out[4, 4] = unused_variance
    return out


def covariance_to_msg(cov: ArrayLike) -> list[float]:
    """The 36 row-major floats of a 6×6 covariance (a diagonal of 6 is accepted too)."""
    c = np.asarray(cov, dtype=np.float64)
    if c.shape == (6,):
        c = np.diag(c)
    if c.shape != (6, 6):
        msg = f"ROS covariance: expected 6×6 or a diagonal of 6, got shape {c.shape}"
        raise ConfigError(msg)
    return [float(v) for v in c.ravel()]


def covariance_from_msg(values: Sequence[float]) -> NDArray[np.float64]:
    """The 6×6 matrix of a message's 36 row-major floats."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.shape != (36,):
        msg = f"ROS covariance: expected 36 values, got {arr.shape[0]}"
        raise ConfigError(msg)
    return arr.reshape(6, 6)


def _header(t_ns: int, frame_id: str) -> Any:
    from std_msgs.msg import Header

    return Header(stamp=stamp_from_ns(t_ns), frame_id=frame_id)


def odometry_msg(
    t_ns: int,
    pose: Sequence[float],
    twist: Sequence[float],
    pose_covariance: ArrayLike,
    twist_covariance: ArrayLike,
    *,
    frame_id: str = "odom",
    child_frame_id: str = "base_link",
) -> Any:
    """``nav_msgs/Odometry``: planar pose (x m, y m, yaw rad) in ``frame_id``, body twist (vx m/s,
    vy m/s, wz rad/s) in ``child_frame_id``, covariances 6×6 (or diagonals)."""
    from geometry_msgs.msg import (
        Point,
        Pose,
        PoseWithCovariance,
        Quaternion,
        Twist,
        TwistWithCovariance,
        Vector3,
    )
    from nav_msgs.msg import Odometry

    x, y, yaw = (float(v) for v in pose)
    vx, vy, wz = (float(v) for v in twist)
    qx, qy, qz, qw = quaternion_from_yaw(yaw)
    return Odometry(
        header=_header(t_ns, frame_id),
        child_frame_id=child_frame_id,
        pose=PoseWithCovariance(
            pose=Pose(
                position=Point(x=x, y=y, z=0.0), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw)
            ),
            covariance=covariance_to_msg(pose_covariance),
        ),
        twist=TwistWithCovariance(
            twist=Twist(linear=Vector3(x=vx, y=vy, z=0.0), angular=Vector3(x=0.0, y=0.0, z=wz)),
            covariance=covariance_to_msg(twist_covariance),
        ),
    )


def odometry_fields(msg: Any) -> tuple[int, tuple[float, float, float], tuple[float, float, float]]:
    """(stamp ns, (x, y, yaw), (vx, vy, wz)) of a ``nav_msgs/Odometry``."""
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
    return (
        ns_from_stamp(msg.header.stamp),
        (float(p.x), float(p.y), yaw_from_quaternion(q.x, q.y, q.z, q.w)),
        (float(lin.x), float(lin.y), float(ang.z)),
    )


def imu_msg(
    t_ns: int,
    gyro_radps: Sequence[float],
    accel_mps2: Sequence[float],
    *,
    gyro_variance: float,
    accel_variance: float,
    frame_id: str = "imu_link",
) -> Any:
    """``sensor_msgs/Imu`` without an orientation (covariance[0] = -1, as REP 145 says)."""
    from geometry_msgs.msg import Vector3
    from sensor_msgs.msg import Imu

    g = [float(v) for v in gyro_radps]
    a = [float(v) for v in accel_mps2]
    no_orientation = [-1.0] + [0.0] * 8
    return Imu(
        header=_header(t_ns, frame_id),
        orientation_covariance=no_orientation,
        angular_velocity=Vector3(x=g[0], y=g[1], z=g[2]),
        angular_velocity_covariance=[float(v) for v in np.diag([gyro_variance] * 3).ravel()],
        linear_acceleration=Vector3(x=a[0], y=a[1], z=a[2]),
        linear_acceleration_covariance=[float(v) for v in np.diag([accel_variance] * 3).ravel()],
    )


def joint_state_msg(
    t_ns: int, names: Sequence[str], positions_rad: ArrayLike, velocities_radps: ArrayLike
) -> Any:
    """``sensor_msgs/JointState`` of wheel joints (no efforts)."""
    from sensor_msgs.msg import JointState

    pos = np.asarray(positions_rad, dtype=np.float64).ravel()
    vel = np.asarray(velocities_radps, dtype=np.float64).ravel()
    if not len(names) == len(pos) == len(vel):
        msg = "joint states: names, positions and velocities differ in length"
        raise ConfigError(msg)
    return JointState(
        header=_header(t_ns, ""), name=list(names), position=pos.tolist(), velocity=vel.tolist()
    )


def laser_scan_msg(
    t_ns: int,
    ranges_m: ArrayLike,
    *,
    angle_min_rad: float,
    angle_increment_rad: float,
    range_min_m: float,
    range_max_m: float,
    scan_period_s: float,
    frame_id: str,
    time_increment_s: float = 0.0,
) -> Any:
    """``sensor_msgs/LaserScan`` (ranges as REP 117: ±inf out of range, NaN for no return);
    ``time_increment_s`` 0: every ray taken at the stamp (a simulated scan of one pose)."""
    from sensor_msgs.msg import LaserScan

    r = np.asarray(ranges_m, dtype=np.float32).ravel()
    return LaserScan(
        header=_header(t_ns, frame_id),
        angle_min=float(angle_min_rad),
        angle_max=float(angle_min_rad + angle_increment_rad * (len(r) - 1)),
        angle_increment=float(angle_increment_rad),
        time_increment=float(time_increment_s),
        scan_time=float(scan_period_s),
        range_min=float(range_min_m),
        range_max=float(range_max_m),
        ranges=r.tolist(),
    )


def pose_with_covariance_msg(
    t_ns: int,
    pose: Sequence[float],
    covariance: ArrayLike,
    *,
    frame_id: str = "map",
    z_m: float = 0.0,
) -> Any:
    """``geometry_msgs/PoseWithCovarianceStamped`` of a planar pose (x, y, yaw) at height ``z_m``."""
    from geometry_msgs.msg import (
        Point,
        Pose,
        PoseWithCovariance,
        PoseWithCovarianceStamped,
        Quaternion,
    )

    x, y, yaw = (float(v) for v in pose)
    qx, qy, qz, qw = quaternion_from_yaw(yaw)
    return PoseWithCovarianceStamped(
        header=_header(t_ns, frame_id),
        pose=PoseWithCovariance(
            pose=Pose(
                position=Point(x=x, y=y, z=float(z_m)),
                orientation=Quaternion(x=qx, y=qy, z=qz, w=qw),
            ),
            covariance=covariance_to_msg(covariance),
        ),
    )


def transform_msg(
    t_ns: int,
    pose: Sequence[float],
    *,
    frame_id: str = "odom",
    child_frame_id: str = "base_link",
    z_m: float = 0.0,
) -> Any:
    """``geometry_msgs/TransformStamped`` of ``child_frame_id`` at planar ``pose`` in ``frame_id``
    (``z_m`` above it)."""
    from geometry_msgs.msg import Quaternion, Transform, TransformStamped, Vector3

    x, y, yaw = (float(v) for v in pose)
    qx, qy, qz, qw = quaternion_from_yaw(yaw)
    return TransformStamped(
        header=_header(t_ns, frame_id),
        child_frame_id=child_frame_id,
        transform=Transform(
            translation=Vector3(x=x, y=y, z=float(z_m)), rotation=Quaternion(x=qx, y=qy, z=qz, w=qw)
        ),
    )


def occupancy_grid_msg(
    t_ns: int,
    cells: ArrayLike,
    resolution_m: float,
    origin: Sequence[float],
    *,
    frame_id: str = "map",
) -> Any:
    """``nav_msgs/OccupancyGrid`` of an int8 grid (0 free, 100 occupied, -1 unknown; row 0 at
    the bottom, as omnical's :class:`~omnical.navigation.grid.OccupancyGrid` and ROS store it)."""
    from geometry_msgs.msg import Point, Pose, Quaternion
    from nav_msgs.msg import MapMetaData, OccupancyGrid

    c = np.asarray(cells, dtype=np.int8)
    if c.ndim != 2:
        msg = f"occupancy grid: expected a 2-D array, got shape {c.shape}"
        raise ConfigError(msg)
    x, y, yaw = (float(v) for v in origin)
    qx, qy, qz, qw = quaternion_from_yaw(yaw)
    stamp = stamp_from_ns(t_ns)
    return OccupancyGrid(
        header=_header(t_ns, frame_id),
        info=MapMetaData(
            map_load_time=stamp,
            resolution=float(resolution_m),
            width=int(c.shape[1]),
            height=int(c.shape[0]),
            origin=Pose(
                position=Point(x=x, y=y, z=0.0), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw)
            ),
        ),
        data=c.ravel().tolist(),
    )
