"""Recordings: columnar tables per topic, ROS bag I/O (ROS 2 MCAP and ROS 1), exports."""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
    from omnical.recording.bag import (
        bag_location,
        read_bag,
        write_bag,
    )
    from omnical.recording.baginfo import summarize_bag
    from omnical.recording.export import (
        export_csv,
        export_tum,
    )
    from omnical.recording.recorder import BagRecorder
    from omnical.recording.recording import (
        Recording,
        RecordingBuilder,
        Table,
    )
    from omnical.recording.recover import recover_bag
    from omnical.recording.summary import (
        RecordingSummary,
        TopicSummary,
        summarize,
    )
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

_EXPORTS: dict[str, str] = {
    "BEACONS_POS_A": "omnical.recording.topics",
    "BEACON_RAW_DISTANCE": "omnical.recording.topics",
    "BagRecorder": "omnical.recording.recorder",
    "CMD_VEL": "omnical.recording.topics",
    "EVENTS": "omnical.recording.topics",
    "GROUND_TRUTH": "omnical.recording.topics",
    "HEDGE_POS_ANG": "omnical.recording.topics",
    "HEDGE_QUALITY": "omnical.recording.topics",
    "IMU": "omnical.recording.topics",
    "ODOM": "omnical.recording.topics",
    "Recording": "omnical.recording.recording",
    "RecordingBuilder": "omnical.recording.recording",
    "RecordingSummary": "omnical.recording.summary",
    "TOPICS": "omnical.recording.topics",
    "Table": "omnical.recording.recording",
    "TopicSpec": "omnical.recording.topics",
    "TopicSummary": "omnical.recording.summary",
    "bag_location": "omnical.recording.bag",
    "export_csv": "omnical.recording.export",
    "export_tum": "omnical.recording.export",
    "read_bag": "omnical.recording.bag",
    "recover_bag": "omnical.recording.recover",
    "summarize": "omnical.recording.summary",
    "summarize_bag": "omnical.recording.baginfo",
    "write_bag": "omnical.recording.bag",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

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
    "summarize_bag",
    "write_bag",
]


__getattr__ = lazy_getattr(__name__, _EXPORTS)
