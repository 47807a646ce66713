"""Multilateration of a recording of any length in bounded memory: the fixes of
:func:`omnical.ips.from_recording.locate`, computed a window at a time.

A long recording is read once (:class:`RangeRun` takes its raw distances a part at a time) and
its ranges are kept on disk, not in memory: first as messages, then grouped into fixes
(:class:`Spill`, an anonymous temporary file, gone when closed or when the process dies).
Grouping is cut where a gap segment starts (a burst never spans two); sequential (round-robin)
ranges get their sliding windows with each hedgehog's latest range of each beacon carried over,
their maximum age from the median period found on disk (:func:`median_on_disk`, exact).

The self-calibration of :func:`~omnical.ips.solve.solve_self_calibrated` needs the whole run,
but only through its learning sample: each learning pass solves the fixes a window at a time
and keeps on disk what the learning reads of the usable ones (position, beacons used, ranges);
the sample, at most :data:`LEARNING_FIXES` fixes per hedgehog evenly spread as ``usable_rows``
takes them, is then gathered and learnt from. The final pass solves each window with the learnt
model and hands the fixes over in order, the off-track check of each fix done once every fix
within its 1 s neighbourhood has been solved. Held in memory at once: a window of fixes, the
learning sample of a few hedgehogs, and what each hedgehog's model and off-track check carry
from one window to the next. With two workers and many hedgehogs, a forked process learns
every other hedgehog's model and finishes its fixes (the final pass and the off-track check
are each hedgehog's own) while this process does the rest; the two halves are then
interleaved in order (:meth:`WindowedLocate.learn`).

The same fixes as the whole run's (both learn from the same sample, at most
:data:`~omnical.ips.solve.selfcal.MAX_LEARNING_FIXES` usable fixes a hedgehog): bit for bit
where the solver's batches do not matter. They can, at the last bit: the vectorised
Gauss–Newton starts a batch from a shared linear solution when every range of the batch is
valid and treats a batch of one fix apart, and a window's hedgehogs are solved in one call
(:func:`~omnical.ips.solve.locate.solve_streams`), so a fix solved in another batch may differ
in its last bits (a printed last digit, now and then; one or two processes alike). A hedgehog
height estimated from 3D fixes is left to the whole-run path.
"""

from __future__ import annotations

import dataclasses
import errno
import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from omnical.choices import LocateMethod, parse_choice
from omnical.ips.beacons import BeaconMap, beacon_map_from_rows, default_beacon_map
from omnical.ips.bursts import DEFAULT_MAX_GAP_NS, burst_starts, group_bursts
from omnical.ips.forked import collect as _collect
from omnical.ips.forked import fork as _fork
from omnical.ips.forked import reap as _reap
from omnical.ips.solve._fit import SolverOptions
from omnical.ips.solve.fixes import Fixes, FixReason, FixStatus
from omnical.ips.solve.linkcov import learn_link_covariance, link_covariances
from omnical.ips.solve.locate import (
    LEARNING_ROUNDS,
    TRACK_NEIGHBOURS,
    TRACK_SPAN_NS,
    MergedFixes,
    Method,
    engine_for,
    model_for,
    off_track,
    solve_fixes,
    solve_streams,
    unread_by_learning,
)
from omnical.ips.solve.noise_model import NoiseModel
from omnical.ips.solve.selfcal import MAX_LEARNING_FIXES, learn_links, learn_sigma, linearise

if TYPE_CHECKING:
    from typing import IO

__all__ = [
    "FIX_WINDOW",
    "LEARNING_FIXES",
    "MAX_WINDOW",
    "MESSAGE_WINDOW",
    "PARALLEL_FIXES",
    "RangeRun",
    "Spill",
    "WindowedLocate",
]

FIX_WINDOW = 2_048
"""Fixes of one hedgehog solved at a time (the solver's temporaries: about 1.2 kB a fix)."""
MAX_WINDOW = 131_072
"""Most fixes of all hedgehogs in one window: a window is :data:`FIX_WINDOW` fixes per
hedgehog, up to this. Many streams are then still solved in few calls each (each call costs
~1 ms of numpy overhead: windows of 16,384 fixes took the 100-stream stress bag from 4.2 to
6.9 s of CPU), at the price of ~0.3 kB a fix of the window while its fixes are finished:
with 100 streams the peak grows until a window is full (~35 minutes of the stress bag)."""
LEARNING_FIXES = MAX_LEARNING_FIXES
"""Most usable fixes of a hedgehog the learning reads, evenly spread over the run: the whole-run
path's cap (4,096; it was 40,000, with its temporaries about 0.75 kB a fix, 30 MB on an hour of
one hedgehog), so ``omnical locate`` and the commands that locate a whole run in memory
(evaluate, calibrate) learn the same noise models."""
MESSAGE_WINDOW = 65_536
"""Raw-distance messages grouped into fixes at a time."""

_GATHER_ROWS = 16_384
"""Usable fixes read at a time when the learning samples are gathered."""
_SAMPLE_FIXES = 65_536
"""Most fixes of the learning samples gathered at once (about 5 MB; at least one hedgehog's,
:data:`LEARNING_FIXES`): each group of hedgehogs costs a pass over the usable fixes (twice
:data:`LEARNING_FIXES` a group cost the 100-stream stress bag 14 passes a round)."""
PARALLEL_FIXES = 20_000
"""Fixes from which :meth:`WindowedLocate.learn` forks a second process (start-up: ~10 ms)."""

_RAW = np.dtype([("t", "<i8"), ("hedge", "<i8"), ("beacon", "<i8"), ("d", "<f8")])


