"""``omnical info`` without reading the bag: counts and times from its index, travel from /odom.

An indexed MCAP file answers "which topics, how many messages, first and last time" from its
summary section and two message indexes per topic (:mod:`omnical.recording.mcapindex`), in
milliseconds whatever the recording's length. The distances travelled and final poses need
the poses themselves: only ``/odom`` and ``/ground_truth`` are decoded for them (memory: their
tables, 48 bytes a row). Other bags (ROS 1, SQLite, unindexed MCAP) are summarised from what
rosbags' reader indexes (ROS 1: its per-message index, no message decoded; others: a full
read).
"""

from __future__ import annotations

from pathlib import Path

from rosbags.highlevel import AnyReader

from omnical.errors import RecordingError
from omnical.recording import summary as summary_module
from omnical.recording.bag import canonical_topic, indexed_mcap, read_bag, resolve_source
from omnical.recording.mcapindex import McapIndexError, McapSummary, channel_times
from omnical.recording.recording import Recording
from omnical.recording.recover import UNREADABLE_BAG_ERRORS
from omnical.recording.summary import RecordingSummary, TopicSummary, summarize
from omnical.recording.topics import GROUND_TRUTH, ODOM, TOPICS
from omnical.recording.typestores import typestore

__all__ = ["TRAVEL_TOPICS", "summarize_bag"]

TRAVEL_TOPICS = (ODOM, GROUND_TRUTH)
"""The topics decoded to summarise a bag (distance travelled, final pose)."""

_NS_PER_S = 1_000_000_000


def summarize_bag(path: str | Path) -> RecordingSummary:
    """What :func:`~omnical.recording.summary.summarize` says of the bag, read from its index.

    Raises:
        RecordingError: Missing path, not a bag, corrupt bag (one line naming the file).
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
    return summarize(read_bag(source))


def _from_ros1_index(source: Path) -> RecordingSummary:
    """Counts and times from the per-message index rosbags builds of a ROS 1 bag."""
    channels: list[tuple[str, str, int, int | None, int | None]] = []
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
        return summarize(read_bag(source))  # the full reader words the error
    return _assemble(source, channels)


def _from_index(source: Path, summary: McapSummary) -> RecordingSummary:
    channels: list[tuple[str, str, int, int | None, int | None]] = []
    try:
        for cid, channel in sorted(summary.channels.items()):
            times = None
            if channel.count and canonical_topic(channel.topic, channel.msgtype) is not None:
                times = channel_times(summary, cid)
            first, last = times if times is not None else (None, None)
            channels.append((channel.topic, channel.msgtype, channel.count, first, last))
    except (McapIndexError, OSError) as err:
        msg = f"{source}: cannot read bag ({type(err).__name__}: {err})"
        raise RecordingError(msg) from None
    return _assemble(source, channels)


def _assemble(
    source: Path, channels: list[tuple[str, str, int, int | None, int | None]]
) -> RecordingSummary:
    """The summary of connections (topic, type, count, first ns, last ns), poses decoded."""
    counts: dict[str, int] = {}
    firsts: dict[str, int] = {}
    lasts: dict[str, int] = {}
    skipped: dict[str, str] = {}
    for topic, msgtype, count, first, last in channels:
        name = canonical_topic(topic, msgtype)
        if name is None:
            skipped[topic] = msgtype
            continue
        counts[name] = counts.get(name, 0) + count
        if first is not None and last is not None:
            firsts[name] = min(firsts.get(name, first), first)
            lasts[name] = max(lasts.get(name, last), last)
    topics = tuple(_topic(n, counts[n], firsts.get(n), lasts.get(n)) for n in TOPICS if n in counts)
    wanted = [t for t in TRAVEL_TOPICS if counts.get(t)]
    poses = read_bag(source, wanted) if wanted else Recording({})
    return summary_module.summarize(poses, topics, skipped)


def _topic(name: str, count: int, first: int | None, last: int | None) -> TopicSummary:
    if not count or first is None or last is None:
        return TopicSummary(name, 0, None, None, None)
    rate = (count - 1) * _NS_PER_S / (last - first) if count > 1 and last > first else None
    return TopicSummary(name, count, first, last, rate)
