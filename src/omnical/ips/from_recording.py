"""Multilateration of a whole recording: beacon map, hedgehog height, fixes, CSV.

Works from the Marvelmind topics alone (``/beacon_raw_distance``, ``/beacons_pos_a``,
``/hedge_pos_ang``), as real recordings have nothing else.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType

import numpy as np

from omnical.errors import ConfigError, RecordingError
from omnical.ips.beacons import BeaconMap, beacon_map_from_rows, default_beacon_map
from omnical.ips.forked import collect, fork, reap
from omnical.ips.solve import Fixes, FixReason, FixStatus, Method, SolverOptions
from omnical.ips.solve.locate import SEQUENTIAL_NOTE, group_ranges, locate_bursts
from omnical.ips.solve.noise_model import NoiseModel
from omnical.ips.windowed import (
    FIX_WINDOW,
    LEARNING_FIXES,
    MESSAGE_WINDOW,
    RangeRun,
    Spill,
    WindowedLocate,
    sequential_from_counts,
)
from omnical.recording.recording import Recording

__all__ = [
    "FIXES_CSV_HEADER",
    "PARALLEL_CSV_ROWS",
    "FixesCsv",
    "LocatedRun",
    "StatusTally",
    "beacon_map_of",
    "hedge_height_of",
    "locate",
    "locate_run",
    "reason_text",
    "status_summary",
    "write_fixes_csv",
]

FIXES_CSV_HEADER = (
    "t_ns,x_m,y_m,z_m,cov_xx,cov_xy,cov_yy,hdop,residual_rms_m,paper_error,beacons_used,status,"
    "reason"
)
_FIX_UNAVAILABLE = 0x01


def beacon_map_of(recording: Recording, beacons: BeaconMap | None = None) -> BeaconMap:
    """The map to use: the one given, else the recording's ``/beacons_pos_a``, else seed 000 Table 3."""
    if beacons is not None:
        return beacons
    if recording.has("/beacons_pos_a") and len(recording.topic("/beacons_pos_a")):
        b = recording.topic("/beacons_pos_a")
        return beacon_map_from_rows(b["address"], b["x_m"], b["y_m"], b["z_m"], t_ns=b.t_ns)
    return default_beacon_map()


def hedge_height_of(recording: Recording, beacons: BeaconMap, address: int) -> float | None:
    """Known hedgehog height: from the map, else the median z of the vendor's valid fixes."""
    z = beacons.hedge_height_m(address)
    if z is not None:
        return z
    if recording.has("/hedge_pos_ang"):
        pos = recording.topic("/hedge_pos_ang")
        ok = (pos["flags"] & _FIX_UNAVAILABLE) == 0
        if np.any(ok):
            return float(np.median(pos["z_m"][ok]))
    return None


COPLANAR_TOLERANCE_M = 0.10
"""Beacons whose heights span less than this are treated as coplanar, metres."""