class Spill:
    """Records of one structured dtype on an anonymous temporary file, read back in windows."""

    def __init__(self, dtype: np.dtype[Any]) -> None:
        self.dtype = dtype
        self.rows = 0
        # Closed by close() (or with the process): not a with-block, it outlives this call.
        self._file: IO[bytes] = tempfile.TemporaryFile(prefix="omnical-", buffering=0)  # noqa: SIM115

    def append(self, records: NDArray[Any]) -> None:
        """Add ``records`` (of :attr:`dtype`) at the end.

        Raises:
            OSError: the write failed (the disk full, ...), named as a temporary file.
        """
        if records.size:
            self.write_at(self.rows, records)

    def write_at(self, row: int, records: NDArray[Any]) -> None:
        """Write ``records`` from record ``row`` on (a forked process may write too).

        Raises:
            OSError: as :meth:`append`.
        """
        data = np.ascontiguousarray(records, dtype=self.dtype).tobytes()
        try:
            written = os.pwrite(self._file.fileno(), data, row * self.dtype.itemsize)
        except OSError as err:
            raise _temporary(err) from None
        if written != len(data):  # a full disk may take a part
            raise _temporary(OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)))
        self.rows = max(self.rows, row + records.size)

    def read(self, lo: int, hi: int) -> NDArray[Any]:
        """Records ``lo:hi`` (read-only; positioned reads: a forked process may read too).

        Raises:
            OSError: as :meth:`append`.
        """
        size = self.dtype.itemsize
        try:
            data = os.pread(self._file.fileno(), (hi - lo) * size, lo * size)
        except OSError as err:
            raise _temporary(err) from None
        return np.frombuffer(data, dtype=self.dtype)

    def windows(self, size: int) -> Iterator[NDArray[Any]]:
        """Every record, ``size`` at a time, in order."""
        for lo in range(0, self.rows, size):
            yield self.read(lo, min(lo + size, self.rows))

    def close(self) -> None:
        """Delete the file."""
        self._file.close()

    def fileno(self) -> int:
        """The file's descriptor (:class:`~omnical.ips.forked.Shared`: a spill made by a
        forked process comes back as its open file)."""
        return self._file.fileno()

    def handover(self) -> tuple[np.dtype[Any], int]:
        """The rest of the spill: its dtype and rows."""
        return self.dtype, self.rows

    @classmethod
    def adopt(cls, fd: int, state: tuple[np.dtype[Any], int]) -> Spill:
        """The spill of a forked process from its open file ``fd`` (now this one's)."""
        spill = cls.__new__(cls)
        spill.dtype, spill.rows = state
        spill._file = os.fdopen(fd, "r+b", buffering=0)
        return spill


def _temporary(err: OSError) -> OSError:
    """``err`` naming the spill's temporary file (an anonymous one: the error had no name)."""
    where = f"a temporary file in {tempfile.gettempdir()} (TMPDIR)"
    return type(err)(err.errno, err.strerror, where)


def _distinct(values: NDArray[np.int64], more: NDArray[np.int64]) -> NDArray[np.int64]:
    return np.union1d(values, np.unique(more)).astype(np.int64)


