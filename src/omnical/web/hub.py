"""The monitor's fan-out: frames from runs to every page, through a queue per page and stream.

A bounded drop-oldest queue per page and stream, served in turn: a stalled page loses only its
own oldest frames. Static data, the run's clock and a bounded history of every stream are sent
to pages that connect later. asyncio, one event loop; no web framework."""

from __future__ import annotations

import asyncio
import collections
import itertools
import json
import time
from collections.abc import Callable, Mapping
from typing import Any

from omnical.web.live import LiveView
from omnical.web.protocol import HISTORY_POINTS, LATCHED_STREAMS, QUEUE_DEPTH, dumps

__all__ = ["HISTORY_BLOCK_ROWS", "History", "Hub", "PageQueue"]

_FIRST: tuple[str, ...] = ("source", "runclock")
"""Streams a page gets before anything else waiting: a new run's identity and clock come before
its rows and events (the page starts afresh on ``source``)."""

_WALL_SPAN_S = 1e5
"""A stamp within this of the run's wall-clock start is wall-clock time; further away it is a
simulated run's bag time (seed 000's epoch)."""


HISTORY_BLOCK_ROWS = 250
"""A columnar stream's history is kept in blocks of this many rows, each encoded once when it
fills: a page that joins gets them as they are (nothing to encode but the open block), and
each is one frame a page parses and handles in a millisecond or two."""


class History:
    """A columnar stream's recent rows, at least ``cap`` (all if fewer came) and fewer than
    ``cap`` + :data:`HISTORY_BLOCK_ROWS`: full blocks as their JSON, the open block as lists."""

    def __init__(self, keys: frozenset[str], cap: int, block: int = HISTORY_BLOCK_ROWS) -> None:
        self.keys = keys
        self.cap = cap
        self.block = block
        self.blocks: collections.deque[tuple[str, int]] = collections.deque()  # (JSON, rows)
        self.open: dict[str, list[Any]] = {k: [] for k in keys}
        self.rows = 0  # in the blocks and the open block

    def extend(self, columns: Mapping[str, list[Any]]) -> None:
        """Append rows (``columns``: one list per key, all as long)."""
        n = len(next(iter(columns.values()))) if columns else 0
        done = 0
        while done < n:
            room = self.block - len(next(iter(self.open.values())))
            take = min(room, n - done)
            for key, values in columns.items():
                self.open[key].extend(values[done : done + take])
            done += take
            self.rows += take
            if take == room:  # a full block: encoded once, here
                self.blocks.append((dumps(self.open), self.block))
                self.open = {k: [] for k in self.keys}
                while self.blocks and self.rows - self.blocks[0][1] >= self.cap:
                    self.rows -= self.blocks.popleft()[1]

    def frames(self) -> list[str]:
        """The kept rows as frames' data, oldest first (the open block encoded now)."""
        out = [text for text, _ in self.blocks]
        if next(iter(self.open.values()), None):
            out.append(dumps(self.open))
        return out


class PageQueue:
    """One page's queues: a bounded drop-oldest deque per stream, taken round-robin."""

    def __init__(self) -> None:
        self._queues: dict[str, collections.deque[str]] = {}
        self._order: collections.deque[str] = collections.deque()
        self._ready = asyncio.Event()
        self.dropped: dict[str, int] = {}
        self.sent = 0
        self.messages = 0  # long messages sent (server.ACK_BYTES or more)
        self.acked = 0  # acks from the page: it opened, then one for each long one it handled
        self._acked = asyncio.Event()

    def put(self, stream: str, payload: str) -> None:
        """Queue ``payload`` (the frame's data as JSON), dropping the stream's oldest if full."""
        q = self._queues.get(stream)
        if q is None:
            q = self._queues[stream] = collections.deque(maxlen=QUEUE_DEPTH.get(stream, 16))
            self._order.append(stream)
        if len(q) == q.maxlen:
            self.dropped[stream] = self.dropped.get(stream, 0) + 1
        q.append(payload)
        self._ready.set()

    def pending(self) -> int:
        """Frames waiting."""
        return sum(len(q) for q in self._queues.values())

    def take(self) -> tuple[str, str] | None:
        """The next (stream, payload): :data:`_FIRST` first, then the streams in turn; None if
        all are empty."""
        for stream in _FIRST:
            first = self._queues.get(stream)
            if first:
                return stream, first.popleft()
        for _ in range(len(self._order)):
            stream = self._order[0]
            self._order.rotate(-1)
            q = self._queues[stream]
            if q:
                return stream, q.popleft()
        self._ready.clear()
        return None

    def forget(self, keep: frozenset[str]) -> None:
        """Drop what waits, but for the streams in ``keep`` (a new run: the last one's frames
        that this page has not had yet are no longer shown)."""
        for stream, q in self._queues.items():
            if stream not in keep:
                q.clear()

    def ack(self) -> None:
        """The page is open (its first), or handled one more long message."""
        self.acked += 1
        self._acked.set()

    async def handled(self, acks: int) -> None:
        """Wait until the page has said ``acks`` times that it is open or handled a long
        message."""
        while self.acked < acks:
            self._acked.clear()
            await self._acked.wait()

    async def get(self) -> tuple[str, str]:
        """Wait for the next frame."""
        while True:
            item = self.take()
            if item is not None:
                return item
            await self._ready.wait()


