"""Recordings: columnar tables per topic, ROS bag I/O (ROS 2 MCAP and ROS 1), exports."""

from omnical.recording.bag import bag_location, read_bag, write_bag
from omnical.recording.export import export_csv, export_tum
from omnical.recording.recorder import BagRecorder
from omnical.recording.recording import Recording, RecordingBuilder, Table
from omnical.recording.recover import recover_bag
from omnical.recording.summary import RecordingSummary, TopicSummary, summarize
from omnical.recording.topics import (
    BEACON_RAW_DISTANCE,
    BEACONS_POS_A,
    CMD_VEL,
    EVENTS,
    GROUND_TRUTH,
    HEDGE_POS_ANG,
    HEDGE_QUALITY,
    IMU,
    ODOM,
    TOPICS,
    TopicSpec,
)

__all__ = [
    "BEACONS_POS_A",
    "BEACON_RAW_DISTANCE",
    "CMD_VEL",
    "EVENTS",
    "GROUND_TRUTH",
    "HEDGE_POS_ANG",
    "HEDGE_QUALITY",
    "IMU",
    "ODOM",
    "TOPICS",
    "BagRecorder",
    "Recording",
    "RecordingBuilder",
    "RecordingSummary",
    "Table",
    "TopicSpec",
    "TopicSummary",
    "bag_location",
    "export_csv",
    "export_tum",
    "read_bag",
    "recover_bag",
    "summarize",
    "write_bag",
]
