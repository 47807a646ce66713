"""A recording for the page to replay: its streams as one latched frame, the derived ones included.

Played with play/pause and a time slider; the frames are the live ones (:func:`.protocol.
rows_to_frames`, :class:`.live.LiveView`'s fused pose and error); raw distances without
positions are multilaterated first (``omnical locate``'s solve)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from omnical.bags.bag import read_bag
from omnical.errors import RecordingError
from omnical.ips.beacons import BeaconMap
from omnical.ips.marvelmind.position import PositionFlag
from omnical.recording.recording import Recording
from omnical.recording.topics import BEACON_RAW_DISTANCE, HEDGE_POS_ANG
from omnical.web.live import LiveView
from omnical.web.protocol import TOPIC_STREAMS, event_payload, rows_to_frames

__all__ = ["load_replay", "located_positions", "replay_payload"]


def _merge(into: dict[str, dict[str, list[Any]]], stream: str, data: dict[str, Any]) -> None:
    cols = into.setdefault(stream, {})
    for key, values in data.items():
        cols.setdefault(key, []).extend(values if isinstance(values, list) else [values])


def located_positions(
    recording: Recording, beacons: BeaconMap | None = None
) -> tuple[dict[str, Any], str] | None:
    """Positions for a recording that has raw distances but none: omnical's multilateration
    (robust, self-calibrated; ``beacons``, else the recording's map) as ``/hedge_pos_ang``
    columns (``t_ns`` and ``x_m``, ``y_m``, ``flags``: unusable fixes flagged unavailable), and
    the line that says so (with the solver's notes); else None."""
    if recording.has(HEDGE_POS_ANG) or not recording.has(BEACON_RAW_DISTANCE):
        return None
    from omnical.ips.from_recording import locate, status_summary
    from omnical.ips.solve.fixes import FixStatus

    fixes, _ = locate(recording, beacons=beacons)
    unusable = fixes.status > FixStatus.DEGRADED
    flags = np.where(unusable, int(PositionFlag.COORDINATES_UNAVAILABLE), 0)
    xy = np.nan_to_num(fixes.positions_map_m[:, :2])
    summary, _ = status_summary(fixes)
    columns = {"t_ns": fixes.t_ns, "x_m": xy[:, 0], "y_m": xy[:, 1], "flags": flags}
    notes = "".join(f"; {note}" for note in fixes.notes)
    return columns, f"no positions in the recording: multilaterated by omnical, {summary}{notes}"


def replay_payload(
    recording: Recording, name: str, located: tuple[dict[str, Any], str] | None = None
) -> dict[str, Any]:
    """The ``recording`` frame: every shown stream columnar, the events, the beacons, the
    fused pose and the odometry − IPS error (the live view run over the rows in time order).
    ``located``: positions and their line from :func:`located_positions`, shown as the fixes."""
    streams: dict[str, dict[str, list[Any]]] = {}
    events: list[dict[str, Any]] = []
    beacons: dict[str, Any] | None = None
    tables = [
        (t, recording.topic(t).t_ns, dict(recording.topic(t).columns))
        for t in TOPIC_STREAMS
        if recording.has(t)
    ]
    if located is not None:
        columns, line = located
        tables.append((HEDGE_POS_ANG, columns["t_ns"], columns))
        if len(columns["t_ns"]):
            events.append(event_payload(float(columns["t_ns"][0]) / 1e9, line))
    for topic, t_ns, table in tables:
        for stream, data in rows_to_frames(topic, t_ns, table):
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


def load_replay(path: Path, beacons: BeaconMap | None = None) -> dict[str, Any]:
    """Read the bag at ``path`` (the topics the monitor shows) into a :func:`replay_payload`;
    raw distances without positions located against ``beacons`` (else the bag's map).

    Raises:
        RecordingError: not a readable bag, or none of the shown topics in it.
    """
    recording = read_bag(path, tuple(TOPIC_STREAMS))
    if not recording.has(HEDGE_POS_ANG):  # the raw distances only when they are all there is
        recording = recording.merged(read_bag(path, (BEACON_RAW_DISTANCE,)))
    if not any(recording.has(t) for t in (*TOPIC_STREAMS, BEACON_RAW_DISTANCE)):
        shown = ", ".join((*TOPIC_STREAMS, BEACON_RAW_DISTANCE))
        msg = f"{path}: none of the topics the monitor shows ({shown})"
        raise RecordingError(msg)
    located = located_positions(recording, beacons)
    payload = replay_payload(recording, path.name, located)
    payload["note"] = None if located is None else located[1]
    if not np.isfinite(payload["t1"]):
        msg = f"{path}: no time stamps"
        raise RecordingError(msg)
    return payload
