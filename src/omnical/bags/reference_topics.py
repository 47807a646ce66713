"""Read an external pose reference (motion capture, a localisation) from any topic of a bag.

Pose, pose with covariance, odometry, transform or tf (one child frame); planar, bag times, cleaned
as canonical topics are; :func:`pose_topics` lists candidates, :func:`read_pose_topic` reads one.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader

from omnical.bags.bag import bag_source, connection_types, reading_bag
from omnical.bags.typestores import complete_store, typestore
from omnical.errors import ConfigError, RecordingError
from omnical.recording.recording import Table
from omnical.recording.topics import recognise_topic

__all__ = [
    "POSE_TYPES",
    "PoseTopic",
    "bag_topics",
    "pose_topics",
    "read_pose_frames",
    "read_pose_topic",
]

POSE_TYPES = (
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "nav_msgs/msg/Odometry",
    "geometry_msgs/msg/TransformStamped",
    "tf2_msgs/msg/TFMessage",
)
"""Message types a reference topic may have (rosbags' normalised names)."""

_WITH_CHILD = frozenset(POSE_TYPES[2:])


@dataclass(frozen=True)
class PoseTopic:
    """The planar poses of a reference topic.

    Attributes:
        topic: the topic read.
        msgtype: its message type.
        frame_id: the parent frame of the poses (first message's header).
        child_frame_id: the child frame taken ("" for pose messages without one).
        table: rows at bag times ``t_ns``, columns ``x_m``, ``y_m``, ``yaw_rad``.
        notes: what the cleaning did, one line each.
    """

    topic: str
    msgtype: str
    frame_id: str
    child_frame_id: str
    table: Table
    notes: tuple[str, ...] = ()


def _yaw(q: Any) -> float:
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _poses(msgtype: str, msg: Any) -> Iterable[tuple[str, str, float, float, float]]:
    """(frame, child, x, y, yaw) of each pose a message carries."""
    if msgtype == "tf2_msgs/msg/TFMessage":
        for tf in msg.transforms:
            yield from _poses("geometry_msgs/msg/TransformStamped", tf)
        return
    frame = str(msg.header.frame_id).lstrip("/")
    if msgtype == "geometry_msgs/msg/TransformStamped":
        tr = msg.transform
        p, q, child = tr.translation, tr.rotation, str(msg.child_frame_id).lstrip("/")
    elif msgtype == "geometry_msgs/msg/PoseStamped":
        p, q, child = msg.pose.position, msg.pose.orientation, ""
    else:  # PoseWithCovarianceStamped, Odometry
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        child = str(getattr(msg, "child_frame_id", "")).lstrip("/")
    yield frame, child, float(p.x), float(p.y), _yaw(q)


def _topic_names(topic: str) -> set[str]:
    bare = topic.lstrip("/")
    return {bare, f"/{bare}"}


def bag_topics(path: str | Path) -> dict[str, str]:
    """Every topic of the bag at ``path`` → its message type (rosbags' normalised name; types
    joined by ``|`` if connections of one topic differ), in the bag's order.

    Raises:
        RecordingError: no such bag, an unreadable bag.
    """
    source, ros = bag_source(path)
    with reading_bag(source), AnyReader([source], default_typestore=typestore(ros)) as reader:
        return connection_types(reader.connections)


def pose_topics(topics: Mapping[str, str]) -> list[str]:
    """The topics of ``topics`` (name → type, :func:`bag_topics`) with a pose type that omnical's
    canonical reader does not take (``/odom``, ``/ground_truth`` are read as themselves)."""
    return [
        topic
        for topic, msgtype in topics.items()
        if msgtype in POSE_TYPES and recognise_topic(topic, msgtype) is None
    ]


def _read_rows(
    path: str | Path, topic: str
) -> tuple[str, list[tuple[int, str, str, float, float, float]]]:
    """The message type of ``topic`` and (t_ns, frame, child, x, y, yaw) of each of its poses."""
    source, ros = bag_source(path)
    rows: list[tuple[int, str, str, float, float, float]] = []
    with reading_bag(source), AnyReader([source], default_typestore=typestore(ros)) as reader:
        complete_store(reader.typestore, [c.msgtype for c in reader.connections], ros)
        names = _topic_names(topic)
        conns = [c for c in reader.connections if c.topic in names]
        if not conns:
            poses = sorted({c.topic for c in reader.connections if c.msgtype in POSE_TYPES})
            msg = f"{source}: no topic {topic} (pose topics: {', '.join(poses) or 'none'})"
            raise RecordingError(msg)
        msgtype = conns[0].msgtype
        if msgtype not in POSE_TYPES or any(c.msgtype != msgtype for c in conns):
            types = ", ".join(sorted({c.msgtype for c in conns}))
            msg = (
                f"{topic} is {types}; a reference topic is one of "
                "PoseStamped, PoseWithCovarianceStamped, Odometry, TransformStamped or tf"
            )
            raise ConfigError(msg)
        for conn, t_ns, raw in reader.messages(connections=conns):
            message = reader.deserialize(raw, conn.msgtype)
            rows.extend((int(t_ns), *pose) for pose in _poses(msgtype, message))
    return msgtype, rows


def read_pose_topic(path: str | Path, topic: str, *, child_frame: str | None = None) -> PoseTopic:
    """The planar poses on ``topic`` of the bag at ``path`` (docs/DESIGN-NOTES.md).

    Raises:
        RecordingError: no such topic (the message lists the pose topics the bag has), an
            unreadable bag, no usable pose.
        ConfigError: the topic's type is not a pose type; a child frame that is not there, or
            several child frames and no selector.
    """
    msgtype, rows = _read_rows(path, topic)
    return _pose_topic(topic, msgtype, rows, child_frame)


def read_pose_frames(path: str | Path, topic: str) -> list[PoseTopic]:
    """The planar poses on ``topic``, one :class:`PoseTopic` per child frame (sorted; a tf
    topic's direct transforms), one for a topic of one child frame or none.

    Raises:
        RecordingError, ConfigError: as :func:`read_pose_topic`.
    """
    msgtype, rows = _read_rows(path, topic)
    children = sorted({r[2] for r in rows})
    if msgtype not in _WITH_CHILD or len(children) < 2:
        return [_pose_topic(topic, msgtype, rows, None)]
    return [_pose_topic(topic, msgtype, rows, child) for child in children]


def _pose_topic(
    topic: str,
    msgtype: str,
    rows: list[tuple[int, str, str, float, float, float]],
    child_frame: str | None,
) -> PoseTopic:
    if child_frame is not None and msgtype not in _WITH_CHILD:
        msg = f"{topic} ({msgtype}) has no child frame; drop the child frame selector"
        raise ConfigError(msg)
    children = sorted({r[2] for r in rows})
    if child_frame is not None:
        want = child_frame.lstrip("/")
        if want not in children:
            msg = f"{topic}: no transform to child frame {want!r} (child frames: {', '.join(children) or 'none'})"
            raise ConfigError(msg)
        rows = [r for r in rows if r[2] == want]
    elif len(children) > 1:
        msg = (
            f"{topic} carries {len(children)} child frames ({', '.join(children)}); choose the "
            "robot's with the child frame selector (--reference-child)"
        )
        raise ConfigError(msg)
    if not rows:
        msg = f"{topic}: no pose message"
        raise RecordingError(msg)
    t_ns = np.array([r[0] for r in rows], dtype=np.int64)
    values = np.array([r[3:] for r in rows], dtype=np.float64).reshape(-1, 3)
    notes: list[str] = []
    order = np.argsort(t_ns, kind="stable")
    if np.any(order != np.arange(order.size)):
        notes.append(f"{topic}: messages out of time order, sorted")
    t_ns, values = t_ns[order], values[order]
    finite = np.all(np.isfinite(values), axis=1)
    if not np.all(finite):
        notes.append(
            f"{topic}: {int(np.count_nonzero(~finite))} pose(s) with a non-finite value dropped"
        )
        t_ns, values = t_ns[finite], values[finite]
    repeated = np.concatenate([[False], np.diff(t_ns) == 0]) if t_ns.size else np.zeros(0, bool)
    if np.any(repeated):
        notes.append(
            f"{topic}: {int(np.count_nonzero(repeated))} pose(s) at a repeated time dropped"
        )
        t_ns, values = t_ns[~repeated], values[~repeated]
    if t_ns.size == 0:
        msg = f"{topic}: no usable pose (every one has a non-finite value)"
        raise RecordingError(msg)
    table = Table(t_ns, {"x_m": values[:, 0], "y_m": values[:, 1], "yaw_rad": values[:, 2]})
    frame = rows[0][1]
    child = rows[0][2]
    return PoseTopic(topic, msgtype, frame, child, table, tuple(notes))
