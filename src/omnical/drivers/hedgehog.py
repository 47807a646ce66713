"""A live Marvelmind hedgehog on a serial port: positions, raw distances, quality, beacon map.

:class:`SerialHedgehog` keeps, per topic, the rows the twin records, stamped on the host's clock
(from the device's own timestamps); ``latest_fix``, ``beacons`` and ``silence`` serve a live loop.
"""

from __future__ import annotations

import collections
import contextlib
import itertools
import math
import statistics
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from omnical.drivers.watchdog import Silence, silence_detail
from omnical.ips.marvelmind.position import HedgePosition, PositionFlag
from omnical.ips.marvelmind.records import BeaconPositions, DistanceFlag, Quality, RawDistances
from omnical.ips.marvelmind.stream import StreamReader, open_serial
from omnical.recording.topics import (
    BEACON_RAW_DISTANCE,
    BEACONS_POS_A,
    HEDGE_POS_ANG,
    HEDGE_QUALITY,
)

if TYPE_CHECKING:
    from omnical.drivers.wheeltec_serial import SerialPort

__all__ = ["HedgeFix", "HedgeRows", "SerialHedgehog"]


@dataclass(frozen=True)
class HedgeFix:
    """A position the hedgehog streamed: host time, map x, y, z (m), device timestamp."""

    t_s: float
    x_m: float
    y_m: float
    z_m: float
    timestamp_ms: int


@dataclass
class HedgeRows:
    """Rows per topic since the last drain: ``topic -> (times_s, {column: values})``."""

    rows: dict[str, tuple[list[float], dict[str, list[Any]]]] = field(default_factory=dict)

    def add(self, topic: str, t_s: float, **values: Any) -> None:
        """Append one row."""
        times, cols = self.rows.setdefault(topic, ([], {k: [] for k in values}))
        times.append(t_s)
        for k, v in values.items():
            cols[k].append(v)


MAX_SILENCE_LIMIT_S = 1.0
"""The longest a required hedgehog may send no position, whatever its rate (a time-scaled test
clock raises it with ``min_limit_s``)."""


def _is_fix(record: object) -> bool:
    """A position with coordinates: what a run that needs the hedgehog lives on."""
    return isinstance(record, HedgePosition) and not (
        int(record.flags) & int(PositionFlag.COORDINATES_UNAVAILABLE)
    )


