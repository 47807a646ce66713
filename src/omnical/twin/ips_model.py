"""Simulated Marvelmind IPS in the non-inverse architecture: what the hedgehog would stream.

:func:`simulate_ips` turns a run's true trajectory into the hedgehog's bursts (position, raw
distances, quality) at :func:`measurement_rate_hz`. The model: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import collections
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike

from omnical.errors import ConfigError
from omnical.estimation.se2 import transform_points
from omnical.twin.ips_messages import (
    F64,
    FLAG_COORDINATES_UNAVAILABLE,
    FLAG_TIMESTAMP_MS,
    I64,
    Bool,
    IpsBeaconPositions,
    IpsDistances,
    IpsMeasurements,
    IpsPositions,
    IpsQuality,
    IpsTruth,
)
from omnical.twin.ips_params import IpsParams
from omnical.twin.ips_vendor import (
    average_fixes,
    jump_filter,
    quality_percent,
    solve_vendor_2d,
)
from omnical.twin.params import TwinEngine

_U32 = 2**32
_VENDOR_MAX_JUMP_M = 0.2

__all__ = [
    "VendorTrack",
    "hedge_positions_map",
    "measured_distances",
    "measurement_rate_hz",
    "select_submap",
    "simulate_ips",
]


def hedge_positions_map(poses_map: ArrayLike, hedge_offset_base_m: ArrayLike) -> F64:
    """Hedgehog positions in the map frame: pose ⊕ offset.

    Args:
        poses_map: (N, 3) x, y (m) and yaw (rad) of base_link in the map frame.
        hedge_offset_base_m: (3,) hedgehog x, y, z in base_link, m (z = height above floor).

    Returns:
        (N, 3) hedgehog x, y, z in the map frame, m.
    """
    poses = np.asarray(poses_map, dtype=np.float64).reshape(-1, 3)
    ox, oy, oz = np.asarray(hedge_offset_base_m, dtype=np.float64).reshape(3)
    return np.column_stack([transform_points(poses, (ox, oy)), np.full(len(poses), oz)])


def measurement_rate_hz(largest_spacing_m: ArrayLike, params: IpsParams) -> F64:
    """Measurement rate of one hedgehog from the largest beacon spacing of its submap.

    Args:
        largest_spacing_m: (...) largest distance between two beacons of the submap, m.
        params: the rate law's knots (the law: docs/DESIGN-NOTES.md).

    Returns:
        (...) rate, Hz.
    """
    spacing = np.asarray(largest_spacing_m, dtype=np.float64)
    knots = np.asarray(params.rate_knots, dtype=np.float64)
    s_k, period_k = knots[:, 0], 1.0 / knots[:, 1]
    period_s = np.interp(spacing, s_k, period_k)
    if len(s_k) > 1:
        slope = (period_k[-1] - period_k[-2]) / (s_k[-1] - s_k[-2])
        period_s = np.where(spacing > s_k[-1], period_k[-1] + slope * (spacing - s_k[-1]), period_s)
    rate = np.maximum(params.rate_min_hz, 1.0 / period_s) / params.hedgehog_count
    return np.asarray(rate, dtype=np.float64)


def select_submap(
    hedge_map_m: ArrayLike,
    beacon_addresses: ArrayLike,
    beacon_positions_m: ArrayLike,
    max_beacons: int,
) -> tuple[I64, F64]:
    """The serving submap: the nearest ``max_beacons`` beacons (all if fewer), by address.

    Args:
        hedge_map_m: (M, 3) hedgehog positions, map frame, m.
        beacon_addresses: (B,) beacon addresses.
        beacon_positions_m: (B, 3) beacon positions, map frame, m.
        max_beacons: submap size limit.

    Returns:
        (M, K) beacon indices sorted by ascending address (K = min(B, max_beacons)), and
        (M,) largest spacing between two beacons of each submap, m (0 for one beacon).
    """
    hedge = np.asarray(hedge_map_m, dtype=np.float64).reshape(-1, 3)
    beacons = np.asarray(beacon_positions_m, dtype=np.float64).reshape(-1, 3)
    addresses = np.asarray(beacon_addresses)
    k = min(len(beacons), max_beacons)
    pair = np.linalg.norm(beacons[:, None, :] - beacons[None, :, :], axis=-1)
    if k == len(beacons):  # every beacon serves everywhere: the same submap for every position
        order = np.argsort(addresses, kind="stable").astype(np.int64)
        every = np.broadcast_to(order, (len(hedge), k)).copy()
        return every, np.full(len(hedge), pair[order[:, None], order[None, :]].max())
    dist = np.linalg.norm(hedge[:, None, :] - beacons[None, :, :], axis=-1)
    nearest = np.argsort(dist, axis=1, kind="stable")[:, :k]
    by_address = np.argsort(addresses[nearest], axis=1, kind="stable")
    sel = np.take_along_axis(nearest, by_address, axis=1).astype(np.int64)
    spacing = pair[sel[:, :, None], sel[:, None, :]].reshape(len(sel), -1).max(axis=1)
    return sel, spacing


def simulate_ips(
    t_s: ArrayLike,
    poses_map: ArrayLike,
    beacon_addresses: ArrayLike,
    beacon_positions_m: ArrayLike,
    params: IpsParams,
    rng: np.random.Generator,
    *,
    engine: TwinEngine = "auto",
) -> IpsMeasurements:
    """Simulate what a Marvelmind NIA system reports while the robot follows a trajectory.

    Args:
        t_s: (N,) strictly increasing trajectory times, s (N ≥ 2).
        poses_map: (N, 3) true x, y (m), yaw (rad) of base_link in the map frame.
        beacon_addresses: (B,) distinct stationary beacon addresses, 1–255.
        beacon_positions_m: (B, 3) stationary beacon positions in the map frame, m.
        params: IPS behaviour.
        rng: source of every random draw (same seed, same output).
        engine: who runs the vendor's solve and track filter (numba kernel or numpy reference,
            :data:`~omnical.twin.params.TwinEngine`); the output is the same bit for bit.

    Returns:
        The streamed messages per topic and the truth of every measurement.

    Raises:
        ConfigError: bad shapes, times, addresses, an NLOS zone naming an unknown beacon, or an
            unknown engine.
    """
    t, poses, addresses, beacons = _check_inputs(
        t_s, poses_map, beacon_addresses, beacon_positions_m, params
    )
    hedge_traj = hedge_positions_map(poses, params.hedge_offset_base_m)
    _, spacing_traj = select_submap(hedge_traj, addresses, beacons, params.max_beacons)
    t_emit = _emission_times(t, measurement_rate_hz(spacing_traj, params), params, rng)

    yaw = np.interp(t_emit, t, np.unwrap(poses[:, 2]))
    poses_emit = np.stack(
        [np.interp(t_emit, t, poses[:, 0]), np.interp(t_emit, t, poses[:, 1]), yaw], axis=1
    )
    hedge = hedge_positions_map(poses_emit, params.hedge_offset_base_m)
    sel, spacing = select_submap(hedge, addresses, beacons, params.max_beacons)
    rate = measurement_rate_hz(spacing, params)
    m, k = sel.shape

    slot_beacons = beacons[sel]
    d_true = np.linalg.norm(hedge[:, None, :] - slot_beacons, axis=-1)
    d_meas, is_outlier = measured_distances(d_true, hedge, sel, addresses, params, rng)
    missing = (rng.random((m, k)) < params.distance_drop_probability) | (
        d_true > params.max_range_m
    )
    dropped = np.asarray(rng.random(m) < params.measurement_drop_probability, dtype=np.bool_)
    received = ~missing

    vendor = solve_vendor_2d(
        slot_beacons,
        d_meas,
        received,
        params.hedge_offset_base_m[2],
        params.min_beacons_for_fix,
        params.vendor_outlier_rms_m,
        engine=engine,
    )
    if params.vendor_outlier_rms_m is not None:
        # The real system's track filter: 0.2 m between fixes is 5 m/s at 25 Hz.
        kept = jump_filter(vendor.xy_m, vendor.ok, _VENDOR_MAX_JUMP_M, engine=engine)
        vendor = replace(vendor, ok=kept, xy_m=np.where(kept[:, None], vendor.xy_m, np.nan))
    if params.vendor_averaging_fixes > 1:
        vendor = replace(
            vendor, xy_m=average_fixes(vendor.xy_m, vendor.ok, params.vendor_averaging_fixes)
        )
    quality = quality_percent(
        vendor,
        np.full(m, k, dtype=np.int64),
        params.quality_residual_scale_m,
        params.quality_hdop_good,
    )
    vendor_xy = vendor.xy_m + rng.normal(0.0, 1.0, (m, 2)) * params.vendor_jitter_m
    gaps = rng.uniform(params.burst_gap_s[0], params.burst_gap_s[1], (m, k + 2))

    reported = np.flatnonzero(~dropped)
    fix_ok = vendor.ok
    shown_xy = _hold_last_fix(vendor_xy, fix_ok, dropped)
    reported_d = received[reported]
    slot_gaps = gaps[reported, 1 : k + 1] * reported_d
    burst_s = slot_gaps.sum(axis=1) + gaps[reported, k + 1]
    t_pos = _ordered_bursts(
        t_emit[reported] + params.latency_s + params.latency_periods / rate[reported],
        burst_s + gaps[reported, 0],
    )
    t_dist = t_pos[:, None] + np.cumsum(slot_gaps, axis=1)

    n_pos = len(reported)
    shown = shown_xy[reported]
    has_xy = ~np.isnan(shown[:, 0])
    positions = IpsPositions(
        t_s=t_pos,
        timestamp_ms=_device_timestamp_ms(t_emit[reported] - t[0], params),
        x_m=_quantize(np.where(has_xy, shown[:, 0], 0.0), params),
        y_m=_quantize(np.where(has_xy, shown[:, 1], 0.0), params),
        z_m=_quantize(np.where(has_xy, hedge[reported, 2], 0.0), params),
        flags=(
            FLAG_TIMESTAMP_MS | np.where(fix_ok[reported], 0, FLAG_COORDINATES_UNAVAILABLE)
        ).astype(np.uint8),
        address=np.full(n_pos, params.hedge_address, dtype=np.uint8),
        angle_deg=np.zeros(n_pos),
        measurement_index=reported.astype(np.int64),
    )
    rows, cols = np.nonzero(reported_d)
    meas_rows = reported[rows]
    distances = IpsDistances(
        t_s=t_dist[rows, cols],
        address_hedge=np.full(len(rows), params.hedge_address, dtype=np.uint8),
        address_beacon=addresses[sel[meas_rows, cols]].astype(np.uint8),
        distance_m=d_meas[meas_rows, cols],
        is_outlier=is_outlier[meas_rows, cols],
        true_distance_m=d_true[meas_rows, cols],
        measurement_index=meas_rows.astype(np.int64),
    )
    quality_msgs = IpsQuality(
        t_s=t_pos + burst_s,
        address=np.full(n_pos, params.hedge_address, dtype=np.uint8),
        quality_percent=quality[reported],
        measurement_index=reported.astype(np.int64),
    )
    truth = IpsTruth(
        t_emit_s=t_emit,
        hedge_map_m=hedge,
        rate_hz=rate,
        submap_addresses=addresses[sel].astype(np.uint8),
        dropped=dropped,
        fix_ok=fix_ok,
    )
    beacon_msgs = _beacon_messages(t[0], t[-1], addresses, _quantize(beacons, params), params, rng)
    for record in (positions, distances, quality_msgs, truth, beacon_msgs):
        _read_only(record)
    return IpsMeasurements(positions, distances, quality_msgs, beacon_msgs, truth)


def _check_inputs(
    t_s: ArrayLike,
    poses_map: ArrayLike,
    beacon_addresses: ArrayLike,
    beacon_positions_m: ArrayLike,
    params: IpsParams,
) -> tuple[F64, F64, I64, F64]:
    t = np.asarray(t_s, dtype=np.float64)
    poses = np.asarray(poses_map, dtype=np.float64)
    addresses = np.asarray(beacon_addresses)
    beacons = np.asarray(beacon_positions_m, dtype=np.float64)
    if t.ndim != 1 or len(t) < 2 or poses.shape != (len(t), 3):
        msg = (
            "simulate_ips: need t_s (N,) with N >= 2 and poses_map (N, 3), "
            f"got {t.shape} and {poses.shape}"
        )
        raise ConfigError(msg)
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(poses)) and np.all(np.diff(t) > 0)):
        msg = "simulate_ips: t_s must be finite and strictly increasing, poses_map finite"
        raise ConfigError(msg)
    if addresses.ndim != 1 or len(addresses) == 0 or beacons.shape != (len(addresses), 3):
        msg = (
            "simulate_ips: need beacon_addresses (B,) with B >= 1 and beacon_positions_m (B, 3), "
            f"got {addresses.shape} and {beacons.shape}"
        )
        raise ConfigError(msg)
    if not np.all(np.isfinite(beacons)):
        msg = "simulate_ips: beacon_positions_m must be finite"
        raise ConfigError(msg)
    if not np.issubdtype(addresses.dtype, np.integer) or np.any(
        (addresses < 1) | (addresses > 255)
    ):
        msg = f"simulate_ips: beacon addresses must be integers 1–255, got {addresses.tolist()}"
        raise ConfigError(msg)
    if len(np.unique(addresses)) != len(addresses) or params.hedge_address in addresses:
        msg = "simulate_ips: beacon addresses must be distinct and differ from the hedgehog's"
        raise ConfigError(msg)
    for zone in params.nlos_zones:
        if zone.beacon_address not in addresses:
            msg = f"nlos_zones: beacon {zone.beacon_address} is not in the beacon map"
            raise ConfigError(msg)
    return t, poses, addresses.astype(np.int64), beacons


def _emission_times(t: F64, rate_hz: F64, params: IpsParams, rng: np.random.Generator) -> F64:
    """One emission per unit of phase ∫ rate dt from a random start phase, plus jitter."""
    phase = np.concatenate([[0.0], np.cumsum(0.5 * (rate_hz[1:] + rate_hz[:-1]) * np.diff(t))])
    start = rng.uniform()
    count = int(np.floor(phase[-1] - start)) + 1 if phase[-1] >= start else 0
    t_emit = np.interp(start + np.arange(count), phase, t)
    jitter = rng.uniform(-params.timing_jitter_s, params.timing_jitter_s, count)
    return np.asarray(np.clip(t_emit + jitter, t[0], t[-1]), dtype=np.float64)


def measured_distances(
    d_true: F64,
    hedge: F64,
    sel: I64,
    addresses: I64,
    params: IpsParams,
    rng: np.random.Generator,
) -> tuple[F64, Bool]:
    """Scale, noise, random reflections and NLOS-zone reflections on the true distances.

    ``d_true`` (M, K) true distances of the submaps ``sel`` (M, K) from the hedgehog positions
    ``hedge`` (M, 3); returns the measured distances (quantised) and which are reflections.
    """
    m, k = d_true.shape
    scale = 1.0 + params.sound_speed_fraction_per_c * params.temperature_error_c
    sigma = params.distance_noise_m + params.distance_noise_fraction * d_true
    noise = rng.normal(0.0, 1.0, (m, k)) * sigma
    random_nlos = rng.random((m, k)) < params.nlos_probability
    random_bias = rng.uniform(params.nlos_bias_range_m[0], params.nlos_bias_range_m[1], (m, k))
    zone_bias = np.zeros((m, k))
    in_zone = np.zeros((m, k), dtype=np.bool_)
    slot_address = addresses[sel]
    for zone in params.nlos_zones:
        hit = zone.contains(hedge[:, 0], hedge[:, 1])[:, None] & (
            slot_address == zone.beacon_address
        )
        zone_bias = np.where(hit, np.maximum(zone_bias, zone.bias_m), zone_bias)
        in_zone |= hit
    bias = np.where(in_zone, zone_bias, np.where(random_nlos, random_bias, 0.0))
    d = np.maximum(d_true * scale + noise + bias, 0.0)
    return _quantize(d, params), in_zone | random_nlos


class VendorTrack:
    """The vendor's track filter and location averaging, one fix at a time (a live hedgehog).

    :meth:`push` runs :func:`~omnical.twin.ips_vendor.jump_filter` on the window that decides
    the newest fix (the last kept fix and those dropped since) and
    :func:`~omnical.twin.ips_vendor.average_fixes` on the last kept ones, so a live stream gets
    the decisions :func:`simulate_ips` takes over a whole run.
    """

    def __init__(self, params: IpsParams) -> None:
        self._filter = params.vendor_outlier_rms_m is not None
        self._n_avg = params.vendor_averaging_fixes
        self._since_kept: list[F64] = []
        self._kept: collections.deque[F64] = collections.deque(maxlen=max(self._n_avg, 1))

    def push(self, xy_m: F64, ok: bool) -> F64 | None:
        """The fix the vendor reports for a new solution ``xy_m`` (None: no fix)."""
        if not ok:
            return None
        xy = np.asarray(xy_m, dtype=np.float64).reshape(2)
        if self._filter:
            window = np.array([*self._since_kept, xy])
            kept = jump_filter(window, np.ones(len(window), dtype=np.bool_), _VENDOR_MAX_JUMP_M)
            if not kept[-1]:
                self._since_kept.append(xy)
                return None
            self._since_kept = [xy]
        self._kept.append(xy)
        if self._n_avg <= 1:
            return xy
        last = np.array(self._kept)
        averaged = average_fixes(last, np.ones(len(last), dtype=np.bool_), self._n_avg)
        return np.asarray(averaged[-1], dtype=np.float64)


def _hold_last_fix(xy: F64, fix_ok: Bool, dropped: Bool) -> F64:
    """Where there is no fix, repeat the last fix the host received (NaN before the first)."""
    shown = fix_ok & ~dropped
    idx = np.where(shown, np.arange(len(xy)), -1)
    last = np.maximum.accumulate(idx) if len(idx) else idx
    held = np.where((last >= 0)[:, None], xy[np.maximum(last, 0)], np.nan)
    return np.where(fix_ok[:, None], xy, held)


def _ordered_bursts(t_start: F64, burst_s: F64) -> F64:
    """Delay burst starts so that each begins after the previous burst has ended."""
    if len(t_start) == 0:
        return t_start
    offset = np.concatenate([[0.0], np.cumsum(burst_s[:-1])])
    return np.asarray(np.maximum.accumulate(t_start - offset) + offset, dtype=np.float64)


def _device_timestamp_ms(t_since_start_s: F64, params: IpsParams) -> I64:
    """uint32 milliseconds since the hedgehog woke up, wrapping at 2³² [IF p.16]."""
    ms = np.floor((params.device_uptime_at_start_s + t_since_start_s) * 1000.0)
    return np.mod(ms.astype(np.int64), _U32)


def _beacon_messages(
    t0: float,
    t1: float,
    addresses: I64,
    beacons: F64,
    params: IpsParams,
    rng: np.random.Generator,
) -> IpsBeaconPositions:
    """All stationary beacons every ``beacon_repeat_period_s``, messages a burst gap apart."""
    first = t0 + params.beacon_first_s
    n_rep = int(np.floor((t1 - first) / params.beacon_repeat_period_s)) + 1 if t1 >= first else 0
    b = len(addresses)
    starts = first + params.beacon_repeat_period_s * np.arange(n_rep)
    gaps = rng.uniform(params.burst_gap_s[0], params.burst_gap_s[1], (n_rep, b))
    t_msg = (starts[:, None] + np.cumsum(gaps, axis=1) - gaps[:, :1]).ravel()
    return IpsBeaconPositions(
        t_s=t_msg,
        address=np.tile(addresses, n_rep).astype(np.uint8),
        x_m=np.tile(beacons[:, 0], n_rep),
        y_m=np.tile(beacons[:, 1], n_rep),
        z_m=np.tile(beacons[:, 2], n_rep),
    )


def _quantize(values_m: F64, params: IpsParams) -> F64:
    """Round to whole millimetres, the wire resolution [IF p.16, p.22], when enabled."""
    values = np.asarray(values_m, dtype=np.float64)
    return np.round(values * 1000.0) / 1000.0 if params.quantize_mm else values


def _read_only(record: object) -> None:
    """Make every array field of a result record read-only."""
    for value in vars(record).values():
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