def locate(
    recording: Recording,
    *,
    beacons: BeaconMap | None = None,
    method: Method = "robust",
    hedge_z_m: float | None = None,
    range_sigma_m: float | None = None,
    self_calibrate: bool = True,
    options: SolverOptions | None = None,
) -> tuple[Fixes, BeaconMap]:
    """Multilaterate every distance burst of a recording (2D at the hedgehog height).

    The hedgehog height is, in this order: ``hedge_z_m``; the map's; the median z of the
    vendor's valid positions; else, with coplanar beacons (heights within
    :data:`COPLANAR_TOLERANCE_M`), the beacons' plane; else estimated from the ranges by 3D
    fixes. What was decided on the user's behalf is in :attr:`Fixes.notes`. The range noise
    is learned from the recording unless ``self_calibrate`` is False (see
    :func:`omnical.ips.solve.locate_recording`).

    Args:
        recording: With ``/beacon_raw_distance`` (``/beacons_pos_a`` and ``/hedge_pos_ang``
            used when present).
        beacons: The beacon map; default the recording's, else seed 000 Table 3.
        method: ``robust``, ``lsq`` or ``grid``.
        hedge_z_m: The hedgehog height, metres.
        range_sigma_m: Fix the range noise σ, metres, instead of learning it.
        self_calibrate: Learn σ, bias and scale per link from the recording.
        options: Numerical options of the solver (default :class:`SolverOptions()`).

    Raises:
        ConfigError: ``hedge_z_m`` is not a finite height within 100 m, or ``range_sigma_m``
            is not a positive finite σ of at most 10 m.
        RecordingError: the recording has no ``/beacon_raw_distance``, or none of its beacon
            addresses is in the beacon map.
    """
    check_locate_options(hedge_z_m, range_sigma_m)
    if not recording.has("/beacon_raw_distance") or not len(
        recording.topic("/beacon_raw_distance")
    ):
        raise no_ranges_error()
    bmap = beacon_map_of(recording, beacons)
    d = recording.topic("/beacon_raw_distance")
    heard = np.unique(d["address_beacon"])
    hedges = np.unique(d["address_hedge"])
    known = hedge_height_of(recording, bmap, int(hedges[0])) if hedges.size else None
    z, notes = plan_height(bmap, heard, hedges, hedge_z_m if hedge_z_m is not None else known)
    # The raw-distance columns are held here only until the fixes are grouped (the caller
    # may have let go of the recording: then they are freed before the solving starts).
    ranges = [d.t_ns, d["address_hedge"], d["address_beacon"], d["distance_m"]]
    del d, recording
    fixes = _locate_ranges(ranges, bmap, z, notes, method, range_sigma_m, self_calibrate, options)
    return fixes, bmap


def _locate_ranges(
    ranges: list[np.ndarray],
    bmap: BeaconMap,
    z: float | None,
    notes: list[str],
    method: Method,
    range_sigma_m: float | None,
    self_calibrate: bool,
    options: SolverOptions | None,
) -> Fixes:
    """The fixes of :func:`locate` from its raw-distance columns (``ranges``: times, hedgehog
    and beacon addresses, distances; emptied once grouped) and :func:`plan_height`'s result."""

    def solve(
        height: float | None, dims: int = 2, calibrate: bool = self_calibrate, last: bool = True
    ) -> Fixes:
        t_ns, hedge, beacon, distance_m = ranges
        bursts, grouped = group_ranges(t_ns, hedge, beacon, distance_m, bmap, dims=dims)
        del t_ns, hedge, beacon, distance_m
        if last:
            ranges.clear()
        return locate_bursts(
            bursts,
            bmap,
            notes=grouped,
            method=method if dims == 2 else "robust",
            dims=dims,
            hedge_z_m=height,
            range_sigma_m=range_sigma_m,
            options=options,
            self_calibrate=calibrate,
        )

    if z is None and notes:  # not coplanar: the height from 3D fixes
        z = height_from_3d(solve(None, dims=3, calibrate=False, last=False), notes)
    fixes = solve(z)
    return dataclasses.replace(fixes, notes=(*notes, *fixes.notes))


@dataclasses.dataclass(frozen=True)
class LocatedRun:
    """:func:`locate_run`'s result: the fixes of a run, handed over a part at a time.

    Attributes:
        beacons: The map used.
        notes: As :attr:`Fixes.notes`.
        noise: As :attr:`Fixes.noise` (known before the fixes come).
        parts: The fixes in order, a part at a time (once through).
        windowed: Solved a window at a time (else whole, at once: sequential ranges, or a
            height estimated from 3D fixes).
    """

    beacons: BeaconMap
    notes: tuple[str, ...]
    noise: tuple[NoiseModel, ...]
    parts: Iterator[Fixes]
    windowed: bool


