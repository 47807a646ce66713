"""Indoor positioning: beacon map, burst grouping of raw distances, multilateration."""

from omnical.ips.beacons import (
    BeaconMap,
    beacon_map_from_rows,
    default_beacon_map,
    load_beacon_map,
    save_beacon_map,
)
from omnical.ips.bursts import Bursts, burst_starts, group_bursts
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
