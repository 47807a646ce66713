"""ROS 2 adapters (extra ``omnical[ros2]``): the twin as a ROS 2 robot, publishers, the ROS 2 rig.

Imported only by ``omnical ros2 ...`` and ``--robot ros2``; rclpy through :mod:`omnical.ros2.runtime`
(call ``ensure_ros_environment()`` first: it re-executes the command once for the wheels'
library path). How rclpy is loaded, and the test domain settings: docs/ros2.md.
"""
