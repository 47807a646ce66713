"""``omnical info`` without reading the bag: counts and times from its index, travel from /odom.

An indexed MCAP answers from its summary, message indexes and the writer's travel tally; other
bags from what rosbags indexes. Every topic is listed, understood by omnical or not.
"""

from __future__ import annotations

from pathlib import Path

from rosbags.highlevel import AnyReader

from omnical.bags.bag import (
    canonical_topic,
    indexed_mcap,
    read_bag,
    resolve_source,
    ros2_bag_files,
)
from omnical.bags.mcapindex import McapIndexError, McapSummary, channel_times
from omnical.bags.rawdecode import MAX_TIME_NS
from omnical.bags.recover import UNREADABLE_BAG_ERRORS
from omnical.bags.typestores import typestore
from omnical.errors import RecordingError
from omnical.recording import summary as summarize_module
from omnical.recording.recording import Recording
from omnical.recording.summary import (
    TRAVEL_KEY_PREFIX,
    ConnectionSummary,
    RecordingSummary,
    StoredTravel,
    TopicSummary,
)
from omnical.recording.topics import GROUND_TRUTH, ODOM, TOPICS

__all__ = ["TRAVEL_TOPICS", "summarize_bag"]

TRAVEL_TOPICS = (ODOM, GROUND_TRUTH)
"""The topics decoded to summarise a bag (distance travelled, final pose)."""

_NS_PER_S = 1_000_000_000


_Channel = tuple[str, str, int, int | None, int | None]
"""A bag connection: topic, type, message count, first and last bag time (ns) if known."""


def summarize_bag(path: str | Path) -> RecordingSummary:
    """What :func:`~omnical.recording.summary.summarize` says of the bag, read from its index,
    with every topic listed (:attr:`RecordingSummary.connections`), understood or not.

    Raises:
        RecordingError: Missing path, not a bag, corrupt bag, bag times at or beyond 2⁶³ ns
            (one line naming the file).
    """
    source = resolve_source(path)
    try:
        summary = indexed_mcap(source)
    except (McapIndexError, OSError):
        summary = None  # let the full reader report what is wrong
    if summary is not None:
        return _from_index(source, summary)
    if source.suffix == ".bag":
        return _from_ros1_index(source)
    return _from_full_read(source)


def _from_full_read(source: Path) -> RecordingSummary:
    """A bag without a usable index: read it all; other topics' counts from rosbags."""
    recording = read_bag(source)
    channels: list[_Channel] = []
    try:
        with AnyReader([source], default_typestore=typestore(2)) as reader:
            for conn in reader.connections:
                channels.append((conn.topic, conn.msgtype, conn.msgcount, None, None))
    except UNREADABLE_BAG_ERRORS:
        channels = []
    connections = []
    for topic, msgtype, count, _, _ in channels:
        name = canonical_topic(topic, msgtype)
        table = recording.tables.get(name) if name is not None else None
        first = int(table.t_ns[0]) if table is not None and len(table) else None
        last = int(table.t_ns[-1]) if table is not None and len(table) else None
        connections.append(_connection(topic, msgtype, count, first, last, name))
    return summarize_module.summarize(recording, connections=connections)


def _from_ros1_index(source: Path) -> RecordingSummary:
    """Counts and times from the per-message index rosbags builds of a ROS 1 bag."""
    channels: list[_Channel] = []
    try:
        with AnyReader([source], default_typestore=typestore(1)) as reader:
            for sub in reader.readers:
                indexes = getattr(sub, "indexes", {})
                for conn in sub.connections:
                    entries = indexes.get(conn.id, [])
                    first = entries[0].time if entries else None
                    last = entries[-1].time if entries else None
                    channels.append((conn.topic, conn.msgtype, len(entries), first, last))
    except UNREADABLE_BAG_ERRORS:
        return _from_full_read(source)  # the full reader words the error
    return _assemble(source, channels)


def _from_index(source: Path, summary: McapSummary) -> RecordingSummary:
    channels: list[_Channel] = []
    try:
        for cid, channel in sorted(summary.channels.items()):
            times = channel_times(summary, cid) if channel.count else None
            first, last = times if times is not None else (None, None)
            channels.append((channel.topic, channel.msgtype, channel.count, first, last))
    except (McapIndexError, OSError) as err:
        msg = f"{source}: cannot read bag ({type(err).__name__}: {err})"
        raise RecordingError(msg) from None
    return _assemble(source, channels)


def _assemble(source: Path, channels: list[_Channel]) -> RecordingSummary:
    """The summary of connections (topic, type, count, first ns, last ns), poses decoded."""
    counts: dict[str, int] = {}
    firsts: dict[str, int] = {}
    lasts: dict[str, int] = {}
    skipped: dict[str, str] = {}
    connections: list[ConnectionSummary] = []
    for topic, msgtype, count, first, last in channels:
        if last is not None and last > MAX_TIME_NS:
            msg = (
                f"{source}: topic {topic}: bag times at or beyond 2^63 ns (after 2262-04-11); "
                "the bag's times are corrupt"
            )
            raise RecordingError(msg)
        name = canonical_topic(topic, msgtype)
        connections.append(_connection(topic, msgtype, count, first, last, name))
        if name is None:
            skipped[topic] = msgtype
            continue
        counts[name] = counts.get(name, 0) + count
        if first is not None and last is not None:
            firsts[name] = min(firsts.get(name, first), first)
            lasts[name] = max(lasts.get(name, last), last)
    topics = tuple(_topic(n, counts[n], firsts.get(n), lasts.get(n)) for n in TOPICS if n in counts)
    stored = {
        name: travel
        for name, travel in _stored_travel(source).items()
        if (travel.count, travel.first_ns, travel.last_ns)
        == (counts.get(name), firsts.get(name), lasts.get(name))
    }
    wanted = [t for t in TRAVEL_TOPICS if counts.get(t) and t not in stored]
    poses = read_bag(source, wanted) if wanted else Recording({})
    return summarize_module.summarize(poses, topics, skipped, connections, stored)


def _stored_travel(source: Path) -> dict[str, StoredTravel]:
    """The travel omnical's writer tallied in a ROS 2 bag directory's ``custom_data``.

    Trust it only where its count and first and last times agree with the bag's index.
    """
    if not source.is_dir():
        return {}
    try:
        _, info = ros2_bag_files(source)
    except RecordingError:
        return {}
    custom = info.get("custom_data")
    if not isinstance(custom, dict):
        return {}
    found = {}
    for topic in TRAVEL_TOPICS:
        if (travel := StoredTravel.from_json(custom.get(TRAVEL_KEY_PREFIX + topic))) is not None:
            found[topic] = travel
    return found


def _rate(count: int, first: int | None, last: int | None) -> float | None:
    if count > 1 and first is not None and last is not None and last > first:
        return (count - 1) * _NS_PER_S / (last - first)
    return None


def _connection(
    topic: str, msgtype: str, count: int, first: int | None, last: int | None, name: str | None
) -> ConnectionSummary:
    return ConnectionSummary(topic, msgtype, count, first, last, _rate(count, first, last), name)


def _topic(name: str, count: int, first: int | None, last: int | None) -> TopicSummary:
    if not count or first is None or last is None:
        return TopicSummary(name, 0, None, None, None)
    return TopicSummary(name, count, first, last, _rate(count, first, last))
