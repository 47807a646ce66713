"""A minimal ROS 2 robot for the rig's tests (run as a script; it holds no tests itself).

/cmd_vel in (Twist, or TwistStamped with --stamped; 0.5 s timeout); /odom, /imu, /joint_states at
50 Hz, a room's /scan and a PointStamped /hedge_pos at 10 Hz out. --silent-after S: /odom stops
S s after the first motion (--scan-silent-after S: /scan); --name: the node's. Prints "moving"
then, and on SIGINT a JSON line (last command, pose).
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import time


def main() -> None:
    """Run the robot until SIGINT."""
    parser = argparse.ArgumentParser()
    parser.add_argument("--stamped", action="store_true")
    parser.add_argument("--silent-after", type=float, default=None)
    parser.add_argument("--scan-silent-after", type=float, default=None)
    parser.add_argument("--start", default="2.9,2.4")
    parser.add_argument("--name", default="rig_test_robot", help="the node's name")
    args = parser.parse_args()

    from omnical.ros2.runtime import ensure_ros_environment, import_rclpy

    ensure_ros_environment()
    rclpy = import_rclpy()
    from geometry_msgs.msg import PointStamped, Twist, TwistStamped
    from nav_msgs.msg import Odometry
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import Imu, JointState, LaserScan

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(args.name)
    sx, sy = (float(v) for v in args.start.split(","))
    state = {"cmd": (0.0, 0.0, 0.0), "last_s": -1e9, "count": 0, "moved_s": None}
    pose = [0.0, 0.0, 0.0]

    def on_cmd(msg: object) -> None:
        body = msg.twist if args.stamped else msg
        cmd = (body.linear.x, body.linear.y, body.angular.z)
        state.update(cmd=cmd, last_s=time.monotonic(), count=state["count"] + 1)
        if cmd != (0.0, 0.0, 0.0) and state["moved_s"] is None:
            state["moved_s"] = time.monotonic()
            print("moving", flush=True)

    node.create_subscription(TwistStamped if args.stamped else Twist, "/cmd_vel", on_cmd, 10)
    odom = node.create_publisher(Odometry, "/odom", 10)
    imu = node.create_publisher(Imu, "/imu", 10)
    joints = node.create_publisher(JointState, "/joint_states", 10)
    scan = node.create_publisher(LaserScan, "/scan", 10)
    hedge = node.create_publisher(PointStamped, "/hedge_pos", 10)
    ticks = [0]

    last_tick = [time.monotonic()]

    def tick() -> None:
        now = time.monotonic()
        dt, last_tick[0] = min(now - last_tick[0], 0.5), now  # the time that passed, not 20 ms
        v = state["cmd"] if now - state["last_s"] < 0.5 else (0.0, 0.0, 0.0)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        pose[0] += (c * v[0] - s * v[1]) * dt
        pose[1] += (s * v[0] + c * v[1]) * dt
        pose[2] += v[2] * dt
        stamp = node.get_clock().now().to_msg()
        ticks[0] += 1
        moved = state["moved_s"]
        if args.silent_after is None or moved is None or now - moved < args.silent_after:
            m = Odometry()
            m.header.stamp, m.header.frame_id, m.child_frame_id = stamp, "odom", "base_link"
            m.pose.pose.position.x, m.pose.pose.position.y = pose[0], pose[1]
            m.pose.pose.orientation.z = math.sin(pose[2] / 2)
            m.pose.pose.orientation.w = math.cos(pose[2] / 2)
            m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.angular.z = v
            odom.publish(m)
        i = Imu()
        i.header.stamp, i.header.frame_id = stamp, "imu_link"
        i.angular_velocity.z, i.linear_acceleration.z = float(v[2]), 9.81
        imu.publish(i)
        j = JointState()
        j.header.stamp = stamp
        j.name = ["w1", "w2", "w3", "w4"]
        j.position = [ticks[0] * 0.01] * 4
        j.velocity = [0.5] * 4
        joints.publish(j)
        if ticks[0] % 5 == 0:  # 10 Hz: the hedgehog at the base (no offset)
            h = PointStamped()
            h.header.stamp, h.header.frame_id = stamp, "map"
            h.point.x, h.point.y, h.point.z = sx + pose[0], sy + pose[1], 0.4
            hedge.publish(h)
            quiet = args.scan_silent_after
            if quiet is None or moved is None or now - moved < quiet:
                scan.publish(room_scan(LaserScan, stamp, pose))

    def room_scan(kind: type, stamp: object, p: list[float]) -> object:
        """180 beams over a half turn in a 4 m square room centred on the start."""
        m = kind()
        m.header.stamp, m.header.frame_id = stamp, "laser"
        m.angle_min, m.angle_increment = -math.pi / 2, math.pi / 180
        m.angle_max = m.angle_min + 179 * m.angle_increment
        m.range_min, m.range_max, m.scan_time = 0.1, 8.0, 0.1
        ranges = []
        for k in range(180):
            a = p[2] + m.angle_min + k * m.angle_increment
            ca, sa = math.cos(a), math.sin(a)
            tx = (2.0 - p[0]) / ca if ca > 1e-9 else (-2.0 - p[0]) / ca if ca < -1e-9 else 1e9
            ty = (2.0 - p[1]) / sa if sa > 1e-9 else (-2.0 - p[1]) / sa if sa < -1e-9 else 1e9
            ranges.append(float(min(tx, ty)))
        m.ranges = ranges
        return m

    node.create_timer(0.02, tick)
    stop = []
    signal.signal(signal.SIGINT, lambda *_: stop.append(True))
    signal.signal(signal.SIGTERM, lambda *_: stop.append(True))
    print("robot up", flush=True)
    while not stop:
        rclpy.spin_once(node, timeout_sec=0.05)
    report = {"count": state["count"], "last": state["cmd"], "pose": pose}
    sys.stdout.write(json.dumps(report) + "\n")
    sys.stdout.flush()
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
