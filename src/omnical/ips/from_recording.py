"""Multilateration of a whole recording: beacon map, hedgehog height, fixes, CSV.

Works from the Marvelmind topics alone (``/beacon_raw_distance``, ``/beacons_pos_a``,
``/hedge_pos_ang``), as real recordings have nothing else.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from omnical.errors import ConfigError, RecordingError
from omnical.ips.beacons import BeaconMap, beacon_map_from_rows, default_beacon_map
from omnical.ips.solve import Fixes, FixStatus, Method, locate_recording
from omnical.recording.recording import Recording

__all__ = ["FIXES_CSV_HEADER", "beacon_map_of", "hedge_height_of", "locate", "write_fixes_csv"]

FIXES_CSV_HEADER = (
    "t_ns,x_m,y_m,z_m,cov_xx,cov_xy,cov_yy,hdop,residual_rms_m,paper_error,beacons_used,status"
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


def locate(
    recording: Recording,
    *,
    beacons: BeaconMap | None = None,
    method: Method = "robust",
    hedge_z_m: float | None = None,
) -> tuple[Fixes, BeaconMap]:
    """Multilaterate every distance burst of a recording (2D with the hedgehog height known).

    Raises:
        ConfigError: ``hedge_z_m`` is not a finite height within 100 m.
        RecordingError: the recording has no ``/beacon_raw_distance``, or none of its beacon
            addresses is in the beacon map.
    """
    if hedge_z_m is not None and not (math.isfinite(hedge_z_m) and abs(hedge_z_m) <= 100.0):
        msg = f"hedgehog height {hedge_z_m} m: expected a finite height within ±100 m"
        raise ConfigError(msg)
    if not recording.has("/beacon_raw_distance") or not len(
        recording.topic("/beacon_raw_distance")
    ):
        msg = "recording has no /beacon_raw_distance messages: nothing to multilaterate"
        raise RecordingError(msg)
    bmap = beacon_map_of(recording, beacons)
    d = recording.topic("/beacon_raw_distance")
    heard = np.unique(d["address_beacon"])
    mapped = np.asarray(bmap.addresses)
    if not np.any(np.isin(heard, mapped)):
        msg = (
            f"none of the beacons in /beacon_raw_distance ({_addresses(heard)}) is in the beacon "
            f"map ({_addresses(mapped)}): wrong map file?"
        )
        raise RecordingError(msg)
    hedges = np.unique(d["address_hedge"])
    z = hedge_z_m
    if z is None and hedges.size:
        z = hedge_height_of(recording, bmap, int(hedges[0]))
    fixes = locate_recording(
        d.t_ns,
        d["address_hedge"],
        d["address_beacon"],
        d["distance_m"],
        bmap,
        method=method,
        hedge_z_m=z,
    )
    return fixes, bmap


def _addresses(values: np.ndarray) -> str:
    shown = ", ".join(str(int(v)) for v in values[:8])
    return shown + (f", … ({len(values)} in all)" if len(values) > 8 else "")


def write_fixes_csv(fixes: Fixes, path: Path) -> Path:
    """One row per fix: ``t_ns,x_m,y_m,z_m,cov_xx,cov_xy,cov_yy,hdop,residual_rms_m,paper_error,beacons_used,status``.

    ``beacons_used`` lists the beacon addresses joined by ``;``; ``status`` is ok, degraded,
    rejected or degenerate.
    """
    t_ns = fixes.t_ns if fixes.t_ns is not None else np.zeros(len(fixes), dtype=np.int64)
    names = {s.value: s.name.lower() for s in FixStatus}
    lines = [FIXES_CSV_HEADER]
    p, c = fixes.positions_map_m, fixes.covariance_xy_m2
    for i in range(len(fixes)):
        used = ";".join(str(a) for a in fixes.beacon_addresses[fixes.used[i]])
        lines.append(
            f"{int(t_ns[i])},{p[i, 0]:.4f},{p[i, 1]:.4f},{p[i, 2]:.4f},"
            f"{c[i, 0, 0]:.6e},{c[i, 0, 1]:.6e},{c[i, 1, 1]:.6e},{fixes.hdop[i]:.4f},"
            f"{fixes.residual_rms_m[i]:.5f},{fixes.error_eq4_m[i]:.6f},{used},{names[int(fixes.status[i])]}"
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
