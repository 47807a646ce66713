"""A user's own rclpy program, run with the environment ``omnical ros2 env`` prints (nothing of
omnical's re-execution): it creates a node, and corrects two JointState messages; prints JSON.
"""

from __future__ import annotations

import json
from pathlib import Path

import rclpy
from sensor_msgs.msg import JointState

from omnical.robot.loader import load_robot
from omnical.ros2.publishers import corrector_for


def main() -> None:
    import sys

    rclpy.init()
    node = rclpy.create_node("a_users_node")
    name = node.get_name()
    enc = load_robot("rosy-mecanum").encoders
    corrector = corrector_for(Path(sys.argv[1]), "rosy-mecanum")  # as `omnical ros2 correct`
    out = None
    for k in range(2):
        msg = JointState()
        msg.header.stamp.sec = 100 + k
        msg.name = list(enc.joints)
        msg.position = [0.5 * k * (i + 1) for i in range(len(enc.joints))]
        out = corrector.from_joint_states(msg, "odom", "base_link")
    assert out is not None
    node.destroy_node()
    rclpy.shutdown()
    report = {
        "node": name,
        "frame_id": out.header.frame_id,
        "child_frame_id": out.child_frame_id,
        "pose_covariance": list(out.pose.covariance),
        "twist_covariance": list(out.twist.covariance),
    }
    print(json.dumps(report))


if __name__ == "__main__":
    main()
