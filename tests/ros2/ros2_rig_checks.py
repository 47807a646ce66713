"""The ROS 2 rig's own safety in one rclpy process (run as a script; it holds no tests itself).

Checks the ``/cmd_vel`` subscriber check, a failing command thread, ``close`` and a stale
``/scan`` on a node of its own (nothing else on the domain), and prints one JSON line.
"""

from __future__ import annotations

import json
import math
import sys
import time
from typing import Any

from omnical.ros2.runtime import ensure_ros_environment


def _error(call: Any) -> str:
    try:
        call()
    except Exception as err:
        return f"{type(err).__name__}: {err}"
    return ""


def main() -> None:
    """Run the checks and print what they saw."""
    ensure_ros_environment()
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import LaserScan

    from omnical.robot.loader import load_robot
    from omnical.ros2.rig import Ros2Lidar, Ros2Link, Ros2Robot

    description = load_robot("rosy-mecanum")
    link = Ros2Link("rig_checks")
    out: dict[str, Any] = {}
    robot = Ros2Robot(link, description)
    out["nobody"] = _error(lambda: robot.check_cmd_vel(0.3))
    link.node.create_subscription(Twist, "/cmd_vel", lambda _m: None, 10)
    out["twist"] = _error(lambda: robot.check_cmd_vel(3.0))
    other = Ros2Link("rig_checks_stamped")  # one topic, one type per participant
    stamped = Ros2Robot(other, description, stamped=True)
    out["stamped"] = _error(lambda: stamped.check_cmd_vel(5.0))
    stamped.close()
    other.close()

    def boom(*_: object) -> None:
        raise RuntimeError("boom")

    robot._tick = boom  # type: ignore[method-assign]  # every tick of the command thread fails
    before = robot.published
    time.sleep(0.3)
    out["alive"] = robot._thread.is_alive()
    out["zeros_while_failing"] = robot.published - before
    out["motion_after_failure"] = _error(lambda: robot.send_twist(0.1, 0.0, 0.0))
    before, t0 = robot.published, time.monotonic()
    robot.close()
    out["close_s"] = time.monotonic() - t0
    out["zeros_at_close"] = robot.published - before
    before = robot.published
    out["motion_after_close"] = _error(lambda: robot.send_twist(0.1, 0.0, 0.0))
    out["published_after_close"] = robot.published - before

    now = [100.0]
    lidar = Ros2Lidar(link, description, lambda: now[0])
    scan = LaserScan()
    scan.angle_min, scan.angle_increment = -math.pi, math.pi / 180
    scan.range_min, scan.range_max, scan.scan_time = 0.1, 8.0, 0.1
    scan.ranges = [1.0] * 360
    for k in range(5):  # 10 Hz
        now[0] = 100.0 + 0.1 * k
        lidar._on_scan(scan)
    out["fresh"] = int(lidar.scan_now().size)
    out["limit_s"] = lidar.silence(now[0]).limit_s
    now[0] += 0.7
    out["stale"] = _error(lidar.scan_now)
    out["stale_exceeded"] = lidar.silence(now[0]).exceeded
    out["unstamped_age_s"] = lidar.scan_age_s()

    # stamped on the robot's clock (50 s behind the host's), received 2–10 ms later
    lidar = Ros2Lidar(link, description, lambda: now[0])
    for k, delay in enumerate((0.004, 0.002, 0.010, 0.003, 0.006)):
        stamp = 50.0 + 0.1 * k
        scan.header.stamp.sec, scan.header.stamp.nanosec = int(stamp), round(stamp % 1 * 1e9)
        now[0] = stamp + 50.0 + delay
        lidar._on_scan(scan)
    now[0] = 100.46  # the last scan's rays were taken at 100.402 on the host's clock
    out["age_s"] = lidar.scan_age_s()
    scan.time_increment = 0.1 / 360  # a rotating LiDAR: its rays over 0.1 s, mean 0.0499 s later
    lidar._on_scan(scan)
    out["age_swept_s"] = lidar.scan_age_s()
    link.close()
    sys.stdout.write(json.dumps(out) + "\n")


if __name__ == "__main__":
    main()