@dataclass
class RangeRun:
    """What :func:`~omnical.ips.from_recording.locate` reads of a recording, taken a part at a
    time: the raw distances (to disk), the latest row of each beacon of ``/beacons_pos_a``, and
    the distinct heights of the vendor's valid positions (for :func:`hedge_height`).
    """

    raw: Spill = field(default_factory=lambda: Spill(_RAW))
    heard: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    hedges: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    beacon_rows: dict[str, NDArray[np.generic]] | None = None
    vendor: bool = False
    heights: Spill = field(default_factory=lambda: Spill(np.dtype("<i8")))
    """The vendor's valid heights, as :func:`float_keys`."""
    nan_heights: bool = False

    def add_ranges(
        self,
        t_ns: NDArray[np.int64],
        address_hedge: NDArray[np.integer],
        address_beacon: NDArray[np.integer],
        distance_m: NDArray[np.floating],
    ) -> None:
        """The next ``/beacon_raw_distance`` messages, in time order."""
        records = np.empty(t_ns.size, dtype=_RAW)
        records["t"] = t_ns
        records["hedge"] = address_hedge
        records["beacon"] = address_beacon
        records["d"] = distance_m
        self.raw.append(records)
        self.heard = _distinct(self.heard, records["beacon"])
        self.hedges = _distinct(self.hedges, records["hedge"])

    def close(self) -> None:
        """Delete what is on disk."""
        self.raw.close()
        self.heights.close()

    def restart_ranges(self) -> None:
        """Forget the ranges added (their topic is about to be handed over again, whole)."""
        self.raw.close()
        self.raw = Spill(_RAW)
        self.heard = np.zeros(0, dtype=np.int64)
        self.hedges = np.zeros(0, dtype=np.int64)

    def add_beacons(
        self,
        t_ns: NDArray[np.int64],
        address: NDArray[np.integer],
        x_m: NDArray[np.floating],
        y_m: NDArray[np.floating],
        z_m: NDArray[np.floating],
        *,
        first: bool = False,
    ) -> None:
        """The next ``/beacons_pos_a`` rows; only the latest of each address is kept."""
        part = {"t": t_ns, "address": address, "x": x_m, "y": y_m, "z": z_m}
        if self.beacon_rows is not None and not first:
            part = {k: np.concatenate([self.beacon_rows[k], v]) for k, v in part.items()}
        # beacon_map_from_rows's rule: the last row of the stable time order wins.
        order = np.argsort(part["t"].astype(np.int64), kind="stable")[::-1]
        _, newest = np.unique(part["address"][order], return_index=True)
        keep = np.sort(order[newest])
        self.beacon_rows = {k: v[keep] for k, v in part.items()}

    def add_vendor(
        self, z_m: NDArray[np.floating], flags: NDArray[np.integer], *, first: bool = False
    ) -> None:
        """The next ``/hedge_pos_ang`` rows: the heights of the valid ones (to disk)."""
        if first:
            self.heights.close()
            self.heights, self.nan_heights = Spill(np.dtype("<i8")), False
        self.vendor = True
        z = np.asarray(z_m[(flags & _FIX_UNAVAILABLE) == 0], dtype=np.float64)
        self.nan_heights |= bool(np.isnan(z).any())
        self.heights.append(float_keys(z))

    def beacon_map(self, beacons: BeaconMap | None = None) -> BeaconMap:
        """As :func:`~omnical.ips.from_recording.beacon_map_of`."""
        if beacons is not None:
            return beacons
        rows = self.beacon_rows
        if rows is not None and rows["t"].size:
            return beacon_map_from_rows(
                rows["address"], rows["x"], rows["y"], rows["z"], t_ns=rows["t"]
            )
        return default_beacon_map()

    def hedge_height(self, beacons: BeaconMap, address: int) -> float | None:
        """As :func:`~omnical.ips.from_recording.hedge_height_of`: the map's height, else the
        median of the vendor's valid heights (``np.median`` of them, found on disk)."""
        z = beacons.hedge_height_m(address)
        if z is not None:
            return z
        if not self.vendor or self.heights.rows == 0:
            return None
        if self.nan_heights:  # np.median gives NaN
            return float("nan")
        middle = middle_on_disk(self.heights)
        assert middle is not None
        return float(np.mean(key_floats(np.asarray(middle, dtype=np.int64))))

    def group(
        self,
        beacons: BeaconMap,
        *,
        window: int = MESSAGE_WINDOW,
        max_gap_ns: int = DEFAULT_MAX_GAP_NS,
    ) -> tuple[Spill, NDArray[np.int64]]:
        """The raw distances grouped into fixes (:func:`~omnical.ips.bursts.group_bursts`) on
        disk, and the number of fixes with each count of valid distances (0 to m).

        The messages are grouped a window at a time, each cut where its last gap segment (or,
        past a window of carry, its last burst) starts: a burst never spans two, the same fixes
        as grouping them all at once.

        Raises:
            ConfigError: the times decrease.
        """
        m = len(beacons)
        spill = Spill(_burst_dtype(m))
        n_valid = np.zeros(m + 1, dtype=np.int64)
        carry: NDArray[Any] = np.zeros(0, dtype=_RAW)

        def emit(records: NDArray[Any]) -> None:
            bursts = group_bursts(
                records["t"], records["hedge"], records["beacon"], records["d"], beacons,
                max_gap_ns=max_gap_ns,
            )  # fmt: skip
            out: NDArray[Any] = np.empty(len(bursts), dtype=spill.dtype)
            out["t"] = bursts.t_ns
            out["hedge"] = bursts.address_hedge
            out["d"] = bursts.distances_m
            out["unknown"] = bursts.n_unknown > 0
            out["invalid"] = bursts.n_invalid > 0
            spill.append(out)
            n_valid[:] += np.bincount(bursts.n_valid, minlength=m + 1)

        for part in self.raw.windows(window):
            records = np.concatenate([carry, part]) if carry.size else part
            t, hedge = records["t"], records["hedge"]
            if np.any(np.diff(t) < 0):
                emit(records)  # group_bursts says where the time goes back
            # cut where the last gap segment starts (a burst starts there), or, when that
            # would carry more than a window (bursts never 15 ms apart: it had carried the
            # whole run), at the last burst start: the greedy grouping restarts at either,
            # so the same fixes as grouping all at once
            starts = np.flatnonzero((np.diff(t) > max_gap_ns) | (hedge[1:] != hedge[:-1])) + 1
            cut = int(starts[-1]) if starts.size else 0
            if records.size - cut > window:
                first = burst_starts(
                    t[cut:], hedge[cut:], records["beacon"][cut:], max_gap_ns=max_gap_ns
                )
                cut += int(np.flatnonzero(first)[-1])
            if cut:
                emit(records[:cut])
            carry = records[cut:].copy()
        if carry.size:
            emit(carry)
        return spill, n_valid

    def sliding(self, beacons: BeaconMap, *, window: int = MESSAGE_WINDOW) -> tuple[Spill, int]:
        """:func:`~omnical.ips.bursts.sliding_windows` of the raw distances, on disk, and the
        maximum age used (1.5 times the median period of a beacon, as there), ns.

        Three passes over the messages: the periods (to disk), their median (by
        :func:`median_on_disk`), then the windows, each hedgehog's latest range of each beacon
        carried from one part to the next.
        """
        m = len(beacons)
        age = self._max_age_ns(beacons, window)
        spill = Spill(_burst_dtype(m))
        h_count = max(self.hedges.size, 1)
        carry_t = np.zeros((h_count, m), dtype=np.int64)
        carry_d = np.full((h_count, m), np.nan)
        carry_has = np.zeros((h_count, m), dtype=bool)
        for part in self.raw.windows(window):
            t, d = part["t"], part["d"]
            column = beacons.index_of(part["beacon"])
            unknown = column < 0
            invalid = ~np.isfinite(d) | (d < 0.0)
            keep = ~unknown & ~invalid
            matrix = np.full((t.size, m), np.nan)
            # the messages by hedgehog (in time order within each): a beacon's latest range
            # up to each message is the last marked position at or before it, if that is
            # within its hedgehog's run of positions, else the range carried over
            order = np.argsort(np.searchsorted(self.hedges, part["hedge"]), kind="stable")
            hedge = np.searchsorted(self.hedges, part["hedge"][order])
            position = np.arange(t.size)
            start = np.ones(t.size, dtype=bool)
            start[1:] = hedge[1:] != hedge[:-1]
            first = np.maximum.accumulate(np.where(start, position, 0))
            ends = np.append(np.flatnonzero(start)[1:], t.size) - 1
            mine_t = t[order]
            for k in range(m):
                marked = keep[order] & (column[order] == k)
                latest = np.maximum.accumulate(np.where(marked, position, -1))
                here = latest >= first
                source = order[np.maximum(latest, 0)]
                have = here | carry_has[hedge, k]
                when = np.where(here, t[source], carry_t[hedge, k])
                fresh = have & (mine_t - when <= age)
                value = np.where(here, d[source], carry_d[hedge, k])
                matrix[order[fresh], k] = value[fresh]
                last = ends[here[ends]]
                carry_t[hedge[last], k], carry_d[hedge[last], k] = t[source[last]], d[source[last]]
                carry_has[hedge[last], k] = True
            out: NDArray[Any] = np.empty(t.size, dtype=spill.dtype)
            out["t"] = t
            out["hedge"] = part["hedge"]
            out["d"] = matrix
            out["unknown"] = unknown
            out["invalid"] = invalid & ~unknown
            spill.append(out)
        return spill, age

    def _max_age_ns(self, beacons: BeaconMap, window: int) -> int:
        """1.5 times the median time between two usable ranges of one link, ns (or the
        default gap without two)."""
        m = len(beacons)
        periods = Spill(np.dtype("<i8"))
        last = np.full(max(self.hedges.size, 1) * m, -1, dtype=np.int64)
        for part in self.raw.windows(window):
            t, d = part["t"], part["d"]
            column = beacons.index_of(part["beacon"])
            keep = (column >= 0) & np.isfinite(d) & (d >= 0.0)
            key = np.searchsorted(self.hedges, part["hedge"][keep]) * m + column[keep]
            order = np.argsort(key, kind="stable")
            key, times = key[order], t[keep][order]
            if key.size == 0:
                continue
            first = np.ones(key.size, dtype=bool)
            first[1:] = key[1:] != key[:-1]
            within = (times[1:] - times[:-1])[~first[1:]]
            heads = np.flatnonzero(first)
            known = last[key[heads]] >= 0
            across = times[heads[known]] - last[key[heads[known]]]
            periods.append(np.concatenate([across, within]))
            ends = np.append(heads[1:], key.size) - 1
            last[key[ends]] = times[ends]
        median = median_on_disk(periods)
        periods.close()
        return int(1.5 * median) if median is not None else DEFAULT_MAX_GAP_NS


