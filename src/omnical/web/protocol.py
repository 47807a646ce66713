"""The monitor's wire format: a run's rows as JSON frames of named streams, and ``--monitor``.

Pure functions on numpy arrays, shared by the run side (:mod:`.tee`) and the server
(:mod:`.server`). Run → server ``{"kind", "stream", "data"}``; server → page ``{"s", "ts", "d"}``.
"""

from __future__ import annotations

import ipaddress
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final
from urllib.parse import parse_qs, urlsplit

import numpy as np
from numpy.typing import ArrayLike

from omnical.errors import ConfigError
from omnical.recording.topics import (
    BEACONS_POS_A,
    CMD_VEL,
    EVENTS,
    GROUND_TRUTH,
    HEDGE_POS_ANG,
    HEDGE_QUALITY,
    ODOM,
)

__all__ = [
    "DEFAULT_PORT",
    "HISTORY_POINTS",
    "LATCHED_STREAMS",
    "MAX_POINT_RATE_HZ",
    "QUEUE_DEPTH",
    "TOPIC_STREAMS",
    "MonitorTarget",
    "beacons_payload",
    "decimate",
    "dumps",
    "event_payload",
    "is_loopback",
    "is_step_marker",
    "map_payload",
    "parse_monitor_target",
    "rows_to_frames",
]

DEFAULT_PORT: Final = 8765
"""``omnical monitor``'s port when none is given (``--port``)."""

MAX_POINT_RATE_HZ: Final = 50.0
"""Pose streams are thinned to at most this rate before they leave the run (a twin in
simulated time writes its odometry at hundreds of rows per robot second)."""

TOPIC_STREAMS: Final[Mapping[str, str]] = {
    ODOM: "odom",
    GROUND_TRUTH: "truth",
    HEDGE_POS_ANG: "fix",
    HEDGE_QUALITY: "quality",
    CMD_VEL: "cmd",
    EVENTS: "events",
    BEACONS_POS_A: "beacons",
}
"""Recording topics the monitor shows, and the stream each becomes."""

LATCHED_STREAMS: Final = frozenset({"beacons", "map", "origin", "source", "recording", "runclock"})
"""Static data: the server keeps the last of each and sends it to every page on connect."""

QUEUE_DEPTH: Final[Mapping[str, int]] = {
    "odom": 64,
    "truth": 64,
    "fix": 64,
    "cmd": 64,
    "fused": 64,
    "error": 64,
    "quality": 8,
    "status": 8,
    "progress": 8,
    "hub": 4,
    "events": 512,
    "factors": 128,
}
"""Frames kept per stream in each bounded drop-oldest queue (run side and per page); a stream
not named here keeps 16. Low-rate streams (events, factors) get deep queues and their own, so
odometry can never push them out."""


HISTORY_POINTS: Final[Mapping[str, int]] = {
    "odom": 4000,
    "truth": 4000,
    "fix": 4000,
    "cmd": 3000,
    "error": 3000,
    "quality": 100,
}
"""Rows the monitor keeps of each columnar stream (the page's own bounds: 80 s of a 50 Hz
trail) and sends as one frame to a page that joins late."""


def dumps(message: Mapping[str, Any]) -> str:
    """Compact JSON; NaN and infinities become null (JSON has none)."""
    try:  # the C encoder alone first: walking every value in Python doubled a frame's cost
        return json.dumps(message, separators=(",", ":"), allow_nan=False)
    except ValueError:  # a NaN or an infinity somewhere
        return json.dumps(_finite(message), separators=(",", ":"), allow_nan=False)


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def decimate(t_s: np.ndarray, max_rate_hz: float = MAX_POINT_RATE_HZ) -> np.ndarray:
    """Indices of the rows to keep so that kept rows are at least ``1/max_rate_hz`` apart
    (the first row of every such interval; the last row always kept)."""
    n = len(t_s)
    if n <= 2:
        return np.arange(n)
    bins = np.floor((t_s - t_s[0]) * max_rate_hz + 1e-6).astype(np.int64)  # 1e-6: rounding
    keep = np.flatnonzero(np.diff(bins, prepend=bins[0] - 1) != 0)
    if keep[-1] != n - 1:
        keep = np.append(keep, n - 1)
    return keep