def locate_run(
    run: RangeRun,
    *,
    beacons: BeaconMap | None = None,
    method: Method = "robust",
    hedge_z_m: float | None = None,
    range_sigma_m: float | None = None,
    self_calibrate: bool = True,
    options: SolverOptions | None = None,
    window: int = FIX_WINDOW,
    message_window: int = MESSAGE_WINDOW,
    learning_fixes: int = LEARNING_FIXES,
    workers: int = 1,
) -> LocatedRun:
    """:func:`locate` of a recording read a part at a time into ``run``, in bounded memory.

    The same fixes solved a window at a time (:mod:`omnical.ips.windowed`, ``window`` fixes
    per hedgehog); the noise models are learnt here from at most ``learning_fixes`` usable
    fixes per hedgehog, evenly spread (by default :func:`locate`'s own sample, so its fixes
    bit for bit but for the solver's batch effects, see :mod:`omnical.ips.windowed`), and the
    fixes are solved as :attr:`LocatedRun.parts` is iterated. Sequential ranges and a height to estimate from 3D
    fixes are solved whole, as :func:`locate` does. ``workers``: 2 learns the models of many
    hedgehogs and finishes their fixes in two processes
    (:meth:`~omnical.ips.windowed.WindowedLocate.learn`). Other arguments and errors as
    :func:`locate`.
    """
    check_locate_options(hedge_z_m, range_sigma_m)
    if run.raw.rows == 0:
        raise no_ranges_error()
    bmap = run.beacon_map(beacons)
    hedges = run.hedges
    known = run.hedge_height(bmap, int(hedges[0])) if hedges.size else None
    run.heights.close()
    z, notes = plan_height(bmap, run.heard, hedges, hedge_z_m if hedge_z_m is not None else known)
    if not (z is None and notes):
        bursts, n_valid = run.group(bmap, window=message_window)
        if sequential_from_counts(n_valid):
            bursts.close()
            bursts, age_ns = run.sliding(bmap, window=message_window)
            notes.append(SEQUENTIAL_NOTE.format(age_ms=age_ns / 1e6))
        run.raw.close()
        engine = WindowedLocate(
            bursts,
            bmap,
            run.hedges,
            method=method,
            hedge_z_m=z,
            range_sigma_m=range_sigma_m,
            options=options,
            self_calibrate=self_calibrate,
            window=window,
            learning_fixes=learning_fixes,
            workers=workers,
        )
        noise = engine.learn()
        return LocatedRun(bmap, tuple(notes), noise, engine.fixes(), windowed=True)
    raw = run.raw.read(0, run.raw.rows)
    run.raw.close()
    ranges = [raw["t"].copy(), raw["hedge"].copy(), raw["beacon"].copy(), raw["d"].copy()]
    del raw
    fixes = _locate_ranges(ranges, bmap, z, notes, method, range_sigma_m, self_calibrate, options)
    return LocatedRun(bmap, fixes.notes, fixes.noise, iter([fixes]), windowed=False)


def check_locate_options(hedge_z_m: float | None, range_sigma_m: float | None) -> None:
    """Raise :class:`ConfigError` for a height or σ :func:`locate` does not take."""
    if hedge_z_m is not None and not (math.isfinite(hedge_z_m) and abs(hedge_z_m) <= 100.0):
        msg = f"hedgehog height {hedge_z_m} m: expected a finite height within ±100 m"
        raise ConfigError(msg)
    if range_sigma_m is not None and not (
        math.isfinite(range_sigma_m) and 0.0 < range_sigma_m <= 10.0
    ):
        msg = f"range noise σ {range_sigma_m} m: expected a positive σ of at most 10 m"
        raise ConfigError(msg)


def no_ranges_error() -> RecordingError:
    """What :func:`locate` raises for a recording without raw distances."""
    return RecordingError(
        "recording has no /beacon_raw_distance messages: nothing to multilaterate"
    )


