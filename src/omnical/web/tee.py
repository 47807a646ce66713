"""The run's side of the monitor: a row sink that tees rows to ``omnical monitor`` without waiting.

:class:`MonitorTee` writes the run's own sink, then queues the rows on a :class:`MonitorLink`
(bounded drop-oldest queues, a sender thread that reconnects and resends the latched data).
"""

from __future__ import annotations

import collections
import contextlib
import os
import sys
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike

from omnical.errors import ProtocolError
from omnical.experiment.rig import RowSink
from omnical.recording.topics import EVENTS
from omnical.web.protocol import (
    QUEUE_DEPTH,
    TOPIC_STREAMS,
    MonitorTarget,
    dumps,
    event_payload,
    is_step_marker,
    rows_to_frames,
)
from omnical.web.wsclient import WebSocketClient

__all__ = ["MonitorLink", "MonitorTee"]

_RETRY_S: Final = 0.25
_REFUSED_RETRY_S: Final = 2.0
_SEND_TIMEOUT_S: Final = 1.0


class MonitorLink:
    """A run's connection to ``omnical monitor`` (``--monitor``), kept up by a daemon thread.

    ``rows``, ``send`` and ``latch`` only append to a bounded deque (O(1), never blocking: the
    oldest frame of that stream is dropped when full); the thread converts, sends and reconnects
    every :data:`_RETRY_S` while the monitor is away, resending the latched frames. A monitor
    that refuses the handshake (a token missing or wrong) is reported once through
    ``on_warning`` (default: a line on stderr) and retried every :data:`_REFUSED_RETRY_S`; a
    frame that cannot be converted is dropped (counted) and the thread goes on.

    Attributes:
        target: where the monitor listens.
        source: the name the page shows for this run (``run``, ``twin serve``, ...).
        reset: the page clears its trails when this source connects (a new run).
        sent: frames sent; dropped: frames dropped per stream (queue full, not connected, or
            not convertible).
        connected: the link is up now.
        refused: the monitor's answer to the last handshake if it refused it, else None.
    """

    def __init__(
        self,
        target: MonitorTarget,
        source: str,
        *,
        reset: bool = True,
        on_state: Callable[[str], None] | None = None,
        on_warning: Callable[[str], None] | None = None,
    ) -> None:
        self.target = target
        self.source = source
        self.reset = reset
        self.on_state = on_state
        self.on_warning = on_warning if on_warning is not None else _to_stderr
        self._queues: dict[str, collections.deque[Any]] = {}
        self._order: list[str] = []
        self._latched: dict[str, dict[str, Any]] = {}
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._ws: WebSocketClient | None = None
        self._resend_latched = True
        self.sent = 0
        self.dropped: dict[str, int] = {}
        self.connected = False
        self.connects = 0
        self.refused: str | None = None
        self._warned: set[str] = set()
        self._thread = threading.Thread(target=self._run, name="monitor-link", daemon=True)
        self._started = False
        self._since = time.time()

    # ------------------------------------------------------------------ the run's side
    def start(self) -> MonitorLink:
        """Start the sender thread (idempotent)."""
        if not self._started:
            self._started = True
            self._thread.start()
        return self

    def _put(self, stream: str, item: Any, depth: int | None = None) -> None:
        q = self._queues.get(stream)
        if q is None:
            with self._lock:
                size = depth if depth is not None else QUEUE_DEPTH.get(stream, 16)
                q = self._queues.setdefault(stream, collections.deque(maxlen=size))
                if stream not in self._order:
                    self._order.append(stream)
        if len(q) == q.maxlen:
            self.dropped[stream] = self.dropped.get(stream, 0) + 1
        q.append(item)
        self._wake.set()

    def rows(self, topic: str, t_ns: ArrayLike, columns: Mapping[str, ArrayLike]) -> None:
        """Queue rows of a recording topic (copied: the caller may reuse its arrays)."""
        cols = {k: np.array(v, copy=True) for k, v in columns.items()}
        depth = QUEUE_DEPTH.get(TOPIC_STREAMS.get(topic, ""), 16)
        self._put(f"rows:{topic}", ("rows", topic, np.array(t_ns, dtype=np.int64), cols), depth)

    def send(self, stream: str, data: Mapping[str, Any]) -> None:
        """Queue one frame of ``stream`` (progress, factors, status, ...)."""
        self._put(stream, ("frame", stream, dict(data)))

    def event(self, text: str, t_s: float | None = None) -> None:
        """Queue one line for the page's event log (a step, a warning, an abort), stamped now
        (or ``t_s``, wall-clock s) with its run time: seconds since this link was made."""
        when = time.time() if t_s is None else t_s
        payload = event_payload(when, text)
        payload["run_s"] = when - self._since
        self.send("events", payload)

    def latch(self, stream: str, data: Mapping[str, Any]) -> None:
        """Static data (map, beacons, origin): sent now and again after every reconnect."""
        with self._lock:
            self._latched[stream] = dict(data)
            self._resend_latched = True
        self._wake.set()

    def close(self, timeout_s: float = 1.0) -> None:
        """Send what is queued (for at most ``timeout_s``), then close the connection."""
        deadline = time.monotonic() + timeout_s
        while (
            self.connected
            and self._thread.is_alive()
            and self._pending()
            and time.monotonic() < deadline
        ):
            self._wake.set()
            time.sleep(0.01)
        self._stop.set()
        self._wake.set()
        if self._started:
            self._thread.join(timeout=max(0.1, deadline - time.monotonic()) + 0.5)

    def _pending(self) -> bool:
        return any(self._queues.values()) or self._resend_latched

    # ------------------------------------------------------------------ the thread
    def _say(self, state: str) -> None:
        if self.on_state is not None:
            with contextlib.suppress(Exception):
                self.on_state(state)

    def _warn_once(self, key: str, text: str) -> None:
        if key in self._warned:
            return
        self._warned.add(key)
        with contextlib.suppress(Exception):
            self.on_warning(text)

    def _connect(self) -> bool:
        t = self.target
        try:
            ws = WebSocketClient.connect(t.host, t.port, t.ingest_path, timeout_s=_SEND_TIMEOUT_S)
        except OSError as err:
            self._warn_once(
                "absent",
                f"warning: --monitor: no monitor answered at {t.host}:{t.port} "
                f"({type(err).__name__}); not streaming until one does",
            )
            return False
        except ProtocolError as err:  # it answered, but not with a WebSocket: it will not change
            why = str(err).rpartition(": ")[2]
            self.refused = why
            hint = "give the URL it printed, with ?token=" if t.token is None else "wrong token?"
            if " 409 " in why:  # a replaying monitor (``omnical monitor RUN``)
                hint = "it is replaying a recording: start a live `omnical monitor` for this run"
            self._warn_once(
                "refused",
                f"warning: --monitor: the monitor at {t.host}:{t.port}: {why}; {hint}; "
                f"not streaming (retrying every {_REFUSED_RETRY_S:g} s)",
            )
            return False
        ws.sock.settimeout(_SEND_TIMEOUT_S)
        self._ws = ws
        self.connected = True
        self.connects += 1
        if self.refused is not None:
            self.refused = None
            self._warned.discard("refused")
        with self._lock:
            self._resend_latched = True
        hello = {
            "source": self.source,
            "pid": os.getpid(),
            "since": self._since,
            "reset": self.reset,
        }
        self._write(dumps({"kind": "hello", "stream": "source", "data": hello}))
        self._say(f"streaming to the monitor at {t.host}:{t.port}")
        return True

    def _drop_connection(self) -> None:
        if self._ws is not None:
            with contextlib.suppress(OSError):
                self._ws.close()
        self._ws = None
        if self.connected:
            self._say("the monitor went away; reconnecting")
        self.connected = False

    def _write(self, text: str) -> None:
        assert self._ws is not None
        self._ws.send_text(text)
        self.sent += 1

    def _next(self) -> tuple[str, Any] | None:
        """One item and its stream, the streams taken in turn (a busy one cannot starve a quiet
        one)."""
        with self._lock:
            order = list(self._order)
        for _ in range(len(order)):
            stream = order[0]
            order = order[1:] + order[:1]
            q = self._queues[stream]
            if q:
                with self._lock:  # next time, start after this stream
                    self._order.remove(stream)
                    self._order.append(stream)
                try:
                    return stream, q.popleft()
                except IndexError:
                    return None
        return None

    def _messages(self, item: Any) -> list[str]:
        if item[0] == "frame":
            _, stream, data = item
            kind = "latch" if stream in self._latched else "frame"
            return [dumps({"kind": kind, "stream": stream, "data": data})]
        _, topic, t_ns, cols = item
        return [
            dumps({"kind": "frame", "stream": s, "data": d})
            for s, d in rows_to_frames(topic, t_ns, cols)
        ]

    def _drop_bad(self, stream: str, err: Exception) -> None:
        """A frame that cannot be converted or encoded: dropped and counted, said once."""
        self.dropped[stream] = self.dropped.get(stream, 0) + 1
        self._warn_once(
            f"bad:{stream}",
            f"warning: --monitor: a frame of {stream} cannot be sent "
            f"({type(err).__name__}: {err}); dropped",
        )

    def _run(self) -> None:
        while not self._stop.is_set():
            if self._ws is None and not self._connect():
                self._stop.wait(_RETRY_S if self.refused is None else _REFUSED_RETRY_S)
                continue
            try:
                if self._resend_latched:
                    with self._lock:
                        latched = dict(self._latched)
                        self._resend_latched = False
                    for stream, data in latched.items():
                        try:
                            text = dumps({"kind": "latch", "stream": stream, "data": data})
                        except Exception as err:  # one bad frame, not the link
                            self._drop_bad(stream, err)
                            continue
                        self._write(text)
                taken = self._next()
                if taken is None:
                    self._wake.wait(0.2)
                    self._wake.clear()
                    continue
                stream, item = taken
                try:
                    texts = self._messages(item)
                except Exception as err:  # one bad frame, not the link
                    self._drop_bad(stream, err)
                    continue
                for text in texts:
                    self._write(text)
            except OSError:
                self._drop_connection()
        self._drop_connection()


