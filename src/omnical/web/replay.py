"""A recording for the page to replay: its streams as one latched frame, the derived ones included.

The page plays it with play/pause and a time slider; the frames are the live ones
(:func:`.protocol.rows_to_frames`, the fused pose and the error of :class:`.live.LiveView`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from omnical.bags.bag import read_bag
from omnical.errors import RecordingError
from omnical.recording.recording import Recording
from omnical.web.live import LiveView
from omnical.web.protocol import TOPIC_STREAMS, rows_to_frames

__all__ = ["load_replay", "replay_payload"]


def _merge(into: dict[str, dict[str, list[Any]]], stream: str, data: dict[str, Any]) -> None:
    cols = into.setdefault(stream, {})
    for key, values in data.items():
        cols.setdefault(key, []).extend(values if isinstance(values, list) else [values])


def replay_payload(recording: Recording, name: str) -> dict[str, Any]:
    """The ``recording`` frame: every shown stream columnar, the events, the beacons, the
    fused pose and the odometry − IPS error (the live view run over the rows in time order)."""
    streams: dict[str, dict[str, list[Any]]] = {}
    events: list[dict[str, Any]] = []
    beacons: dict[str, Any] | None = None
    for topic in TOPIC_STREAMS:
        if not recording.has(topic):
            continue
        table = recording.topic(topic)
        for stream, data in rows_to_frames(topic, table.t_ns, dict(table.columns)):
            if stream == "events":
                events.append(data)
            elif stream == "beacons":
                beacons = data
            else:
                _merge(streams, stream, data)
    live = LiveView()
    steps: list[tuple[float, int, str, dict[str, Any]]] = []
    for order, stream in enumerate(("odom", "fix")):
        cols = streams.get(stream)
        if cols is None:
            continue
        keys = [k for k in cols if k != "t"]
        for i, t in enumerate(cols["t"]):
            row = {"t": [t], **{k: [cols[k][i]] for k in keys}}
            steps.append((t, order, stream, row))
    steps.sort(key=lambda s: (s[0], s[1]))
    for _, _, stream, row in steps:
        for derived, data in live.on_frame(stream, row):
            if derived == "fused":
                _merge(streams, "fused", {k: [v] for k, v in data.items()})
            else:
                _merge(streams, derived, data)
    times = [t for cols in streams.values() for t in cols.get("t", [])[:1] + cols.get("t", [])[-1:]]
    return {
        "name": name,
        "t0": min(times) if times else 0.0,
        "t1": max(times) if times else 0.0,
        "streams": streams,
        "events": events,
        "beacons": beacons,
        "origin": None if live.origin is None else list(live.origin),
        "rows": int(sum(len(recording.topic(t)) for t in recording.topics)),
        "duration_s": float(recording.duration_s) if recording.message_count else 0.0,
    }


def load_replay(path: Path) -> dict[str, Any]:
    """Read the bag at ``path`` (the topics the monitor shows) into a :func:`replay_payload`.

    Raises:
        RecordingError: not a readable bag, or none of the shown topics in it.
    """
    recording = read_bag(path, tuple(TOPIC_STREAMS))
    if not any(recording.has(t) for t in TOPIC_STREAMS):
        msg = f"{path}: none of the topics the monitor shows ({', '.join(TOPIC_STREAMS)})"
        raise RecordingError(msg)
    payload = replay_payload(recording, path.name)
    if not np.isfinite(payload["t1"]):
        msg = f"{path}: no time stamps"
        raise RecordingError(msg)
    return payload
