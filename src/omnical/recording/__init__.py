"""Recordings in memory: one columnar table per topic (:class:`Recording`), the canonical topics
and their columns (:mod:`.topics`), summaries. Bag files are :mod:`omnical.bags`."""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
    from omnical.recording.recording import (
        Recording,
        RecordingBuilder,
        Table,
    )
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
    "summarize": "omnical.recording.summary",
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
    "Recording",
    "RecordingBuilder",
    "RecordingSummary",
    "Table",
    "TopicSpec",
    "TopicSummary",
    "summarize",
]


__getattr__ = lazy_getattr(__name__, _EXPORTS)
