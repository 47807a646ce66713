"""An independent rclpy process that drives and watches a ROS 2 robot; prints JSON at the end.

Run by tests/ros2/test_twin_node.py beside ``omnical ros2 twin``: it prints ``ready``, waits for
the first /odom, counts every topic at rest, drives /cmd_vel, stops commanding, and reports the
receipt times (its own monotonic and wall clocks), frames and covariances it saw.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from typing import Any

from omnical.ros2.runtime import ensure_ros_environment, import_rclpy


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--vx", type=float, default=0.3)
    parser.add_argument("--rest-s", type=float, default=1.0)
    parser.add_argument("--drive-s", type=float, default=1.5)
    parser.add_argument("--after-s", type=float, default=2.0)
    parser.add_argument("--cmd-hz", type=float, default=20.0)
    parser.add_argument("--moving-mps", type=float, default=0.01)
    parser.add_argument("--stamped", action="store_true")
    parser.add_argument("--wait", nargs="*", default=["/odom"], help="topics to wait for first")
    args = parser.parse_args()
    ensure_ros_environment()
    rclpy = import_rclpy()
    from geometry_msgs.msg import PoseWithCovarianceStamped, Twist, TwistStamped
    from nav_msgs.msg import Odometry
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Imu, JointState, LaserScan

    rclpy.init()
    node = rclpy.create_node("omnical_test_probe")
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    lock = threading.Lock()
    received: dict[str, list[tuple[float, Any]]] = {}
    first_wall: dict[str, float] = {}

    def on(topic: str) -> Any:
        def callback(msg: Any) -> None:
            now = time.monotonic()
            with lock:
                received.setdefault(topic, []).append((now, msg))
                first_wall.setdefault(topic, time.time())

        return callback

    types = {
        "/odom": Odometry,
        "/ground_truth": Odometry,
        "/imu": Imu,
        "/joint_states": JointState,
        "/scan": LaserScan,
        "/odom_calibrated": Odometry,
        "/ips/fix": PoseWithCovarianceStamped,
    }
    for topic, kind in types.items():
        node.create_subscription(kind, topic, on(topic), qos)
    try:  # built by `omnical ros2 build-tf2-msgs` (make), or a system ROS 2's
        from tf2_msgs.msg import TFMessage

        node.create_subscription(TFMessage, "/tf", on("/tf"), qos)
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        node.create_subscription(TFMessage, "/tf_static", on("/tf_static"), latched)
    except ImportError:
        pass
    cmd_pub = node.create_publisher(TwistStamped if args.stamped else Twist, "/cmd_vel", qos)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spin = threading.Thread(target=executor.spin, daemon=True)
    spin.start()
    print("ready", flush=True)

    deadline = time.monotonic() + 15.0
    deadline = time.monotonic() + 30.0
    while not set(args.wait) <= set(first_wall) and time.monotonic() < deadline:
        time.sleep(0.005)
    # wait for the twin to see the /cmd_vel publisher too
    while cmd_pub.get_subscription_count() < 1 and time.monotonic() < deadline:
        time.sleep(0.005)
    time.sleep(0.3)  # every other topic's discovery
    rest_from = time.monotonic()
    time.sleep(args.rest_s)
    rest_to = time.monotonic()

    def command(vx: float) -> None:
        twist = Twist()
        twist.linear.x = vx
        if args.stamped:
            stamped = TwistStamped()
            stamped.header.frame_id = "base_link"
            stamped.twist = twist
            cmd_pub.publish(stamped)
        else:
            cmd_pub.publish(twist)

    cmd_times = []
    start = time.monotonic()
    while time.monotonic() - start < args.drive_s:
        cmd_times.append(time.monotonic())
        command(args.vx)
        time.sleep(1.0 / args.cmd_hz)
    time.sleep(args.after_s)
    executor.shutdown(timeout_sec=1.0)
    with lock:
        snapshot = {t: list(v) for t, v in received.items()}

    def counts_between(topic: str, a: float, b: float) -> int:
        return sum(1 for t, _ in snapshot.get(topic, []) if a <= t < b)

    odom = [
        (
            t,
            m.twist.twist.linear.x,
            m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec,
            list(m.pose.covariance),
            list(m.twist.covariance),
        )
        for t, m in snapshot.get("/odom", [])
    ]
    moving = [t for t, vx, *_ in odom if t >= cmd_times[0] and vx >= args.moving_mps]
    after_last = [t for t, vx, *_ in odom if t > cmd_times[-1] and vx == 0.0]
    frames = {
        topic: [sorted({m.header.frame_id for _, m in msgs})]
        + (
            [sorted({m.child_frame_id for _, m in msgs})]
            if hasattr(msgs[0][1], "child_frame_id")
            else []
        )
        for topic, msgs in snapshot.items()
        if topic not in ("/tf", "/tf_static")  # frames per transform: "tf" below
    }
    moving_cov = next((o[3] for o in odom if o[1] > 0.0), None)
    stopped_cov = next((o[3] for o in odom if o[1] == 0.0), None)
    moving_twist_cov = next((o[4] for o in odom if o[1] > 0.0), None)
    stopped_twist_cov = next((o[4] for o in odom if o[1] == 0.0), None)
    scan = snapshot.get("/scan", [])

    def stamp_s(m: Any) -> float:
        return m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec

    def poses(topic: str) -> list[list[float]]:
        out = []
        for _, m in snapshot.get(topic, []):
            p, q = m.pose.pose.position, m.pose.pose.orientation
            yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
            out.append([stamp_s(m), p.x, p.y, yaw, *[m.pose.covariance[7 * i] for i in (0, 1, 5)]])
        return out

    def stamp_rate_hz(topic: str) -> float:
        """Messages per second of their own stamps, of those received at rest: a stall of
        the machine delays and bunches receipts, not stamps."""
        stamps = sorted(stamp_s(m) for t, m in snapshot.get(topic, []) if rest_from <= t < rest_to)
        if len(stamps) < 3 or stamps[-1] <= stamps[0]:
            return 0.0
        return (len(stamps) - 1) / (stamps[-1] - stamps[0])

    def transforms(topic: str, *, last_only: bool = False) -> list[list[Any]]:
        """Every transform on ``topic`` (of its last message only): stamp, parent, child, x, y,
        yaw, z."""
        out = []
        for _, m in snapshot.get(topic, [])[-1:] if last_only else snapshot.get(topic, []):
            for tf in m.transforms:
                v, q = tf.transform.translation, tf.transform.rotation
                yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
                out.append([stamp_s(tf), tf.header.frame_id, tf.child_frame_id, v.x, v.y, yaw, v.z])
        return out

    result = {
        "tf": transforms("/tf"),
        "tf_static_last": transforms("/tf_static", last_only=True),
        "poses": {t: poses(t) for t in ("/odom", "/odom_calibrated", "/ground_truth", "/ips/fix")},
        "rest_stamp_rates_hz": {t: stamp_rate_hz(t) for t in types},
        "first_wall_s": first_wall,
        "rest_s": rest_to - rest_from,
        "rest_counts": {t: counts_between(t, rest_from, rest_to) for t in types},
        "first_cmd_s": cmd_times[0],
        "last_cmd_s": cmd_times[-1],
        "commands": len(cmd_times),
        "first_moving_s": moving[0] if moving else None,
        "stopped_s": after_last[0] if after_last else None,
        "max_vx_mps": max((o[1] for o in odom), default=0.0),
        "frames": frames,
        "moving_pose_covariance": moving_cov,
        "stopped_pose_covariance": stopped_cov,
        "moving_twist_covariance": moving_twist_cov,
        "stopped_twist_covariance": stopped_twist_cov,
        "odom_stamps_s": [o[2] for o in odom],
        "odom_rx_s": [o[0] for o in odom],
        "scan_beams": len(scan[-1][1].ranges) if scan else 0,
        "scan_finite": sum(1 for r in scan[-1][1].ranges if r == r and abs(r) < 1e9) if scan else 0,
        "joint_names": list(snapshot["/joint_states"][-1][1].name)
        if snapshot.get("/joint_states")
        else [],
    }
    node.destroy_node()
    rclpy.shutdown()
    print(json.dumps(result), flush=True)


if __name__ == "__main__":
    sys.exit(main())
