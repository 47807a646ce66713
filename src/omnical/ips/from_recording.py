"""Multilateration of a whole recording: beacon map, hedgehog height, fixes, CSV.

Works from the Marvelmind topics alone (``/beacon_raw_distance``, ``/beacons_pos_a``,
``/hedge_pos_ang``), as real recordings have nothing else.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from omnical.errors import ConfigError, RecordingError
from omnical.ips.beacons import (
    MAX_HEDGE_Z_M,
    BeaconMap,
    beacon_map_from_rows,
    default_beacon_map,
)
from omnical.ips.solve._fit import SolverOptions
from omnical.ips.solve.fixes import Fixes, FixReason, FixStatus
from omnical.ips.solve.locate import Method, group_ranges, locate_bursts
from omnical.recording.recording import Recording
from omnical.recording.topics import BEACON_RAW_DISTANCE, BEACONS_POS_A, HEDGE_POS_ANG

__all__ = [
    "FIXES_CSV_HEADER",
    "beacon_map_of",
    "hedge_height_of",
    "locate",
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
    if recording.has(BEACONS_POS_A) and len(recording.topic(BEACONS_POS_A)):
        b = recording.topic(BEACONS_POS_A)
        return beacon_map_from_rows(b["address"], b["x_m"], b["y_m"], b["z_m"], t_ns=b.t_ns)
    return default_beacon_map()


def hedge_height_of(recording: Recording, beacons: BeaconMap, address: int) -> float | None:
    """Known hedgehog height: from the map, else the median z of the vendor's valid fixes."""
    z = beacons.hedge_height_m(address)
    if z is not None:
        return z
    if recording.has(HEDGE_POS_ANG):
        pos = recording.topic(HEDGE_POS_ANG)
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

    The height is ``hedge_z_m``; else the map's; else the median z of the vendor's valid
    positions; else the beacons' plane if coplanar (:data:`COPLANAR_TOLERANCE_M`); else from
    3D fixes. What was decided for the user is in :attr:`Fixes.notes`. The range noise is
    learned unless ``self_calibrate`` is False
    (:func:`~omnical.ips.solve.locate.solve_self_calibrated`).

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
    if not recording.has(BEACON_RAW_DISTANCE) or not len(recording.topic(BEACON_RAW_DISTANCE)):
        raise no_ranges_error()
    bmap = beacon_map_of(recording, beacons)
    d = recording.topic(BEACON_RAW_DISTANCE)
    heard = np.unique(d["address_beacon"])
    hedges = np.unique(d["address_hedge"])
    known = hedge_height_of(recording, bmap, int(hedges[0])) if hedges.size else None
    z, notes = plan_height(bmap, heard, hedges, hedge_z_m if hedge_z_m is not None else known)
    # Held only until the fixes are grouped: freed before solving if the caller let go.
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


def check_locate_options(hedge_z_m: float | None, range_sigma_m: float | None) -> None:
    """Raise :class:`ConfigError` for a height or σ :func:`locate` does not take."""
    if hedge_z_m is not None and not (math.isfinite(hedge_z_m) and abs(hedge_z_m) <= MAX_HEDGE_Z_M):
        msg = (
            f"--hedge-z {hedge_z_m}: the hedgehog's height must be finite, "
            f"within ±{MAX_HEDGE_Z_M:g} m"
        )
        raise ConfigError(msg)
    if range_sigma_m is not None and not (
        math.isfinite(range_sigma_m) and 0.0 < range_sigma_m <= 10.0
    ):
        msg = f"--sigma-m {range_sigma_m}: the range noise σ must be positive, at most 10 m"
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
    counts = np.bincount(fixes.status, minlength=max(s.value for s in FixStatus) + 1)
    total = len(fixes)
    n = max(total, 1)
    parts = [f"{s.name.lower()} {counts[s]} ({100.0 * counts[s] / n:.1f} %)" for s in FixStatus]
    usable = int(counts[: FixStatus.DEGRADED + 1].sum())
    return f"{total} fixes " + ", ".join(parts), (usable / total if total else 0.0)


def write_fixes_csv(fixes: Fixes, path: Path) -> Path:
    """One row per fix: :data:`FIXES_CSV_HEADER`.

    ``beacons_used``: addresses joined by ``;``; ``status``: ok, degraded, rejected or
    degenerate; ``reason``: :class:`FixReason` flags, lower case, joined by ``;`` (or empty).
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    n = len(fixes)
    t_ns = fixes.t_ns if fixes.t_ns is not None else np.zeros(n, dtype=np.int64)
    with path.open("w", encoding="utf-8") as out:
        out.write(FIXES_CSV_HEADER + "\n")
        out.writelines(_csv_chunks(fixes, t_ns, 0, n))
    return path


_CSV_CHUNK = 16_384
"""Rows formatted at a time by :func:`write_fixes_csv`."""


def _csv_chunks(fixes: Fixes, t_ns: np.ndarray, lo: int, hi: int) -> Iterator[str]:
    """The CSV lines of fixes ``lo:hi``, :data:`_CSV_CHUNK` rows at a time."""
    for start in range(lo, hi, _CSV_CHUNK):
        yield _csv_rows(fixes, t_ns, start, min(start + _CSV_CHUNK, hi))


def _csv_rows(fixes: Fixes, t_ns: np.ndarray, lo: int, hi: int) -> str:
    """The CSV lines of fixes ``lo:hi``, each ending in a newline."""
    n = hi - lo
    p, c = fixes.positions_map_m[lo:hi], fixes.covariance_xy_m2[lo:hi]
    # The text of each distinct beacon set, status and reason once, not once a row.
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
    # the fields row after row (same text as str.format per row).
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