class SerialHedgehog:
    """The hedgehog's stream read live.

    Args:
        port: an open port (``open_serial``) or anything with ``read`` / ``in_waiting`` /
            ``close``.
        clock: monotonic time source, s.
        device_time: stamp rows from the device's timestamps (False: on receipt).
        offset_window_s: how far back the smallest receive − device offset is taken, s.
        name: the device as the user names it, in messages ("hedgehog on PORT").
        min_limit_s: the shortest silence limit, s (see :meth:`silence`).
    """

    def __init__(
        self,
        port: SerialPort | Any,
        *,
        clock: Callable[[], float] = time.monotonic,
        device_time: bool = True,
        offset_window_s: float = 10.0,
        name: str = "hedgehog",
        min_limit_s: float = 0.3,
    ):
        self._port = port
        self.name = name
        self._min_limit_s = min_limit_s
        self._measured_rx: collections.deque[float] = collections.deque(maxlen=17)
        self._bytes_at_valid = 0
        self._clock = clock
        self._device_time = device_time
        self._offset_window_s = offset_window_s
        self._offsets: dict[str, collections.deque[tuple[float, float]]] = {}
        self._last_stamp: float | None = None
        self._latest_by_kind: dict[str, float] = {}
        self.reader = StreamReader()
        self._lock = threading.Lock()
        self._rows = HedgeRows()
        self._latest: HedgeFix | None = None
        self.beacons: dict[int, tuple[float, float, float]] = {}
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="hedgehog-reader", daemon=True)
        self._thread.start()

    @classmethod
    def open(
        cls,
        path: str,
        baudrate: int = 115200,
        *,
        clock: Callable[[], float] = time.monotonic,
        min_limit_s: float = 0.3,
    ) -> SerialHedgehog:
        """Open ``path`` (timeout 10 ms) and start reading, stamping with ``clock``."""
        port = open_serial(path, baudrate, timeout_s=0.01)
        port.reset_input_buffer()
        return cls(port, clock=clock, name=f"hedgehog on {path}", min_limit_s=min_limit_s)

    def silence(self, now_s: float) -> Silence:
        """Time since the last position with coordinates, and what came since.

        The limit is three measurement periods (the median spacing of the last 16 such
        positions as received; 0.1 s before there are 4), at least ``min_limit_s`` and at most
        :data:`MAX_SILENCE_LIMIT_S` (a hedgehog that slows down does not widen its own limit).
        """
        with self._lock:
            rx = list(self._measured_rx)
            since = self.reader.stats.bytes_received - self._bytes_at_valid
        silent = now_s - rx[-1] if rx else math.inf
        period = (
            statistics.median(b - a for a, b in itertools.pairwise(rx)) if len(rx) >= 4 else 0.1
        )
        limit = min(
            max(3.0 * period, self._min_limit_s), max(MAX_SILENCE_LIMIT_S, self._min_limit_s)
        )
        if self.error is not None:
            limit = 0.0
        return Silence(self.name, silent, limit, silence_detail(since, self.error))

    def latest_fix(self) -> HedgeFix | None:
        """The newest position with coordinates."""
        with self._lock:
            return self._latest

    def drain(self) -> dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]:
        """The rows received since the last call, as arrays per topic."""
        with self._lock:
            rows, self._rows = self._rows, HedgeRows()
        return {
            topic: (
                np.asarray(times, dtype=np.float64),
                {k: np.asarray(v) for k, v in cols.items()},
            )
            for topic, (times, cols) in rows.rows.items()
        }

    def close(self) -> None:
        """Stop reading and close the port."""
        self._stop.set()
        self._thread.join(timeout=1.0)
        with contextlib.suppress(Exception):
            self._port.close()

    def __enter__(self) -> SerialHedgehog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _loop(self) -> None:
        try:
            while not self._stop.is_set():
                waiting = getattr(self._port, "in_waiting", 0)
                data = self._port.read(max(1, min(int(waiting), 4096)))
                if data:
                    t = self._clock()
                    records = self.reader.feed(data)
                    if records:
                        with self._lock:
                            for r in records:
                                self._record(t, r)
                            if any(_is_fix(r) for r in records):
                                self._measured_rx.append(t)
                                self._bytes_at_valid = self.reader.stats.bytes_received
        except Exception as err:  # the port went away: remembered for the caller
            self.error = err

    def _stamp(self, kind: str, t_rx: float, device_s: float) -> float:
        """Host time of a device timestamp: ``device_s`` + the smallest recent offset.

        One offset per packet kind (their timestamps may differ in unit or origin); the stamps
        of a kind never go back (an offset that drops by more than the packets' spacing would).
        """
        if not self._device_time:
            return t_rx
        offsets = self._offsets.setdefault(kind, collections.deque())
        raw = t_rx - device_s
        while offsets and offsets[-1][1] >= raw:  # a monotone deque: its head is the minimum
            offsets.pop()
        offsets.append((t_rx, raw))
        while offsets[0][0] < t_rx - self._offset_window_s:
            offsets.popleft()
        if abs(raw - offsets[0][1]) > 5.0:  # the device clock jumped (reboot, wrap): restart
            offsets.clear()
            offsets.append((t_rx, raw))
        stamp = max(min(t_rx, device_s + offsets[0][1]), self._latest_by_kind.get(kind, -1e300))
        self._latest_by_kind[kind] = stamp
        return stamp

    def _record(self, t_rx: float, r: object) -> None:
        rows = self._rows
        t = t_rx
        if isinstance(r, HedgePosition):
            t = self._stamp("position", t_rx, r.timestamp_s)
            self._last_stamp = t
            flags = int(r.flags)
            rows.add(
                HEDGE_POS_ANG,
                t,
                address=r.address,
                timestamp_ms=r.timestamp,
                x_m=r.x_mm / 1000.0,
                y_m=r.y_mm / 1000.0,
                z_m=r.z_mm / 1000.0,
                flags=flags,
                angle_deg=0.0,
            )
            if not flags & int(PositionFlag.COORDINATES_UNAVAILABLE):
                self._latest = HedgeFix(
                    t, r.x_mm / 1000.0, r.y_mm / 1000.0, r.z_mm / 1000.0, r.timestamp
                )
        elif isinstance(r, RawDistances):
            t = self._stamp("distances", t_rx, r.timestamp_ms / 1000.0)
            for item in r.items:
                if item.address == 0 or item.flags & DistanceFlag.NOT_APPLICABLE:
                    continue
                rows.add(
                    BEACON_RAW_DISTANCE,
                    t,
                    address_hedge=r.hedge_address,
                    address_beacon=item.address,
                    distance_m=item.distance_mm / 1000.0,
                )
        elif isinstance(r, Quality):
            if self._last_stamp is not None and self._device_time:
                t = self._last_stamp
            rows.add(HEDGE_QUALITY, t, address=r.address, quality_percent=r.quality_percent)
        elif isinstance(r, BeaconPositions):
            for b in r.beacons:
                pos = (b.x_mm / 1000.0, b.y_mm / 1000.0, b.z_mm / 1000.0)
                self.beacons[b.address] = pos
                rows.add(BEACONS_POS_A, t, address=b.address, x_m=pos[0], y_m=pos[1], z_m=pos[2])
