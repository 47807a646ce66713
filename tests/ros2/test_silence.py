"""The one warning of a ROS 2 command whose input stays silent: its wording (topic, domain,
types) and the watch that says it once, after the silence, and not while input arrives."""

from __future__ import annotations

import time

from omnical.ros2.silence import SilenceWatch, topic_silence_line, type_mismatch

ODOM_TYPE = "nav_msgs/msg/Odometry"


def test_a_topic_of_another_type_is_named_with_the_expected_one() -> None:
    line = topic_silence_line("ros2 correct", "/imu", ODOM_TYPE, ["sensor_msgs/msg/Imu"], 7, 3.0)
    assert "/imu" in line and "ROS_DOMAIN_ID 7" in line and "3 s" in line
    assert "published as sensor_msgs/msg/Imu" in line and f"expects {ODOM_TYPE}" in line


def test_no_publisher_says_so_and_that_it_waits() -> None:
    line = topic_silence_line("ros2 correct", "/odom", ODOM_TYPE, [], 0, 4.0)
    assert "no publisher" in line and "ROS_DOMAIN_ID 0" in line and "still waiting" in line


def test_a_matching_publisher_that_sends_nothing_is_not_a_type_mismatch() -> None:
    line = topic_silence_line("ros2 correct", "/odom", ODOM_TYPE, [ODOM_TYPE], 3, 3.0)
    assert "published as" not in line and "QoS" in line
    assert type_mismatch([ODOM_TYPE, "a/msg/B", "a/msg/B"], ODOM_TYPE) == ["a/msg/B"]


def wait_for(predicate: object, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate() and time.monotonic() < deadline:  # type: ignore[operator]
        time.sleep(0.01)


def test_the_watch_says_its_line_once_after_the_silence() -> None:
    said: list[str] = []
    watch = SilenceWatch(lambda s: f"silent {s:g}", after_s=0.1, warn=said.append, period_s=0.01)
    watch.start()
    try:
        wait_for(lambda: said, 10.0)
        time.sleep(0.1)  # ten more periods: still one line
    finally:
        watch.stop()
    assert said == [watch.said] and said[0].startswith("silent")


def test_the_watch_is_quiet_while_input_arrives_and_when_describe_has_nothing() -> None:
    said: list[str] = []
    asked: list[float] = []

    def nothing(s: float) -> None:
        asked.append(s)

    quiet = SilenceWatch(nothing, after_s=0.05, warn=said.append, period_s=0.01).start()
    fed = SilenceWatch(lambda s: "fed", after_s=5.0, warn=said.append, period_s=0.01).start()
    try:
        wait_for(lambda: len(asked) >= 3, 10.0)
        for _ in range(20):
            fed.seen()
            time.sleep(0.01)
    finally:
        quiet.stop()
        fed.stop()
    assert len(asked) >= 3 and said == []