def _col(columns: Mapping[str, ArrayLike], name: str, rows: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(columns[name], dtype=np.float64)[rows]]


def event_payload(t_s: float, text: str) -> dict[str, Any]:
    """One event (a run's ``/omnical/events`` row, or a line the command says): its kind,
    its level (``info``, ``warning``, ``abort``) and a readable line."""
    kind, level, line = "note", "info", text
    try:
        data = json.loads(text)
    except ValueError:
        data = None
    if isinstance(data, dict) and "script" in data and "edge" in data:  # the runner's markers
        kind = "step"
        marker = f" ({data['marker']})" if data.get("marker") else ""
        line = f"{data['script']}: step {data.get('step')} {data.get('kind', '')} {data['edge']}{marker}"
    elif isinstance(data, dict):
        kind = str(data.get("omnical", data.get("event", "event")))
        rest = {k: v for k, v in data.items() if k not in {"omnical", "event"}}
        line = kind + (
            ": " + ", ".join(f"{k} {_plain(v)}" for k, v in rest.items())[:300] if rest else ""
        )
    lowered = line.lower()
    if any(w in lowered for w in ("stop", "abort", "interrupt", "safety")):
        level = "abort"
    elif any(w in lowered for w in ("warn", "silent", "gap", "lost", "refus")):
        level = "warning"
    return {"t": t_s, "kind": kind, "level": level, "text": line}


def _plain(value: Any) -> str:
    """An event's value as a reader wants it: text bare, numbers short, the rest compact JSON."""
    if isinstance(value, str):
        return value
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, Mapping):
        return "(" + ", ".join(f"{k} {_plain(v)}" for k, v in value.items()) + ")"
    return json.dumps(value, separators=(",", ":"))


def is_step_marker(text: str) -> bool:
    """``text`` is one of the runner's step markers (``{"script", "step", "edge", ...}``)."""
    if not text.startswith("{") or '"edge"' not in text:
        return False
    try:
        data = json.loads(text)
    except ValueError:
        return False
    return isinstance(data, dict) and "script" in data and "edge" in data


def beacons_payload(addresses: ArrayLike, positions_m: ArrayLike) -> dict[str, Any]:
    """The latched beacon list, one entry per address (the last position of each)."""
    addr = np.asarray(addresses).astype(np.int64).ravel()
    pos = np.asarray(positions_m, dtype=np.float64).reshape(len(addr), -1)
    seen: dict[int, list[float]] = {}
    for a, p in zip(addr, pos, strict=True):
        seen[int(a)] = [float(v) for v in p[:3]]
    return {"beacons": [{"address": a, "x": p[0], "y": p[1], "z": p[2]} for a, p in seen.items()]}