def plan_height(
    bmap: BeaconMap, heard: np.ndarray, hedges: np.ndarray, known_z_m: float | None
) -> tuple[float | None, list[str]]:
    """The hedgehog height :func:`locate` solves at, and the notes on how it was chosen.

    ``heard`` and ``hedges`` are the sorted distinct beacon and hedgehog addresses of the
    ranges; ``known_z_m`` the height given, else :func:`hedge_height_of` the first hedgehog.
    A height of None with notes: not coplanar, the height is to be estimated from 3D fixes
    (the last note is then replaced by :func:`height_from_3d`).

    Raises:
        RecordingError: none of the beacons heard is in the map.
    """
    mapped = np.asarray(bmap.addresses)
    if not np.any(np.isin(heard, mapped)):
        msg = (
            f"none of the beacons in /beacon_raw_distance ({_addresses(heard)}) is in the beacon "
            f"map ({_addresses(mapped)}): wrong map file?"
        )
        raise RecordingError(msg)
    z = known_z_m
    notes: list[str] = []
    if z is None and hedges.size and not np.all(np.isin(hedges, bmap.hedge_addresses)):
        z = _unknown_height(bmap, heard, notes)
    return z, notes


def _unknown_height(bmap: BeaconMap, heard: np.ndarray, notes: list[str]) -> float | None:
    """The beacons' plane if they are coplanar (with a note); None (and a note) otherwise."""
    index = bmap.index_of(heard)
    z = bmap.positions_m[index[index >= 0], 2]
    lo, hi = float(np.min(z)), float(np.max(z))
    if hi - lo <= COPLANAR_TOLERANCE_M:
        plane = float(np.mean(z))
        notes.append(
            "the hedgehog height is not known (no --hedge-z, no hedge height in the beacon map, "
            f"no vendor positions) and the beacons are coplanar (z {lo:.3f}–{hi:.3f} m): solved "
            f"in the beacons' plane, z = {plane:.3f} m (a hedgehog Δz off that plane adds about "
            "Δz²/2r to each range, which the self-calibrated range bias absorbs)"
        )
        return plane
    notes.append("the hedgehog height is not known: estimating it from 3D fixes")
    return None


def height_from_3d(fixes3: Fixes, notes: list[str]) -> float | None:
    """The height from 3D fixes (their median z), the last of ``notes`` saying how it went."""
    good = (fixes3.status == FixStatus.OK) & np.isfinite(fixes3.positions_map_m[:, 2])
    if not np.any(good):
        notes[-1] = (
            "the hedgehog height is not known and could not be estimated from the ranges "
            "(no consistent 3D fix): give --hedge-z"
        )
        return None
    z = float(np.median(fixes3.positions_map_m[good, 2]))
    spread = float(np.subtract(*np.percentile(fixes3.positions_map_m[good, 2], [75, 25])))
    notes[-1] = (
        f"the hedgehog height is not known: estimated from {int(good.sum())} 3D fixes as "
        f"z = {z:.3f} m (interquartile range {spread:.3f} m), then solved in 2D at that height"
    )
    return z


def _addresses(values: np.ndarray) -> str:
    shown = ", ".join(str(int(v)) for v in values[:8])
    return shown + (f", … ({len(values)} in all)" if len(values) > 8 else "")


def reason_text(reason: int) -> str:
    """The names of the :class:`FixReason` flags set in ``reason``, lower case, joined by ``;``."""
    return ";".join(
        (flag.name or "").lower() for flag in FixReason if flag.value and reason & flag.value
    )


def status_summary(fixes: Fixes) -> tuple[str, float]:
    """One line with the fraction of fixes in each status, and the usable (ok or degraded) fraction."""
    tally = StatusTally()
    tally.add(fixes)
    return tally.summary()