class Hub:
    """Latched data, the pages' queues, the live view and the stream rates.

    Args:
        clock: wall-clock seconds (frames are stamped with it when they leave, for the page's
            latency figure).
    """

    def __init__(self, clock: Callable[[], float] = time.time) -> None:
        self.clock = clock
        self.latched: dict[str, str] = {}
        self.history: dict[str, collections.deque[str]] = {
            "events": collections.deque(maxlen=200),
            "factors": collections.deque(maxlen=100),
            "fused": collections.deque(maxlen=1),
            "progress": collections.deque(maxlen=1),
            "status": collections.deque(maxlen=4),
        }
        self.series: dict[str, History] = {}
        self.run_clock: dict[str, Any] | None = None
        self._run_key: int | None = None
        self._data_t0: float | None = None
        self.pages: set[PageQueue] = set()
        self.live = LiveView()
        self.sources: dict[int, str] = {}
        self.devices: set[int] = set()  # sources that are not a run (reset False: twin serve)
        self._shown_run: int | None = None  # the latest run's key: the page shows it
        self._run_wall: bool | None = None  # its stamps are wall-clock (else simulated)
        self._latched_by: dict[str, int] = {}
        self.held_back = 0  # frames of a device not shown beside the run (another clock)
        self._span: list[float] = []  # the shown run's rows: [first, last stamp, first, last wall]
        self._counts: dict[str, int] = collections.defaultdict(int)
        self._window_start = time.monotonic()
        self.rates_hz: dict[str, float] = {}
        self.frames_in = 0
        self.busy_ms = 0.0  # the longest a call held the event loop in this window (note_busy)

    # ------------------------------------------------------------------ out
    def frame_text(self, stream: str, payload: str) -> str:
        """The message a page receives: stream, send time (ms) and data."""
        return f'{{"s":{json.dumps(stream)},"ts":{self.clock() * 1e3:.3f},"d":{payload}}}'

    def publish(self, stream: str, data: Mapping[str, Any], *, latch: bool = False) -> None:
        """Send a frame to every page (and keep it for later pages when ``latch``)."""
        if stream == "events" and data.get("run_s") is None:
            data = {**data, "run_s": self.run_time_s(data.get("t"))}
        payload = dumps(data)
        if latch or stream in LATCHED_STREAMS:
            self.latched[stream] = payload
        elif stream in self.history:
            self.history[stream].append(payload)
        elif stream in HISTORY_POINTS:
            self._keep(stream, data)
        t = data.get("t")
        self._counts[stream] += len(t) if isinstance(t, list) else 1
        if isinstance(t, list) and t and stream in HISTORY_POINTS:
            self._note_stamp(t[0])
        for page in self.pages:
            page.put(stream, payload)

    def _keep(self, stream: str, data: Mapping[str, Any]) -> None:
        """Append a columnar frame's rows to ``stream``'s bounded history."""
        t = data.get("t")
        if not isinstance(t, list) or not t:
            return
        rows = {k: v for k, v in data.items() if isinstance(v, list) and len(v) == len(t)}
        kept = self.series.get(stream)
        if kept is None or kept.keys != set(rows):  # the first frame, or other columns: afresh
            kept = self.series[stream] = History(frozenset(rows), HISTORY_POINTS[stream])
        kept.extend(rows)

    def history_frames(self) -> list[tuple[str, str]]:
        """The kept history of each columnar stream, in blocks of :data:`HISTORY_BLOCK_ROWS`
        rows (a late joiner's trails), the streams' blocks interleaved oldest first."""
        blocks = [
            [(stream, text) for text in kept.frames()] for stream, kept in self.series.items()
        ]
        return [f for row in itertools.zip_longest(*blocks) for f in row if f is not None]

    def _is_wall(self, t: float) -> bool:
        since = None if self.run_clock is None else self.run_clock.get("since")
        return isinstance(since, int | float) and abs(t - since) < _WALL_SPAN_S

    def _note_stamp(self, t: Any) -> None:
        """A simulated run's first bag stamp: its time 0 (sent in ``runclock`` as ``t0``, every
        page's and plot's time 0)."""
        if isinstance(t, int | float) and not self._is_wall(t):
            t0 = t if self._data_t0 is None else min(self._data_t0, t)
            if t0 != self._data_t0:
                self._data_t0 = t0
                if self.run_clock is not None:
                    self.run_clock = {**self.run_clock, "t0": t0}
                    self.publish("runclock", self.run_clock, latch=True)

    def run_time_s(self, t: Any) -> float | None:
        """Seconds of the run at stamp ``t``: since the run's wall-clock start (its link's
        ``since``), or, for a simulated run's bag time, since its first stamp."""
        if not isinstance(t, int | float):
            return None
        if self._is_wall(t):
            assert self.run_clock is not None
            return float(t - self.run_clock["since"])
        self._note_stamp(t)
        assert self._data_t0 is not None
        return float(t - self._data_t0)

    def attach(self) -> PageQueue:
        """A new page: its queue, the latched data, the run's clock and the history of every
        stream (bounded: the recent trails, events and factors)."""
        started_s, at_ms = time.perf_counter(), self.clock() * 1e3
        page = PageQueue()
        for stream, payload in self.latched.items():
            page.put(stream, payload)
        for stream, payload in self.history_frames():
            page.put(stream, payload)
        for stream, kept in self.history.items():
            for payload in kept:
                page.put(stream, payload)
        took_ms = (time.perf_counter() - started_s) * 1e3
        self.note_busy(took_ms)
        page.put("hub", dumps({**self.status(), "attach": {"at": at_ms, "ms": took_ms}}))
        self.pages.add(page)
        return page

    def note_busy(self, ms: float) -> None:
        """A call held the event loop ``ms`` (the ``hub`` frame's ``busy_ms``: the longest in
        its window, time every page's frames waited)."""
        self.busy_ms = max(self.busy_ms, ms)

    def detach(self, page: PageQueue) -> None:
        """A page closed."""
        self.pages.discard(page)

    # ------------------------------------------------------------------ in
    def source_connected(self, key: int, name: str) -> None:
        """A run connected to the ingest socket."""
        self.sources[key] = name

    def source_gone(self, key: int) -> None:
        """A run's connection closed."""
        name = self.sources.pop(key, None)
        if key in self.devices:  # the page's device line goes with it
            self.devices.discard(key)
            self.publish("device", {"source": name, "gone": True})
        if key == self._run_key and self.run_clock is not None:
            self._run_key = None
            self.publish("runclock", {**self.run_clock, "end": self.clock()}, latch=True)
        if name is not None:
            self.publish("events", {"t": self.clock(), "kind": "source", "level": "info",
                                    "text": f"{name} disconnected"})  # fmt: skip

    def ingest(self, key: int, text: str) -> None:
        """One message from a run: ``{"kind": hello|frame|latch, "stream": ..., "data": {...}}``.

        Raises:
            ValueError: not such a message.
        """
        message = json.loads(text)
        if not isinstance(message, dict) or not isinstance(message.get("data"), dict):
            msg = "an ingest message is an object with 'kind', 'stream' and 'data'"
            raise ValueError(msg)
        kind, stream, data = message.get("kind"), str(message.get("stream")), message["data"]
        self.frames_in += 1
        if kind == "hello":
            self._hello(key, data)
            return
        if key != self._shown_run and self._shown_run is not None:
            if key not in self.devices:  # an earlier run still connected: not the one shown
                self.held_back += 1
                return
            shown_as = self._device_stream(stream, data)
            if shown_as is None:
                self.held_back += 1
                return
            if shown_as == "device":
                self.publish("device", {**data, "source": self.sources.get(key, "device")})
                return
        elif key == self._shown_run and stream in HISTORY_POINTS:
            t = data.get("t")
            if isinstance(t, list) and t and all(isinstance(v, int | float) for v in (t[0], t[-1])):
                if self._run_wall is None:
                    self._run_wall = self._is_wall(t[0])
                self._note_span(float(min(t[0], t[-1])), float(max(t[0], t[-1])))
        if kind == "latch":
            self._latched_by[stream] = key
        self.publish(stream, data, latch=kind == "latch")
        for derived, payload in self.live.on_frame(stream, data):
            self.publish(derived, payload)

    def _note_span(self, first: float, last: float) -> None:
        now = time.monotonic()
        if not self._span:
            self._span = [first, last, now, now]
        else:
            sp = self._span
            sp[0], sp[1], sp[3] = min(sp[0], first), max(sp[1], last), now

    def speedup(self) -> float | None:
        """Robot seconds per wall second the shown run's rows came at, when well above 1 (an
        in-process run sent whole, simulated), else None."""
        if len(self._span) < 4 or self._run_wall is not False:  # wall stamps: a live run
            return None
        robot_s, wall_s = self._span[1] - self._span[0], self._span[3] - self._span[2]
        ratio = robot_s / max(wall_s, 0.05)
        return ratio if robot_s > 1.0 and ratio > 3.0 else None

    def _hello(self, key: int, data: Mapping[str, Any]) -> None:
        """A source connected: a run (``reset``) starts the page afresh and becomes what it
        shows; a device (``twin serve``) beside a run is shown as that device only."""
        name = str(data.get("source", "run"))
        self.source_connected(key, name)
        reset = bool(data.get("reset", True))
        if not reset:
            self.devices.add(key)
        if reset:
            self.live.reset()
            self._shown_run, self._run_wall = key, None
            # what the last run sent goes; the monitor's own (--map, --beacons) and a
            # connected device's stay
            for gone in ("origin", "recording", "map", "beacons"):
                owner = self._latched_by.get(gone)
                mine = owner is None and gone in {"map", "beacons"}
                if not mine and owner not in self.devices:
                    self.latched.pop(gone, None)
                    self._latched_by.pop(gone, None)
            for kept in self.history.values():  # the events too: the page's log is the run's
                kept.clear()
            still_latched = frozenset(self.latched)  # what a page has not had of the last run
            for page in self.pages:  # goes too, but for what the hub still latches
                page.forget(still_latched)
            self.series.clear()
            self._data_t0 = None
            self._span = []
        if not reset and self._shown_run is not None and self._shown_run not in self.sources:
            self._shown_run, self._run_wall = None, None  # the run is over: the device shows
        if reset or self._shown_run is None:
            still = sorted(k for k in ("beacons", "map") if k in self.latched)
            self.publish("source", {**data, "kept": still}, latch=True)
        else:
            self.publish("device", {"source": name, "pid": data.get("pid")})
        if reset or self.run_clock is None:  # the run's own start stamp, for run time
            since = data.get("since")
            self._run_key = key
            self.run_clock = {
                "since": float(since) if isinstance(since, int | float) else self.clock(),
                "source": name,
                "end": None,
            }
            self.publish("runclock", self.run_clock, latch=True)
        self.publish("events", {"t": self.clock(), "kind": "source", "level": "info",
                                "text": f"{name} connected (pid {data.get('pid')})"})  # fmt: skip

    def _device_stream(self, stream: str, data: Mapping[str, Any]) -> str | None:
        """A device's frame beside the shown run: its status as ``device``, its rows only if
        stamped by the run's clock (a served twin a run drives), else None (held back)."""
        if stream == "status":
            return "device"
        if stream in {"events", "beacons"}:  # the device's beacons are the run's too
            return stream
        t = data.get("t")
        stamp = t[0] if isinstance(t, list) and t else t
        if self._run_wall is None or not isinstance(stamp, int | float):
            return None
        return stream if self._is_wall(stamp) == self._run_wall else None

    # ------------------------------------------------------------------ rates
    def status(self) -> dict[str, Any]:
        """The ``hub`` frame: stream rates (rows/s), pages, runs connected, frames dropped."""
        return {
            "t": self.clock(),
            "rates": dict(self.rates_hz),
            "pages": len(self.pages),
            "sources": sorted(self.sources.values()),
            "dropped": sum(sum(p.dropped.values()) for p in self.pages),
            "speedup": self.speedup(),
            "busy_ms": round(self.busy_ms, 3),
        }

    def tick(self) -> None:
        """Once a second: the rates over the last window, sent as a ``hub`` frame."""
        now = time.monotonic()
        span = max(now - self._window_start, 1e-3)
        self.rates_hz = {s: n / span for s, n in self._counts.items() if s not in {"hub"}}
        self._counts.clear()
        self._window_start = now
        self.publish("hub", self.status())
        self.busy_ms = 0.0
