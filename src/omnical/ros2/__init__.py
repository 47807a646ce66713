"""ROS 2 adapters (extra ``omnical[ros2]``): the twin as a ROS 2 robot, publishers, the ROS 2 rig.

Imported only by ``omnical ros2 ...`` and ``--robot ros2``; rclpy via :mod:`omnical.ros2.runtime`
(``ensure_ros_environment()`` first: it re-executes once for the wheels' library path; docs/ros2.md).
"""