class StatusTally:
    """The fixes of each status, counted as they come, for :func:`status_summary`."""

    def __init__(self) -> None:
        self.counts = np.zeros(max(s.value for s in FixStatus) + 1, dtype=np.int64)

    def add(self, fixes: Fixes) -> None:
        """Count ``fixes``."""
        self.counts += np.bincount(fixes.status, minlength=self.counts.size)[: self.counts.size]

    def summary(self) -> tuple[str, float]:
        """As :func:`status_summary` of every fix added."""
        total = int(self.counts.sum())
        n = max(total, 1)
        parts = [
            f"{s.name.lower()} {self.counts[s]} ({100.0 * self.counts[s] / n:.1f} %)"
            for s in FixStatus
        ]
        usable = int(self.counts[: FixStatus.DEGRADED + 1].sum())
        return f"{total} fixes " + ", ".join(parts), (usable / total if total else 0.0)


def write_fixes_csv(fixes: Fixes, path: Path) -> Path:
    """One row per fix: :data:`FIXES_CSV_HEADER`.

    ``beacons_used`` lists the beacon addresses joined by ``;``; ``status`` is ok, degraded,
    rejected or degenerate; ``reason`` the :class:`~omnical.ips.solve.FixReason` flags, lower
    case, joined by ``;`` (empty when none).
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    with FixesCsv(path) as out:
        out.write(fixes)
    return path


class FixesCsv:
    """A fixes CSV (:func:`write_fixes_csv`) written a part of the fixes at a time, in order.

    Use as a context manager: the header is written on entry, each :meth:`write` appends the
    rows of some fixes, the same text as :func:`write_fixes_csv` of them all. ``workers`` 2:
    the second half of each block of :data:`_CSV_BLOCK` rows (of :data:`PARALLEL_CSV_ROWS`
    rows or more) is formatted in a forked process (:mod:`omnical.ips.forked`) while this one
    formats the first.
    """

    def __init__(self, path: Path, *, workers: int = 1) -> None:
        self.path = path
        self.workers = workers
        self._out = path.open("w", encoding="utf-8")
        self._out.write(FIXES_CSV_HEADER + "\n")

    def write(self, fixes: Fixes) -> None:
        """Append the rows of ``fixes``."""
        n = len(fixes)
        t_ns = fixes.t_ns if fixes.t_ns is not None else np.zeros(n, dtype=np.int64)
        for lo in range(0, n, _CSV_BLOCK):
            self._write_block(fixes, t_ns, lo, min(lo + _CSV_BLOCK, n))

    def _write_block(self, fixes: Fixes, t_ns: np.ndarray, lo: int, hi: int) -> None:
        """Append the rows ``lo:hi``: with two workers, their second half formatted by a
        forked process meanwhile (here, if it fails)."""
        middle = (lo + hi) // 2 if self.workers > 1 and hi - lo >= PARALLEL_CSV_ROWS else hi
        if middle == hi:
            self._out.writelines(_csv_chunks(fixes, t_ns, lo, hi))
            return
        child = fork(functools.partial(_csv_spill, fixes, t_ns, middle, hi), shared=(Spill,))
        try:
            self._out.writelines(_csv_chunks(fixes, t_ns, lo, middle))
            text = collect(child)
        finally:
            reap(child)
        if not isinstance(text, Spill):  # the child failed: formatted here
            self._out.writelines(_csv_chunks(fixes, t_ns, middle, hi))
            return
        try:
            self._out.flush()
            for window in text.windows(_CSV_SPILL_BYTES):
                self._out.buffer.write(window.tobytes())
        finally:
            text.close()

    def close(self) -> None:
        """Close the file."""
        self._out.close()

    def __enter__(self) -> FixesCsv:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


_CSV_CHUNK = 16_384
"""Rows formatted at a time by :func:`write_fixes_csv` (the text of a whole run held at once
was several times the fixes themselves)."""
_CSV_BLOCK = 131_072
"""Rows of which a forked process formats half (:class:`FixesCsv`), ~8 MB of text it writes
to a temporary file for this process to copy."""
PARALLEL_CSV_ROWS = 16_384
"""Rows from which :class:`FixesCsv` with two workers forks (start-up: ~10 ms; formatting
~1.7 µs a row)."""


def _csv_chunks(fixes: Fixes, t_ns: np.ndarray, lo: int, hi: int) -> Iterator[str]:
    """The CSV lines of fixes ``lo:hi``, :data:`_CSV_CHUNK` rows at a time."""
    for start in range(lo, hi, _CSV_CHUNK):
        yield _csv_rows(fixes, t_ns, start, min(start + _CSV_CHUNK, hi))


def _csv_spill(fixes: Fixes, t_ns: np.ndarray, lo: int, hi: int) -> Spill:
    """The CSV lines of fixes ``lo:hi``, UTF-8 in a temporary file: what a forked process
    hands back (as its open file; its text sent through the socket had waited for this
    process to read it, 0.03–0.08 s a block)."""
    spill = Spill(np.dtype(np.uint8))
    for text in _csv_chunks(fixes, t_ns, lo, hi):
        spill.append(np.frombuffer(text.encode(), dtype=np.uint8))
    return spill


_CSV_SPILL_BYTES = 1 << 22
"""Bytes of a forked process's CSV lines copied at a time."""


