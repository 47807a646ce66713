"""Builds one of each message omnical.ros2.messages makes and prints their CDR bytes (hex) as
serialised by rclpy, as JSON: tests/ros2/test_messages.py decodes them with rosbags."""

from __future__ import annotations

import json
import math

from omnical.ros2.runtime import ensure_ros_environment, import_rclpy


def main() -> None:
    ensure_ros_environment()
    import_rclpy()
    import numpy as np
    from rclpy.serialization import deserialize_message, serialize_message

    from omnical.ros2 import messages as m

    t_ns = 1_795_954_110_944_749_520
    pose_cov = np.arange(36, dtype=float).reshape(6, 6) * 1e-3
    built = {
        "nav_msgs/msg/Odometry": m.odometry_msg(
            t_ns, (1.5, -2.25, 2.5), (0.3, -0.1, 0.7), pose_cov, m.WHEELTEC_MOVING_COVARIANCE_DIAG
        ),
        "sensor_msgs/msg/Imu": m.imu_msg(
            t_ns, (0.01, -0.02, 0.5), (0.1, 0.2, 9.81), gyro_variance=4e-6, accel_variance=9e-4
        ),
        "sensor_msgs/msg/JointState": m.joint_state_msg(t_ns, ["a", "b"], [1.0, -2.0], [0.5, -0.5]),
        "sensor_msgs/msg/LaserScan": m.laser_scan_msg(
            t_ns,
            [1.0, math.inf, -math.inf, math.nan],
            angle_min_rad=-math.pi,
            angle_increment_rad=math.pi / 2,
            range_min_m=0.15,
            range_max_m=12.0,
            scan_period_s=0.1,
            frame_id="laser",
        ),
        "geometry_msgs/msg/PoseWithCovarianceStamped": m.pose_with_covariance_msg(
            t_ns, (3.0, 4.0, -1.0), np.diag([4e-4, 4e-4, 1e6, 1e6, 1e6, 1e6]), z_m=1.25
        ),
        "geometry_msgs/msg/TransformStamped": m.transform_msg(t_ns, (1.0, 2.0, 0.5)),
        "nav_msgs/msg/OccupancyGrid": m.occupancy_grid_msg(
            t_ns, np.array([[0, 100, -1], [100, 0, 0]], dtype=np.int8), 0.05, (-1.0, -2.0, 0.0)
        ),
    }
    out = {}
    for name, msg in built.items():
        data = serialize_message(msg)
        again = serialize_message(deserialize_message(data, type(msg)))
        assert again == data, name
        out[name] = data.hex()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
