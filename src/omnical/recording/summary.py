"""A short account of a recording: what is in it, how long, how far the robot went."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from omnical.recording.recording import MAX_ABS_VALUE, Recording, Table
from omnical.recording.topics import GROUND_TRUTH, ODOM

__all__ = [
    "TRAVEL_KEY_PREFIX",
    "ConnectionSummary",
    "RecordingSummary",
    "StoredTravel",
    "TopicSummary",
    "TravelTally",
    "summarize",
    "travel",
]

_NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class TopicSummary:
    """Rows of one topic: count, first and last time (ns), mean rate (Hz, None if < 2 rows)."""

    name: str
    count: int
    first_ns: int | None
    last_ns: int | None
    rate_hz: float | None


@dataclass(frozen=True)
class ConnectionSummary:
    """One topic of a bag as stored: name, type, message count, first and last bag time (ns,
    None if unknown), mean rate (Hz), and the canonical topic omnical reads it as (None: a
    topic omnical does not understand)."""

    topic: str
    msgtype: str
    count: int
    first_ns: int | None
    last_ns: int | None
    rate_hz: float | None
    reads_as: str | None

    @property
    def understood(self) -> bool:
        """Whether omnical reads this topic."""
        return self.reads_as is not None


@dataclass(frozen=True)
class RecordingSummary:
    """Per-topic counts and rates, total duration, odometry and ground-truth travel.

    Distances are planar path lengths (m), final poses (x m, y m, yaw rad) of the last row;
    None when the topic is absent. ``connections``: every topic of the bag as stored (empty
    from memory); ``notes``: what reading cleaned.
    """

    topics: tuple[TopicSummary, ...]
    duration_s: float
    start_ns: int | None
    end_ns: int | None
    distance_odom_m: float | None
    distance_ground_truth_m: float | None
    final_pose_odom: tuple[float, float, float] | None
    final_pose_ground_truth: tuple[float, float, float] | None
    skipped_topics: Mapping[str, str]
    connections: tuple[ConnectionSummary, ...] = field(default=(), compare=False)
    notes: tuple[str, ...] = ()

    @property
    def understood_nothing(self) -> bool:
        """The bag holds topics, and omnical understands none of them."""
        return bool(self.connections) and not any(c.understood for c in self.connections)


def _topic_summary(topic: str, table: Table) -> TopicSummary:
    n = len(table)
    if n == 0:
        return TopicSummary(topic, 0, None, None, None)
    first, last = int(table.t_ns[0]), int(table.t_ns[-1])
    rate = (n - 1) * _NS_PER_S / (last - first) if n > 1 and last > first else None
    return TopicSummary(topic, n, first, last, rate)


def travel(
    recording: Recording, topic: str
) -> tuple[float | None, tuple[float, float, float] | None]:
    """Planar path length (m) and final pose (x, y, yaw) of a pose topic; None if absent."""
    if not recording.has(topic):
        return None, None
    table = recording.topic(topic)
    steps = np.hypot(np.diff(table["x_m"]), np.diff(table["y_m"]))
    final = (float(table["x_m"][-1]), float(table["y_m"][-1]), float(table["yaw_rad"][-1]))
    return float(np.sum(steps)), final


TRAVEL_KEY_PREFIX = "omnical.travel:"
"""Key prefix of a pose topic's travel in a ROS 2 bag's ``custom_data`` (written on close)."""


@dataclass(frozen=True)
class StoredTravel:
    """What :func:`travel` says of a pose topic, as the writer tallied it: rows, first and last
    time (ns), planar path length (m) and final pose (x m, y m, yaw rad)."""

    count: int
    first_ns: int
    last_ns: int
    distance_m: float
    final_pose: tuple[float, float, float]

    def to_json(self) -> str:
        """The ``custom_data`` value (rosbag2 custom data are strings)."""
        return json.dumps(
            {
                "count": self.count,
                "first_ns": self.first_ns,
                "last_ns": self.last_ns,
                "distance_m": self.distance_m,
                "final_pose": list(self.final_pose),
            },
            separators=(",", ":"),
        )

    @staticmethod
    def from_json(text: object) -> StoredTravel | None:
        """Parse a ``custom_data`` value; None for anything that is not one (never raises)."""
        if not isinstance(text, str) or len(text) > 1000:
            return None
        try:
            data = json.loads(text)
            pose = tuple(float(v) for v in data["final_pose"])
            stored = StoredTravel(
                int(data["count"]),
                int(data["first_ns"]),
                int(data["last_ns"]),
                float(data["distance_m"]),
                (pose[0], pose[1], pose[2]),
            )
        except (ValueError, TypeError, KeyError, IndexError, RecursionError):
            return None
        finite = math.isfinite(stored.distance_m) and all(map(math.isfinite, stored.final_pose))
        if len(pose) != 3 or not finite or stored.count < 1 or stored.last_ns < stored.first_ns:
            return None
        return stored


class TravelTally:
    """The travel of a pose topic summed while it is written, in any number of tables.

    Valid only while rows arrive in strictly increasing time with every value finite and in
    range (reading the bag back then gives the same table); otherwise :meth:`result` is None.
    """

    def __init__(self) -> None:
        self.count = 0
        self.first_ns = 0
        self.last_ns = -1
        self.distance_m = 0.0
        self.last_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.valid = True

    def add(self, table: Table) -> None:
        """Tally ``table``'s rows (columns ``x_m``, ``y_m``, ``yaw_rad``)."""
        if not self.valid or len(table) == 0:
            return
        t = table.t_ns.astype(np.int64)
        x, y, yaw = (np.asarray(table[c], dtype=np.float64) for c in ("x_m", "y_m", "yaw_rad"))
        values = [np.asarray(table[c], dtype=np.float64) for c in table.names]
        clean = all(bool(np.all(np.abs(v) <= MAX_ABS_VALUE)) for v in values)  # NaN fails too
        if not clean or np.any(np.diff(t) <= 0) or int(t[0]) <= self.last_ns:
            self.valid = False
            return
        if self.count:
            x = np.concatenate(([self.last_pose[0]], x))
            y = np.concatenate(([self.last_pose[1]], y))
        else:
            self.first_ns = int(t[0])
        self.distance_m += float(np.sum(np.hypot(np.diff(x), np.diff(y))))
        self.count += len(table)
        self.last_ns = int(t[-1])
        self.last_pose = (float(x[-1]), float(y[-1]), float(yaw[-1]))

    def result(self) -> StoredTravel | None:
        """The tally, or None if rows were out of order, not finite, or none came."""
        if not self.valid or not self.count:
            return None
        return StoredTravel(
            self.count, self.first_ns, self.last_ns, self.distance_m, self.last_pose
        )