def median_on_disk(values: Spill, *, limit: int = 1 << 20) -> float | None:
    """``np.median`` of the int64 values of a spill (None if there are none), exactly, holding
    at most ``limit`` of them at once (:func:`middle_on_disk`)."""
    middle = middle_on_disk(values, limit=limit)
    return None if middle is None else float(np.mean(np.asarray(middle, dtype=np.int64)))


def middle_on_disk(values: Spill, *, limit: int = 1 << 20) -> list[int] | None:
    """The middle value (odd count) or two middle values (even) of the int64 values of a
    spill, None if there are none: each pass counts them in 2¹⁶ buckets of the range that
    holds the one sought, until that range holds few enough (``limit``) to sort."""
    n = values.rows
    if n == 0:
        return None
    ranks = [n // 2] if n % 2 else [n // 2 - 1, n // 2]
    return [_select(values, rank, limit) for rank in ranks]


def float_keys(values: NDArray[np.float64]) -> NDArray[np.int64]:
    """int64 keys in the order of the (non-NaN) float64 ``values`` (−0 before +0)."""
    bits = np.ascontiguousarray(values, dtype=np.float64).view(np.int64)
    keys: NDArray[np.int64] = bits ^ ((bits >> 63) & np.int64(0x7FFFFFFFFFFFFFFF))
    return keys


def key_floats(keys: NDArray[np.int64]) -> NDArray[np.float64]:
    """The float64 values of :func:`float_keys`."""
    bits = keys ^ ((keys >> 63) & np.int64(0x7FFFFFFFFFFFFFFF))
    return bits.view(np.float64)


def _select(values: Spill, rank: int, limit: int) -> int:
    """The value of the given rank (0: the smallest) among the int64 values of ``values``."""
    lo = min(int(p.min()) for p in values.windows(limit))
    hi = max(int(p.max()) for p in values.windows(limit))
    below = 0
    while True:
        inside = sum(int(np.count_nonzero((p >= lo) & (p <= hi))) for p in values.windows(limit))
        if inside <= limit or lo == hi:
            if lo == hi:
                return lo
            chosen = [p[(p >= lo) & (p <= hi)] for p in values.windows(limit)]
            return int(np.sort(np.concatenate(chosen))[rank - below])
        shift = max((hi - lo).bit_length() - 16, 0)
        counts = np.zeros(((hi - lo) >> shift) + 1, dtype=np.int64)
        base = np.array([lo], dtype=np.int64).view(np.uint64)[0]
        for part in values.windows(limit):
            mine = part[(part >= lo) & (part <= hi)]
            offsets = mine.view(np.uint64) - base  # lo <= mine: the unsigned difference
            counts += np.bincount(
                (offsets >> np.uint64(shift)).astype(np.intp), minlength=counts.size
            )
        ends = np.cumsum(counts)
        bucket = int(np.searchsorted(ends, rank - below, side="right"))
        below += int(ends[bucket - 1]) if bucket else 0
        lo, hi = lo + (bucket << shift), min(hi, lo + ((bucket + 1) << shift) - 1)


_FIX_UNAVAILABLE = 0x01


def _burst_dtype(m: int) -> np.dtype[np.void]:
    return np.dtype(
        [("t", "<i8"), ("hedge", "<i8"), ("d", "<f8", (m,)), ("unknown", "?"), ("invalid", "?")]
    )


def sequential_from_counts(n_valid: NDArray[np.int64], dims: int = 2) -> bool:
    """:func:`~omnical.ips.bursts.is_sequential` from the count of fixes per number of valid
    distances: ``np.median`` of those numbers below ``dims + 1``."""
    total = int(n_valid.sum())
    if total == 0:
        return False
    ends = np.cumsum(n_valid)
    middle = [total // 2] if total % 2 else [total // 2 - 1, total // 2]
    values = np.searchsorted(ends, np.asarray(middle), side="right").astype(np.float64)
    return bool(np.mean(values) < dims + 1)


def _keep(block: NDArray[Any], rows: NDArray[np.intp], fixes: Fixes) -> None:
    """Write ``fixes`` into the rows ``rows`` of a block of :func:`_final_dtype` records."""
    for name, values in (
        ("p", fixes.positions_map_m),
        ("c", fixes.covariance_xy_m2),
        ("sz", fixes.sigma_z_m),
        ("rs", fixes.range_sigma_m),
        ("hdop", fixes.hdop),
        ("res", fixes.residual_rms_m),
        ("e4", fixes.error_eq4_m),
        ("used", fixes.used),
        ("s", fixes.status),
        ("r", fixes.reason),
    ):
        block[name][rows] = values


def _final_dtype(m: int) -> np.dtype[np.void]:
    return np.dtype(
        [
            ("p", "<f8", (3,)),
            ("c", "<f8", (2, 2)),
            ("sz", "<f8"),
            ("rs", "<f8"),
            ("hdop", "<f8"),
            ("res", "<f8"),
            ("e4", "<f8"),
            ("used", "?", (m,)),
            ("s", "u1"),
            ("r", "<u2"),
        ]
    )


def _usable_dtype(m: int) -> np.dtype[np.void]:
    return np.dtype(
        [("h", "<i8"), ("p", "<f8", (3,)), ("used", "?", (m,)), ("d", "<f8", (m,)), ("s", "u1")]
    )


@dataclass
class _Pending:
    """Fixes solved but not handed over yet: their off-track check waits for later fixes."""

    fixes: list[Fixes] = field(default_factory=list)

    def join(self) -> Fixes | None:
        if not self.fixes:
            return None
        if len(self.fixes) > 1:
            self.fixes = [_concatenate(self.fixes)]
        return self.fixes[0]


def _concatenate(parts: list[Fixes]) -> Fixes:
    first = parts[0]
    columns: dict[str, Any] = {
        f.name: np.concatenate([getattr(p, f.name) for p in parts])
        for f in dataclasses.fields(Fixes)
        if f.name not in {"beacon_addresses", "method", "dims", "noise", "notes"}
    }
    return dataclasses.replace(first, **columns)


def _take(fixes: Fixes, rows: slice) -> Fixes:
    columns: dict[str, Any] = {
        f.name: getattr(fixes, f.name)[rows]
        for f in dataclasses.fields(Fixes)
        if f.name not in {"beacon_addresses", "method", "dims", "noise", "notes"}
    }
    return dataclasses.replace(fixes, **columns)


class WindowedLocate:
    """:func:`~omnical.ips.solve.locate.locate_bursts` of fixes on disk, a window at a time.

    Args:
        bursts: The fixes of :meth:`RangeRun.group`.
        beacons: The map they were grouped with.
        hedges: The distinct hedgehog addresses of the run, sorted.
        method, dims, hedge_z_m, range_sigma_m, options, self_calibrate: As
            :func:`~omnical.ips.solve.locate.locate_bursts` (``range_sigma_m`` a scalar or None).
        window: Fixes of one hedgehog solved at a time (:data:`FIX_WINDOW`); a window holds
            that many per hedgehog of the run, at most :data:`MAX_WINDOW` (or ``window``).
        learning_fixes: Most usable fixes of a hedgehog the learning reads (evenly spread);
            with :data:`~omnical.ips.solve.selfcal.MAX_LEARNING_FIXES` the noise models, hence
            the fixes, are the whole-run path's bit for bit.
        workers: 2 to learn in two processes (:meth:`learn`), 1 in this one.
    """

    def __init__(
        self,
        bursts: Spill,
        beacons: BeaconMap,
        hedges: NDArray[np.int64],
        *,
        method: Method = "robust",
        dims: int = 2,
        hedge_z_m: float | None = None,
        range_sigma_m: float | None = None,
        options: SolverOptions | None = None,
        self_calibrate: bool = True,
        window: int = FIX_WINDOW,
        learning_fixes: int = LEARNING_FIXES,
        workers: int = 1,
    ) -> None:
        self.bursts, self.beacons, self.hedges = bursts, beacons, hedges
        self.learning_fixes = max(1, int(learning_fixes))
        self.method, self.dims, self.range_sigma_m = method, dims, range_sigma_m
        self.self_calibrate = self_calibrate
        self.window = max(1, min(int(window) * max(hedges.size, 1), max(MAX_WINDOW, int(window))))
        self.options = engine_for(options or SolverOptions(), hedges.size)
        fallback = np.nan if hedge_z_m is None else float(hedge_z_m)
        self.heights = np.full(hedges.size, fallback)
        for address, z in zip(beacons.hedge_addresses, beacons.hedge_z_m, strict=True):
            self.heights[hedges == address] = z
        self.models = [model_for(beacons, self.options, range_sigma_m, int(a)) for a in hedges]
        self.usable: NDArray[np.int64] | None = None
        """Usable fixes per hedgehog of the final solve, once known."""
        self.track_usable = np.zeros(hedges.size, dtype=np.int64)
        self._learnt = not self_calibrate
        self.workers = workers
        self.active: NDArray[np.bool_] | None = None
        """The hedgehogs solved and learnt (None: all)."""
        self.kept: Spill | None = None
        """The final fixes of the last learning pass: a region of every fix per process."""
        self.region = 0
        self.owner: NDArray[np.bool_] | None = None
        """The hedgehogs whose final fixes are in region 1 of :attr:`kept` (None: none)."""
        self.finished: tuple[Spill, Spill] | None = None
        """The final fixes of the hedgehogs not of the :attr:`owner` and of its, each in
        order, when two processes finished them (:meth:`learn`)."""

    # -- solving ---------------------------------------------------------------------------

    def _groups(self, window: NDArray[Any]) -> list[tuple[int, NDArray[np.intp]]]:
        """(hedgehog index, rows of the window) of each hedgehog, rows in order.

        One stable sort of the hedgehogs' indices (a radix sort when they fit 16 bits), their
        counts giving each one's rows (sorting the addresses, then again to find where each
        starts, was 0.1 s of each learning process on the 100-stream stress bag)."""
        index = np.searchsorted(self.hedges, window["hedge"])
        small = index.astype(np.uint16) if self.hedges.size <= 1 << 16 else index
        order = np.argsort(small, kind="stable")
        counts = np.bincount(index, minlength=self.hedges.size)
        ends = np.cumsum(counts)
        active = self.active
        return [
            (h, order[ends[h] - counts[h] : ends[h]])
            for h in np.flatnonzero(counts).tolist()
            if active is None or active[h]
        ]

    def _solve(self, h: int, distances: NDArray[np.float64], method: Method) -> Fixes:
        model = self.models[h]
        return solve_fixes(
            model.correct(distances),
            self.beacons,
            method=method,
            dims=self.dims,
            hedge_z_m=np.full(distances.shape[0], self.heights[h]),
            range_sigma_m=model.sigma_m,
            options=self.options,
        )

    def _sweep(self, method: Method, *, keep: bool = False) -> tuple[Spill, NDArray[np.int64]]:
        """Solve every fix with the current models; their usable fixes for the learning.

        Also counts each hedgehog's fixes usable for the off-track check in
        :attr:`track_usable`; with ``keep`` (the last pass: the final fixes), writes the fixes
        to this process's region of :attr:`kept`, where the final pass reads them.
        """
        m = len(self.beacons)
        usable = Spill(_usable_dtype(m))
        counts = np.zeros(self.hedges.size, dtype=np.int64)
        self.track_usable = np.zeros(self.hedges.size, dtype=np.int64)
        lo = 0
        for window in self.bursts.windows(self.window):
            block: NDArray[Any] = np.zeros(window.size, dtype=_final_dtype(m)) if keep else window
            groups = self._groups(window)
            if groups:  # the window's hedgehogs in one solve (records in the same order)
                rows = np.concatenate([r for _, r in groups])
                sizes = [r.size for _, r in groups]
                owner = np.repeat([h for h, _ in groups], sizes)
                corrected = [self.models[h].correct(window["d"][r]) for h, r in groups]
                fixes = solve_streams(
                    np.concatenate(corrected),
                    self.beacons,
                    sizes,
                    method=method,
                    dims=self.dims,
                    hedge_z_m=self.heights[owner],
                    range_sigma_m=[self.models[h].sigma_m for h, _ in groups],
                    options=self.options,
                )
                if keep:
                    _keep(block, rows, fixes)
                good = (fixes.status <= FixStatus.DEGRADED) & np.all(
                    np.isfinite(fixes.positions_map_m[:, :2]), axis=1
                )
                self.track_usable += np.bincount(owner[good], minlength=self.hedges.size)
                good &= fixes.n_used > fixes.dims
                records: NDArray[Any] = np.empty(int(good.sum()), dtype=usable.dtype)
                records["h"] = owner[good]
                records["p"] = fixes.positions_map_m[good]
                records["used"] = fixes.used[good]
                records["d"] = window["d"][rows[good]]
                records["s"] = fixes.status[good]
                usable.append(records)
                counts += np.bincount(records["h"], minlength=self.hedges.size)
            if keep and self.kept is not None:
                self.kept.write_at(self.region * self.bursts.rows + lo, block)
            lo += window.size
        return usable, counts

    def _samples(
        self, usable: Spill, counts: NDArray[np.int64]
    ) -> Iterator[tuple[int, NDArray[Any]]]:
        """Each active hedgehog's learning sample: its usable fixes, at most
        :attr:`learning_fixes` evenly spread (as ``usable_rows`` takes them).

        Gathered a few hedgehogs at a time (at most :data:`_SAMPLE_FIXES` fixes held, or one
        hedgehog's), each group by a pass over ``usable``, which is deleted once through.
        """
        cap = self.learning_fixes
        sizes = np.minimum(counts, cap)
        wanted = [h for h in range(self.hedges.size) if self.active is None or self.active[h]]
        group: list[int] = []
        held = 0
        for h in [*wanted, -1]:
            if group and (h < 0 or held + int(sizes[h]) > max(_SAMPLE_FIXES, cap)):
                yield from self._gather(usable, counts, group)
                group, held = [], 0
            if h >= 0:
                group.append(h)
                held += int(sizes[h])
        usable.close()

    def _gather(
        self, usable: Spill, counts: NDArray[np.int64], group: list[int]
    ) -> Iterator[tuple[int, NDArray[Any]]]:
        """The samples of the hedgehogs ``group`` (one pass over ``usable``)."""
        cap = self.learning_fixes
        picks = {
            h: np.linspace(0, int(counts[h]) - 1, cap).astype(np.intp) if counts[h] > cap else None
            for h in group
        }
        seen = dict.fromkeys(group, 0)
        parts: dict[int, list[NDArray[Any]]] = {h: [] for h in group}
        members = np.asarray(group, dtype=np.int64)
        for window in usable.windows(_GATHER_ROWS):
            hedge = window["h"]
            mine = np.flatnonzero(np.isin(hedge, members))
            if mine.size == 0:
                continue
            order = mine[np.argsort(hedge[mine], kind="stable")]
            present, starts = np.unique(hedge[order], return_index=True)
            for h, rows in zip(present.tolist(), np.split(order, starts[1:]), strict=True):
                chosen = picks[h]
                if chosen is None:
                    parts[h].append(window[rows].copy())
                else:
                    ordinal = seen[h] + np.arange(rows.size)
                    parts[h].append(window[rows[np.isin(ordinal, chosen)]].copy())
                seen[h] += rows.size
        for h in group:
            yield h, np.concatenate(parts[h]) if parts[h] else np.zeros(0, usable.dtype)
            parts[h] = []

    def _sample_fixes(self, sample: NDArray[Any]) -> Fixes:
        n = sample.size
        return Fixes(
            positions_map_m=np.ascontiguousarray(sample["p"]),
            **unread_by_learning(n),
            used=np.ascontiguousarray(sample["used"]),
            status=np.ascontiguousarray(sample["s"]),
            reason=np.zeros(n, dtype=np.uint16),
            beacon_addresses=self.beacons.addresses,
            method="robust",
            dims=self.dims,
        )

    def learn(self) -> tuple[NoiseModel, ...]:
        """Learn each hedgehog's noise model from the whole run (as
        :func:`~omnical.ips.solve.locate.solve_self_calibrated`); the models, by hedgehog.

        With :attr:`workers` 2 and at least :data:`PARALLEL_FIXES` fixes of two hedgehogs or
        more, a forked process learns every other hedgehog's model (each hedgehog's learning
        is its own: the same models) and finishes those hedgehogs' fixes (:meth:`_finish`),
        as this process does the rest's, for :meth:`fixes` to interleave (the final pass had
        been this process's alone: 0.78 of the 230,400-fix stress bag's 3.4 s); if it
        fails, its share is done here.
        """
        if self._learnt:
            if self.usable is None:
                # no self-calibration: one solve counts each hedgehog's usable fixes, so the
                # off-track check never waits for a hedgehog's count (a stray address with
                # a few ranges had held every later fix of the run in memory)
                self.kept = Spill(_final_dtype(len(self.beacons)))
                self._sweep(self.method, keep=True)[0].close()
                self.usable = self.track_usable
            return tuple(self.models)
        self.kept = Spill(_final_dtype(len(self.beacons)))
        if self.workers > 1 and self.hedges.size > 1 and self.bursts.rows >= PARALLEL_FIXES:
            theirs = np.arange(self.hedges.size) % 2 == 1
            self.owner = theirs
            child = _fork(lambda: self._learn_and_finish(theirs, region=1), shared=(Spill,))
            try:
                mine = self._learn_and_finish(~theirs, region=0)
                result = _collect(child)
            finally:
                _reap(child)
            if result is None:  # the child failed: its share done here, the counts kept
                counts = self.track_usable.copy()
                result = self._learn_and_finish(theirs, region=1)
                self.track_usable[~theirs] = counts[~theirs]
            models, usable, finished = result
            for h in np.flatnonzero(theirs).tolist():
                self.models[h] = models[h]
                self.track_usable[h] = usable[h]
            self.finished = (mine[2], finished)
            self.kept.close()
            self.kept = None
        else:
            self._learn(None)
        self.usable = self.track_usable
        self._learnt = True
        return tuple(self.models)

    def _learn_and_finish(
        self, active: NDArray[np.bool_], *, region: int
    ) -> tuple[list[NoiseModel], NDArray[np.int64], Spill]:
        """:meth:`_learn` of the ``active`` hedgehogs, then their final fixes, off-track
        checked (:meth:`_finish`)."""
        models, usable = self._learn(active, region=region)
        self.usable = usable
        return models, usable, self._finish(active)

    def _finish(self, active: NDArray[np.bool_]) -> Spill:
        """The final fixes of the ``active`` hedgehogs (their off-track check is theirs
        alone), in order, as records of :func:`_final_dtype`: half of what :meth:`fixes`
        does in each process, whose results it then interleaves."""
        assert self.usable is not None
        self.active = active
        out = Spill(_final_dtype(len(self.beacons)))
        track = _Track(self.hedges, self.usable)
        lo = 0
        for window in [*self.bursts.windows(self.window), None]:
            if window is None:
                done = track.push(None, last=True)
            else:
                done = track.push(self._final(window, lo), last=False)
                lo += window.size
            if done is not None:
                block: NDArray[Any] = np.empty(len(done), dtype=out.dtype)
                _keep(block, np.arange(len(done)), done)
                out.append(block)
        self.active = None
        return out

    def _learn(
        self, active: NDArray[np.bool_] | None, *, region: int = 0
    ) -> tuple[list[NoiseModel], NDArray[np.int64]]:
        """Learn the models of the ``active`` hedgehogs (None: all); the models and the
        usable fixes of the final solve, per hedgehog."""
        self.active, self.region = active, region
        learn_sigma_too = self.range_sigma_m is None
        usable, counts = self._sweep("lsq")
        for round_ in range(LEARNING_ROUNDS):
            for h, sample in self._samples(usable, counts):
                fixes = self._sample_fixes(sample)
                model = self.models[h]
                corrected = model.correct(sample["d"])
                lin = linearise(fixes, corrected, self.beacons, np.arange(sample.size))
                if learn_sigma_too:
                    model = learn_sigma(fixes, corrected, self.beacons, model, linearised=lin)
                self.models[h] = learn_links(
                    fixes, corrected, self.beacons, model, joint=round_ == 0, linearised=lin
                )
            last = round_ == LEARNING_ROUNDS - 1
            usable, counts = self._sweep(self.method if last else "robust", keep=last)
        if learn_sigma_too:
            for h, sample in self._samples(usable, counts):
                fixes = self._sample_fixes(sample)
                model = self.models[h]
                corrected = model.correct(sample["d"])
                self.models[h] = learn_link_covariance(fixes, corrected, self.beacons, model)
        usable.close()
        self.active = None
        return self.models, self.track_usable

    def _solved(self, window: NDArray[Any], lo: int) -> list[tuple[NDArray[np.intp], Fixes]]:
        """The final fixes of the window (its first fix is fix ``lo`` of the run) of each
        hedgehog, with their rows: kept by the last learning pass, else solved here."""
        link = self.self_calibrate and self.range_sigma_m is None
        kept, n = self.kept, self.bursts.rows
        regions: dict[int, NDArray[Any]] = {}  # read once a region is needed
        out = []
        for h, rows in self._groups(window):
            distances = window["d"][rows]
            if kept is not None:
                r = int(self.owner is not None and self.owner[h])
                if r not in regions:
                    regions[r] = kept.read(r * n + lo, r * n + lo + window.size)
                fixes = self._kept_fixes(regions[r][rows])
            else:
                fixes = self._solve(h, distances, self.method)
            if link:
                model = self.models[h]
                covariance = link_covariances(fixes, model.correct(distances), self.beacons, model)
                fixes = dataclasses.replace(fixes, covariance_xy_m2=covariance)
            out.append((rows, dataclasses.replace(fixes, noise=())))
        return out

    def _kept_fixes(self, records: NDArray[Any]) -> Fixes:
        """Fixes from records of :attr:`kept`."""
        return Fixes(
            positions_map_m=np.ascontiguousarray(records["p"]),
            covariance_xy_m2=np.ascontiguousarray(records["c"]),
            sigma_z_m=np.ascontiguousarray(records["sz"]),
            range_sigma_m=np.ascontiguousarray(records["rs"]),
            hdop=np.ascontiguousarray(records["hdop"]),
            residual_rms_m=np.ascontiguousarray(records["res"]),
            error_eq4_m=np.ascontiguousarray(records["e4"]),
            used=np.ascontiguousarray(records["used"]),
            status=np.ascontiguousarray(records["s"]),
            reason=np.ascontiguousarray(records["r"]),
            beacon_addresses=self.beacons.addresses.copy(),
            method=parse_choice(LocateMethod, self.method, "method").value,
            dims=self.dims,
        )

    def _final(self, window: NDArray[Any], lo: int) -> Fixes | None:
        """The window's fixes (of the :attr:`active` hedgehogs only, if set) as
        :func:`~omnical.ips.solve.locate.locate_bursts` gives them, before the off-track
        check; None if it has none (hedgehogs recorded one after another)."""
        parts = self._solved(window, lo)
        if not parts:
            return None
        if self.active is not None:  # the active hedgehogs' rows only
            mine = self.active[np.searchsorted(self.hedges, window["hedge"])]
            index = np.cumsum(mine) - 1
            window = window[mine]
            parts = [(index[rows], part) for rows, part in parts]
        merged = MergedFixes(window.size, len(self.beacons))
        for rows, part in parts:
            merged.add(rows, part)
        fixes = merged.result()
        reason = fixes.reason.copy()
        reason[window["unknown"]] |= np.uint16(FixReason.UNKNOWN_BEACON)
        reason[window["invalid"]] |= np.uint16(FixReason.INVALID_DISTANCE)
        return dataclasses.replace(
            fixes,
            reason=reason,
            t_ns=window["t"].copy(),
            address_hedge=window["hedge"].copy(),
            noise=(),
        )

    def fixes(self) -> Iterator[Fixes]:
        """The final fixes, in order, a part at a time (:meth:`learn` first, if not done)."""
        self.learn()
        if self.finished is not None:
            yield from self._interleaved(*self.finished)
            return
        assert self.usable is not None  # counted by learn()
        track = _Track(self.hedges, self.usable)
        lo = 0
        for window in self.bursts.windows(self.window):
            done = track.push(self._final(window, lo), last=False)
            lo += window.size
            if done is not None:
                yield done
        done = track.push(None, last=True)
        if self.kept is not None:
            self.kept.close()
        if done is not None:
            yield done

    def _interleaved(self, mine: Spill, theirs: Spill) -> Iterator[Fixes]:
        """The final fixes of two processes (:meth:`_finish`: the :attr:`owner`'s in
        ``theirs``), a window at a time in order."""
        assert self.owner is not None
        taken = [0, 0]
        for window in self.bursts.windows(self.window):
            owned = self.owner[np.searchsorted(self.hedges, window["hedge"])]
            block: NDArray[Any] = np.empty(window.size, dtype=mine.dtype)
            for r, (spill, rows) in enumerate(((mine, ~owned), (theirs, owned))):
                count = int(np.count_nonzero(rows))
                block[rows] = spill.read(taken[r], taken[r] + count)
                taken[r] += count
            fixes = self._kept_fixes(block)
            yield dataclasses.replace(
                fixes, t_ns=window["t"].copy(), address_hedge=window["hedge"].copy()
            )
        mine.close()
        theirs.close()


class _Track:
    """The off-track check (:func:`~omnical.ips.solve.locate.off_track`) across windows.

    A fix is decided once every fix within :data:`TRACK_SPAN_NS` after it has been solved;
    its neighbours before it are the last :data:`TRACK_NEIGHBOURS` usable fixes of its
    hedgehog already handed over. A hedgehog with fewer than ``2k + 1`` usable fixes in the
    whole run (``usable``, counted by the learning's last pass) is not checked (the whole-run
    rule).
    """

    def __init__(self, hedges: NDArray[np.int64], usable: NDArray[np.int64]) -> None:
        self.hedges = hedges
        self.total = usable
        self.seen = np.zeros(hedges.size, dtype=np.int64)
        self.context: dict[int, tuple[NDArray[np.float64], NDArray[np.int64]]] = {}
        self.pending = _Pending()

    def push(self, fixes: Fixes | None, *, last: bool) -> Fixes | None:
        """Add a window's fixes; return those now decided (None if none)."""
        if fixes is not None and len(fixes):
            self.pending.fixes.append(fixes)
        pending = self.pending.join()
        if pending is None:
            return None
        assert pending.t_ns is not None and pending.address_hedge is not None
        t, hedge = pending.t_ns, pending.address_hedge
        index = np.searchsorted(self.hedges, hedge)
        usable = (pending.status <= FixStatus.DEGRADED) & np.all(
            np.isfinite(pending.positions_map_m[:, :2]), axis=1
        )
        if last:
            ready = t.size
            self.seen += np.bincount(index[usable], minlength=self.hedges.size)
            total = self.seen
        else:
            ready = int(np.searchsorted(t, int(t[-1]) - 2 * TRACK_SPAN_NS, side="left"))
            total = self.total
        if ready == 0:
            return None
        k = TRACK_NEIGHBOURS
        reason, status = pending.reason[:ready].copy(), pending.status[:ready].copy()
        for h in np.unique(index[:ready]).tolist():
            mine = np.flatnonzero(index == h)
            if total[h] >= 2 * k + 1:
                xy_c, t_c = self.context.get(h, (np.zeros((0, 2)), np.zeros(0, np.int64)))
                c = t_c.size
                xy = np.concatenate([xy_c, pending.positions_map_m[mine, :2]])
                covariance = np.concatenate(
                    [np.full((c, 2, 2), np.nan), pending.covariance_xy_m2[mine]]
                )
                status_h = np.concatenate([np.zeros(c, dtype=np.uint8), pending.status[mine]])
                off = off_track(xy, covariance, status_h, np.concatenate([t_c, t[mine]]),
                                 whole=False)[c:]  # fmt: skip
                rows = mine[off & (mine < ready)]
                reason[rows] |= np.uint16(FixReason.OFF_TRACK)
                status[rows[status[rows] == FixStatus.OK]] = FixStatus.DEGRADED
            done = mine[(mine < ready) & usable[mine]]
            if done.size:
                self._remember(h, pending, done, k)
        if not last:
            self.seen += np.bincount(index[:ready][usable[:ready]], minlength=self.hedges.size)
        out = dataclasses.replace(_take(pending, slice(0, ready)), reason=reason, status=status)
        rest = _take(pending, slice(ready, None))
        self.pending.fixes = [rest] if len(rest) else []
        return out

    def _remember(self, h: int, pending: Fixes, done: NDArray[np.intp], k: int) -> None:
        """Keep the last k usable fixes of hedgehog h handed over (in time order)."""
        assert pending.t_ns is not None
        xy_c, t_c = self.context.get(h, (np.zeros((0, 2)), np.zeros(0, np.int64)))
        xy = np.concatenate([xy_c, pending.positions_map_m[done, :2]])
        t = np.concatenate([t_c, pending.t_ns[done]])
        order = np.argsort(t, kind="stable")[-k:]
        self.context[h] = (xy[order], t[order])