def _csv_rows(fixes: Fixes, t_ns: np.ndarray, lo: int, hi: int) -> str:
    """The CSV lines of fixes ``lo:hi``, each ending in a newline."""
    n = hi - lo
    p, c = fixes.positions_map_m[lo:hi], fixes.covariance_xy_m2[lo:hi]
    # The text of each distinct beacon set, status and reason once, not once a row (a long run
    # has a handful of each and 10⁵ rows).
    used = np.asarray(fixes.used[lo:hi], dtype=bool).reshape(n, -1)
    packed = np.ascontiguousarray(np.packbits(used, axis=1))
    keys = packed.view(np.dtype((np.void, packed.shape[1]))).reshape(n)
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    used_text = np.array(
        [";".join(str(a) for a in fixes.beacon_addresses[used[i]]) for i in first], dtype=object
    )[inverse.reshape(n)].tolist()
    status_names = {s.value: s.name.lower() for s in FixStatus}
    status_text = [status_names[int(v)] for v in range(max(status_names) + 1)]
    statuses = np.array(status_text, dtype=object)[fixes.status[lo:hi]].tolist()
    distinct, reason_index = np.unique(fixes.reason[lo:hi], return_inverse=True)
    reasons = np.array([reason_text(int(r)) for r in distinct], dtype=object)[
        reason_index.reshape(n)
    ].tolist()
    numbers = np.column_stack(
        [
            p,
            c.reshape(-1, 4)[:, [0, 1, 3]],
            fixes.hdop[lo:hi],
            fixes.residual_rms_m[lo:hi],
            fixes.error_eq4_m[lo:hi],
        ]
    )
    # The whole chunk in one printf-style formatting: the row template repeated, applied to
    # the fields row after row. Same text as str.format per row ("%.4f" and "{:.4f}" are one
    # C routine; NaN and infinities write "nan", "inf", "-inf" either way) without the
    # Python loop over rows: 0.7× the time of a str.format call per row.
    fields = itertools.chain.from_iterable(
        zip(
            t_ns[lo:hi].tolist(),
            *(numbers[:, k].tolist() for k in range(numbers.shape[1])),
            used_text,
            statuses,
            reasons,
            strict=True,
        )
    )
    return (_CSV_ROW * n) % tuple(fields)


_CSV_ROW = "%d,%.4f,%.4f,%.4f,%.6e,%.6e,%.6e,%.4f,%.5f,%.6f,%s,%s,%s\n"
"""One line of :data:`FIXES_CSV_HEADER`: the time, x y z and hdop to 0.1 mm, the covariance
to 7 significant digits, the residual and the paper's error to 1 µm, then the text columns."""