def summarize(
    recording: Recording,
    topics: Sequence[TopicSummary] | None = None,
    skipped: Mapping[str, str] | None = None,
    connections: Sequence[ConnectionSummary] = (),
    stored_travel: Mapping[str, StoredTravel] | None = None,
) -> RecordingSummary:
    """Summarise ``recording`` (an empty one has duration 0 and no start or end).

    Args:
        recording: The recording, or only its pose topics when ``topics`` is given.
        topics: Per-topic counts and times taken from elsewhere (a bag's index, see
            :func:`omnical.bags.baginfo.summarize_bag`); the duration then spans them
            and ``recording`` only supplies distances and final poses.
        skipped: Skipped topics to report instead of ``recording.skipped_topics``.
        connections: Every topic of the bag as stored (see :class:`ConnectionSummary`).
        stored_travel: Travel of pose topics tallied by the writer; used for a topic that
            ``recording`` does not hold.
    """
    if topics is None:
        topics = tuple(_topic_summary(name, table) for name, table in recording.tables.items())
    firsts = [t.first_ns for t in topics if t.first_ns is not None]
    lasts = [t.last_ns for t in topics if t.last_ns is not None]
    start, end = (min(firsts), max(lasts)) if firsts and lasts else (None, None)
    stored = stored_travel or {}
    distance_odom, pose_odom = _travel_or_stored(recording, ODOM, stored)
    distance_gt, pose_gt = _travel_or_stored(recording, GROUND_TRUTH, stored)
    return RecordingSummary(
        topics=tuple(topics),
        duration_s=0.0 if start is None or end is None else (end - start) / _NS_PER_S,
        start_ns=start,
        end_ns=end,
        distance_odom_m=distance_odom,
        distance_ground_truth_m=distance_gt,
        final_pose_odom=pose_odom,
        final_pose_ground_truth=pose_gt,
        skipped_topics=MappingProxyType(
            dict(recording.skipped_topics if skipped is None else skipped)
        ),
        connections=tuple(connections),
        notes=recording.notes,
    )


def _travel_or_stored(
    recording: Recording, topic: str, stored: Mapping[str, StoredTravel]
) -> tuple[float | None, tuple[float, float, float] | None]:
    if not recording.has(topic) and topic in stored:
        return stored[topic].distance_m, stored[topic].final_pose
    return travel(recording, topic)
