"""Drives ``omnical ros2 twin`` twice the same way, the second time with the twin stopped
(SIGSTOP by its PID) while the zero command is sent; prints the two distances as JSON.

Run by tests/ros2/test_twin_stall.py: ``ros2_stall_probe.py TWIN_PID``. Each drive: 0.2 m/s
on /cmd_vel at 20 Hz for 2 s, then zero for 1.5 s; its distance by the twin's /ground_truth,
and the time from the first command to the first zero as this process sent them.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time
from typing import Any

from omnical.ros2.runtime import ensure_ros_environment, import_rclpy

VX_MPS = 0.2
DRIVE_S = 2.0
STALL_FROM_S, STALL_TO_S = 1.85, 2.2  # the zero command (at 2 s) is sent while the twin stalls


def main() -> None:
    twin_pid = int(sys.argv[1])
    ensure_ros_environment()
    rclpy = import_rclpy()
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    rclpy.init()
    node = rclpy.create_node("omnical_stall_probe")
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    lock = threading.Lock()
    x = [float("nan")]

    def on_truth(msg: Any) -> None:
        with lock:
            x[0] = float(msg.pose.pose.position.x)

    node.create_subscription(Odometry, "/ground_truth", on_truth, qos)
    pub = node.create_publisher(Twist, "/cmd_vel", qos)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    done = threading.Event()

    def spin() -> None:
        while not done.is_set():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    end = time.monotonic() + 20.0
    while (x[0] != x[0] or pub.get_subscription_count() == 0) and time.monotonic() < end:
        time.sleep(0.05)  # the truth flowing, the twin subscribed
    time.sleep(0.5)

    def drive(stall: bool) -> tuple[float, float]:
        """The distance driven and the time from the first command to the first zero (as
        sent: a stall of this process lengthens it, and the twin applies it so)."""
        with lock:
            x0 = x[0]
        t0 = time.monotonic()
        zero_at = None
        stopped = False
        while (t := time.monotonic() - t0) < DRIVE_S + 1.5:
            if stall and not stopped and t >= STALL_FROM_S:
                os.kill(twin_pid, signal.SIGSTOP)
                stopped = True
            if stall and stopped and t >= STALL_TO_S:
                os.kill(twin_pid, signal.SIGCONT)
                stall = False
            msg = Twist()
            msg.linear.x = VX_MPS if t < DRIVE_S else 0.0
            if t >= DRIVE_S and zero_at is None:
                zero_at = t
            pub.publish(msg)
            time.sleep(0.05)
        with lock:
            return x[0] - x0, DRIVE_S if zero_at is None else zero_at

    try:
        plain, plain_s = drive(stall=False)
        stalled, stalled_s = drive(stall=True)
    finally:
        os.kill(twin_pid, signal.SIGCONT)
    got = {"plain_m": plain, "stalled_m": stalled, "plain_s": plain_s, "stalled_s": stalled_s}
    sys.stdout.write(json.dumps(got) + "\n")
    sys.stdout.flush()
    done.set()
    spinner.join(timeout=2.0)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
