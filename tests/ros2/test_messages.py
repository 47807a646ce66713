"""omnical's ROS 2 messages on the wire: rclpy's CDR bytes (in a subprocess with the extra) decoded
by rosbags' ROS 2 store field by field, and re-encoded by rosbags to the same bytes but padding."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from functools import cache
from typing import Any

import numpy as np
import pytest
from ros2_env import HERE, needs_ros2

from omnical.bags.typestores import typestore
from omnical.ros2.messages import (
    WHEELTEC_MOVING_COVARIANCE_DIAG,
    covariance_from_msg,
    covariance_to_msg,
    planar_covariance,
    quaternion_from_yaw,
    yaw_from_quaternion,
)

pytestmark = needs_ros2
T_NS = 1_795_954_110_944_749_520


@cache
def wire() -> dict[str, bytes]:
    done = subprocess.run(
        [sys.executable, str(HERE / "ros2_wire.py")],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    return {k: bytes.fromhex(v) for k, v in json.loads(done.stdout).items()}


def trimmed(name: str) -> bytes:
    """rclpy's bytes without the end padding rosbags refuses: Fast CDR aligns an empty float64
    sequence at the end (JointState's efforts) to 8, 4 bytes past what rosbags allows (3)."""
    data = wire()[name]
    return data[:-4] if name == "sensor_msgs/msg/JointState" else data


def decoded(name: str) -> Any:
    return typestore(2).deserialize_cdr(trimmed(name), name)


@pytest.mark.parametrize(
    "name",
    [
        "nav_msgs/msg/Odometry",
        "sensor_msgs/msg/Imu",
        "sensor_msgs/msg/JointState",
        "sensor_msgs/msg/LaserScan",
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        "geometry_msgs/msg/TransformStamped",
        "nav_msgs/msg/OccupancyGrid",
    ],
)
def test_rosbags_re_encodes_rclpys_bytes_identically_but_the_padding(name: str) -> None:
    # Fast CDR leaves alignment padding (after a string) as it was in memory; rosbags writes 0
    store = typestore(2)
    data = trimmed(name)
    again = bytes(store.serialize_cdr(store.deserialize_cdr(data, name), name))
    assert len(again) == len(data)
    differ = [i for i, (a, b) in enumerate(zip(data, again, strict=True)) if a != b]
    assert all(again[i] == 0 for i in differ)
    assert len(differ) <= 7 * 3  # at most 7 bytes after each of ≤ 3 strings


def test_odometry_fields_and_covariances_round_trip() -> None:
    odom = decoded("nav_msgs/msg/Odometry")
    assert odom.header.stamp.sec * 10**9 + odom.header.stamp.nanosec == T_NS
    assert (odom.header.frame_id, odom.child_frame_id) == ("odom", "base_link")
    q = odom.pose.pose.orientation
    assert yaw_from_quaternion(q.x, q.y, q.z, q.w) == pytest.approx(2.5, abs=1e-12)
    assert (odom.pose.pose.position.x, odom.pose.pose.position.y) == (1.5, -2.25)
    assert odom.twist.twist.linear.x == 0.3 and odom.twist.twist.angular.z == 0.7
    pose_cov = np.arange(36, dtype=float).reshape(6, 6) * 1e-3
    assert np.array_equal(covariance_from_msg(odom.pose.covariance), pose_cov)
    assert np.array_equal(
        covariance_from_msg(odom.twist.covariance), np.diag(WHEELTEC_MOVING_COVARIANCE_DIAG)
    )


def test_imu_says_it_has_no_orientation() -> None:
    imu = decoded("sensor_msgs/msg/Imu")
    assert imu.orientation_covariance[0] == -1.0
    assert imu.angular_velocity.z == 0.5
    assert imu.angular_velocity_covariance[8] == pytest.approx(4e-6)
    assert imu.linear_acceleration.z == 9.81


def test_scan_ranges_keep_rep_117_infinities_and_nan() -> None:
    scan = decoded("sensor_msgs/msg/LaserScan")
    r = scan.ranges
    assert r[0] == 1.0 and r[1] == math.inf and r[2] == -math.inf and math.isnan(r[3])
    assert scan.angle_max == pytest.approx(-math.pi + 3 * math.pi / 2, abs=1e-6)
    assert scan.header.frame_id == "laser"


def test_fix_pose_and_grid_and_transform() -> None:
    fix = decoded("geometry_msgs/msg/PoseWithCovarianceStamped")
    assert (fix.pose.pose.position.x, fix.pose.pose.position.z) == (3.0, 1.25)
    assert fix.header.frame_id == "map" and fix.pose.covariance[0] == 4e-4
    grid = decoded("nav_msgs/msg/OccupancyGrid")
    assert (grid.info.width, grid.info.height) == (3, 2)
    assert grid.info.resolution == pytest.approx(0.05, rel=1e-7)  # float32
    assert list(grid.data) == [0, 100, -1, 100, 0, 0]  # row 0 (the bottom) first
    assert grid.info.origin.position.x == -1.0
    tf = decoded("geometry_msgs/msg/TransformStamped")
    assert (tf.header.frame_id, tf.child_frame_id) == ("odom", "base_link")
    assert tf.transform.rotation.z == pytest.approx(math.sin(0.25))
    joints = decoded("sensor_msgs/msg/JointState")
    assert list(joints.name) == ["a", "b"] and list(joints.velocity) == [0.5, -0.5]


def test_planar_covariance_places_x_y_yaw() -> None:
    c = planar_covariance([[1.0, 0.1, 0.2], [0.1, 2.0, 0.3], [0.2, 0.3, 3.0]])
    assert c[0, 0] == 1.0 and c[1, 1] == 2.0 and c[5, 5] == 3.0 and c[0, 5] == 0.2
    assert c[1, 5] == 0.3 and c[2, 2] == 1e6
    assert covariance_to_msg(np.ones(6))[7] == 1.0
    assert quaternion_from_yaw(math.pi)[3] == pytest.approx(0.0, abs=1e-15)
