"""Indoor positioning: beacon map, burst grouping of raw distances, multilateration."""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
    from omnical.ips.beacons import (
        BeaconMap,
        beacon_map_from_rows,
        default_beacon_map,
        load_beacon_map,
        save_beacon_map,
    )
    from omnical.ips.bursts import (
        Bursts,
        burst_starts,
        group_bursts,
    )
    from omnical.ips.solve import (
        CHI2_2DOF_95,
        Ellipses,
        Fixes,
        FixReason,
        FixStatus,
        Method,
        SolverOptions,
        ellipses_from_covariances,
        locate_recording,
        mahalanobis_sq,
        solve_fixes,
    )

_EXPORTS: dict[str, str] = {
    "BeaconMap": "omnical.ips.beacons",
    "Bursts": "omnical.ips.bursts",
    "CHI2_2DOF_95": "omnical.ips.solve",
    "Ellipses": "omnical.ips.solve",
    "FixReason": "omnical.ips.solve",
    "FixStatus": "omnical.ips.solve",
    "Fixes": "omnical.ips.solve",
    "Method": "omnical.ips.solve",
    "SolverOptions": "omnical.ips.solve",
    "beacon_map_from_rows": "omnical.ips.beacons",
    "burst_starts": "omnical.ips.bursts",
    "default_beacon_map": "omnical.ips.beacons",
    "ellipses_from_covariances": "omnical.ips.solve",
    "group_bursts": "omnical.ips.bursts",
    "load_beacon_map": "omnical.ips.beacons",
    "locate_recording": "omnical.ips.solve",
    "mahalanobis_sq": "omnical.ips.solve",
    "save_beacon_map": "omnical.ips.beacons",
    "solve_fixes": "omnical.ips.solve",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

__all__ = [
    "CHI2_2DOF_95",
    "BeaconMap",
    "Bursts",
    "Ellipses",
    "FixReason",
    "FixStatus",
    "Fixes",
    "Method",
    "SolverOptions",
    "beacon_map_from_rows",
    "burst_starts",
    "default_beacon_map",
    "ellipses_from_covariances",
    "group_bursts",
    "load_beacon_map",
    "locate_recording",
    "mahalanobis_sq",
    "save_beacon_map",
    "solve_fixes",
]


__getattr__ = lazy_getattr(__name__, _EXPORTS)