def _to_stderr(text: str) -> None:
    """The default warning sink: one line on stderr, ``omnical: TEXT``."""
    with contextlib.suppress(OSError, ValueError):
        print(f"omnical: {text}", file=sys.stderr, flush=True)


class MonitorTee:
    """A :class:`~omnical.experiment.rig.RowSink` writing to ``sink`` and teeing to ``link``.

    The run's own sink is written first and whole; the monitor gets a copy of the rows queued
    for its sender thread, which may drop them (a stalled monitor never slows the run). The
    runner's step markers reach the monitor as they happen (:meth:`live_event`); the same
    markers in the run's ``/omnical/events`` rows at its end are then not sent again."""

    def __init__(self, sink: RowSink, link: MonitorLink) -> None:
        self.sink = sink
        self.link = link
        self.live_steps = 0

    def live_event(self, t_s: float, text: str) -> None:
        """A step marker as the runner logs it (``t_s``: the run's clock): to the monitor now."""
        del t_s  # the page shows run time: the link stamps it with the wall clock
        self.live_steps += 1
        self.link.event(text)

    def write_rows(self, topic: str, t_ns: ArrayLike, **columns: ArrayLike) -> None:
        """Append rows to ``topic`` in the sink, and queue them for the monitor."""
        self.sink.write_rows(topic, t_ns, **columns)
        if topic == EVENTS and self.live_steps and "text" in columns:
            texts = np.asarray(columns["text"], dtype=object)
            keep = np.array([not is_step_marker(str(x)) for x in texts], dtype=bool)
            stamps = np.asarray(t_ns, dtype=np.int64)
            for t, text in zip(stamps[~keep], texts[~keep], strict=True):
                # a marker the page already has: its recorded stamp (the run's own clock)
                # re-times it there, as a replay shows it; the page adds no second line
                self.link.send("events", {**event_payload(t / 1e9, str(text)), "recorded": True})
            if not keep.all():
                if not keep.any():
                    return
                t_ns = stamps[keep]
                columns = {k: np.asarray(v)[keep] for k, v in columns.items()}
        self.link.rows(topic, t_ns, columns)

    def __getattr__(self, name: str) -> Any:
        """Everything else (``close``, ``kept_at``, ``build`` ...) is the sink's."""
        return getattr(self.sink, name)