def rows_to_frames(
    topic: str,
    t_ns: ArrayLike,
    columns: Mapping[str, ArrayLike],
    max_rate_hz: float = MAX_POINT_RATE_HZ,
) -> list[tuple[str, dict[str, Any]]]:
    """The frames (stream, payload) for rows of a recording ``topic``; [] for a topic the
    monitor does not show. Times ``t`` are bag seconds (``t_ns / 1e9``)."""
    stream = TOPIC_STREAMS.get(topic)
    t = np.asarray(t_ns, dtype=np.int64)
    if stream is None or len(t) == 0:
        return []
    t_s = t.astype(np.float64) / 1e9
    if stream == "events":
        texts = np.asarray(columns["text"], dtype=object)
        return [
            ("events", event_payload(float(ts), str(x))) for ts, x in zip(t_s, texts, strict=True)
        ]
    if stream == "beacons":
        pos = np.column_stack(
            [np.asarray(columns[c], dtype=np.float64) for c in ("x_m", "y_m", "z_m")]
        )
        return [("beacons", beacons_payload(columns["address"], pos))]
    rows = decimate(t_s, max_rate_hz) if stream in {"odom", "truth", "cmd"} else np.arange(len(t))
    out: dict[str, Any] = {"t": [float(v) for v in t_s[rows]]}
    if stream in {"odom", "truth"}:
        for key, name in (("x", "x_m"), ("y", "y_m"), ("yaw", "yaw_rad")):
            out[key] = _col(columns, name, rows)
        if stream == "odom":
            for key, name in (("vx", "vx_mps"), ("vy", "vy_mps"), ("wz", "wz_radps")):
                out[key] = _col(columns, name, rows)
    elif stream == "cmd":
        for key, name in (("vx", "vx_mps"), ("vy", "vy_mps"), ("wz", "wz_radps")):
            out[key] = _col(columns, name, rows)
    elif stream == "fix":
        out["x"], out["y"] = _col(columns, "x_m", rows), _col(columns, "y_m", rows)
        out["flags"] = [int(v) for v in np.asarray(columns["flags"]).astype(np.int64)[rows]]
    elif stream == "quality":
        out["percent"] = [
            int(v) for v in np.asarray(columns["quality_percent"]).astype(np.int64)[rows]
        ]
    return [(stream, out)]


@dataclass(frozen=True)
class MonitorTarget:
    """Where a run streams to: ``omnical monitor``'s host and port, and its token if it has one."""

    host: str
    port: int
    token: str | None = None

    @property
    def ingest_path(self) -> str:
        """The ingest WebSocket's path and query."""
        return "/ingest" + (f"?token={self.token}" if self.token else "")


def parse_monitor_target(text: str, option: str = "--monitor") -> MonitorTarget:
    """``PORT``, ``HOST:PORT`` or the URL ``omnical monitor`` printed (``http://HOST:PORT/?token=T``).

    Raises:
        ConfigError: not one of these, or a port outside 1–65535.
    """
    raw = text.strip()
    token: str | None = None
    host, port_text = "127.0.0.1", raw
    if "://" in raw:
        parts = urlsplit(raw)
        if parts.scheme not in {"http", "ws"} or parts.hostname is None:
            msg = f"{option} {text!r}: give [HOST:]PORT or the http://HOST:PORT/ URL the monitor printed"
            raise ConfigError(msg)
        host = parts.hostname
        try:
            port_text = str(parts.port or DEFAULT_PORT)
        except ValueError:
            port_text = "?"
        token = parse_qs(parts.query).get("token", [None])[0]
    elif ":" in raw:
        host, _, port_text = raw.rpartition(":")
        host = host.strip("[]") or "127.0.0.1"
    try:
        port = int(port_text)
    except ValueError:
        port = 0
    if not 1 <= port <= 65535:
        msg = f"{option} {text!r}: the port must be a number within 1–65535 ([HOST:]PORT)"
        raise ConfigError(msg)
    return MonitorTarget(host, port, token)


def is_loopback(host: str) -> bool:
    """``host`` names this machine only (``localhost``, 127.0.0.0/8, ``::1``)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def map_payload(
    cells: ArrayLike, resolution_m: float, origin: tuple[float, float, float]
) -> dict[str, Any]:
    """The latched occupancy map: (rows, cols) cells (0 free, 100 occupied, −1 unknown; row 0
    at the bottom) as base64 bytes (255 unknown), its resolution and origin."""
    import base64

    grid = np.asarray(cells).astype(np.int16)
    data = np.where(grid < 0, 255, grid).astype(np.uint8)
    return {
        "width": int(data.shape[1]),
        "height": int(data.shape[0]),
        "resolution": float(resolution_m),
        "origin": [float(v) for v in origin],
        "cells": base64.b64encode(data.tobytes()).decode(),
    }
