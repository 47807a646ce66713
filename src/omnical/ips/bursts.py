"""Group headerless raw-distance messages into fixes (one measurement each).

:func:`group_bursts` turns ``/beacon_raw_distance`` messages into :class:`Bursts`;
:func:`sliding_windows` regroups them. Burst rule and algorithm: docs/locate.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError
from omnical.ips.beacons import BeaconMap

__all__ = ["Bursts", "burst_starts", "group_bursts", "is_sequential", "sliding_windows"]

DEFAULT_MAX_GAP_NS = 15_000_000
"""Default largest gap between two messages of one burst: 15 ms."""


@dataclass(frozen=True, eq=False)
class Bursts:
    """Raw distances grouped into fixes.

    Attributes:
        t_ns: Time of the first message of each fix, shape (f,), int64 ns.
        address_hedge: Hedgehog address of each fix, shape (f,).
        beacon_addresses: Column order of :attr:`distances_m`, shape (m,) (the map's order).
        distances_m: Distance to each map beacon, shape (f, m), metres; NaN where the burst
            has no valid distance for that beacon.
        n_messages: Messages in each fix, shape (f,).
        n_unknown: Messages whose beacon is not in the map, shape (f,).
        n_invalid: Messages with a NaN, infinite or negative distance, shape (f,).
        fix_of_message: Index of the fix each input message went to, shape (n,).
    """

    t_ns: NDArray[np.int64]
    address_hedge: NDArray[np.int64]
    beacon_addresses: NDArray[np.int64]
    distances_m: NDArray[np.float64]
    n_messages: NDArray[np.int64]
    n_unknown: NDArray[np.int64]
    n_invalid: NDArray[np.int64]
    fix_of_message: NDArray[np.intp]

    def __len__(self) -> int:
        """Return the number of fixes."""
        return int(self.t_ns.size)

    @property
    def n_valid(self) -> NDArray[np.int64]:
        """Number of valid distances to map beacons in each fix, shape (f,)."""
        counts: NDArray[np.int64] = np.count_nonzero(np.isfinite(self.distances_m), axis=1)
        return counts.astype(np.int64)


def burst_starts(
    t_ns: ArrayLike,
    address_hedge: ArrayLike,
    address_beacon: ArrayLike,
    *,
    max_gap_ns: int = DEFAULT_MAX_GAP_NS,
) -> NDArray[np.bool_]:
    """Mark the messages that start a new burst.

    A message starts a burst when it is the first one, when the time since the previous
    message exceeds ``max_gap_ns``, when its hedgehog address differs from the previous one,
    or when its beacon address already occurred in the current burst (greedy, in time order).

    Args:
        t_ns: Receive time of each message, shape (n,), int ns, non-decreasing.
        address_hedge: Hedgehog address of each message, shape (n,).
        address_beacon: Beacon address of each message, shape (n,).
        max_gap_ns: Largest gap inside a burst, ns.

    Returns:
        Boolean mask, shape (n,), True where a burst starts.

    Raises:
        ConfigError: If the arrays differ in length or the times decrease.
    """
    t = np.asarray(t_ns, dtype=np.int64).reshape(-1)
    hedge = np.asarray(address_hedge, dtype=np.int64).reshape(-1)
    beacon = np.asarray(address_beacon, dtype=np.int64).reshape(-1)
    n = t.size
    if hedge.size != n or beacon.size != n:
        msg = f"burst_starts: arrays differ in length: {n}, {hedge.size}, {beacon.size}"
        raise ConfigError(msg)
    if n == 0:
        return np.zeros(0, dtype=bool)
    if np.any(np.diff(t) < 0):
        first = int(np.flatnonzero(np.diff(t) < 0)[0]) + 1
        msg = f"burst_starts: t_ns must be non-decreasing, message {first} goes back in time"
        raise ConfigError(msg)
    segment_start = np.ones(n, dtype=bool)
    segment_start[1:] = (np.diff(t) > max_gap_ns) | (hedge[1:] != hedge[:-1])
    segment = np.cumsum(segment_start) - 1
    # End (exclusive) of the gap segment each message lies in.
    segment_begin = np.flatnonzero(segment_start)
    segment_end = np.append(segment_begin[1:], n)[segment]
    # Next message of the same beacon inside the same segment (n if none).
    order = np.lexsort((np.arange(n), beacon, segment))
    next_same = np.full(n, n, dtype=np.int64)
    same = (segment[order[1:]] == segment[order[:-1]]) & (beacon[order[1:]] == beacon[order[:-1]])
    next_same[order[:-1][same]] = order[1:][same]
    # A burst starting at s ends at the first j whose beacon already occurred in [s, j), i.e.
    # min over p >= s of next_same[p]; never past the end of its segment.
    first_repeat = np.minimum.accumulate(next_same[::-1])[::-1]
    jump = np.append(np.minimum(first_repeat, segment_end), n)  # node n is the sink
    # Mark every node on the chain 0 -> jump[0] -> ... by pointer doubling.
    on_chain = np.zeros(n + 1, dtype=bool)
    on_chain[0] = True
    while True:
        nodes = np.flatnonzero(on_chain)
        on_chain[jump[nodes]] = True
        if jump[0] == n:
            break
        jump = jump[jump]
    return on_chain[:n]


def group_bursts(
    t_ns: ArrayLike,
    address_hedge: ArrayLike,
    address_beacon: ArrayLike,
    distance_m: ArrayLike,
    beacons: BeaconMap,
    *,
    max_gap_ns: int = DEFAULT_MAX_GAP_NS,
) -> Bursts:
    """Group raw-distance messages into fixes with one distance column per map beacon.

    Args:
        t_ns: Receive time of each message, shape (n,), int ns, non-decreasing.
        address_hedge: Hedgehog address of each message, shape (n,).
        address_beacon: Beacon address of each message, shape (n,).
        distance_m: Distance of each message, shape (n,), metres.
        beacons: Map that fixes the column order; other beacons are counted as unknown.
        max_gap_ns: Largest gap between two messages of one burst, ns (default 15 ms).

    Returns:
        The fixes, see :class:`Bursts`. Invalid distances (NaN, infinite, negative) are left
        out of the matrix and counted in ``n_invalid``.

    Raises:
        ConfigError: If the arrays differ in length or the times decrease.
    """
    t = np.asarray(t_ns, dtype=np.int64).reshape(-1)
    distance = np.asarray(distance_m, dtype=np.float64).reshape(-1)
    hedge = np.asarray(address_hedge, dtype=np.int64).reshape(-1)
    beacon = np.asarray(address_beacon, dtype=np.int64).reshape(-1)
    if distance.size != t.size:
        msg = f"group_bursts: {t.size} times but {distance.size} distances"
        raise ConfigError(msg)
    starts = burst_starts(t, hedge, beacon, max_gap_ns=max_gap_ns)
    fix = (np.cumsum(starts) - 1).astype(np.intp)
    n_fix = int(starts.sum())
    column = beacons.index_of(beacon)
    unknown = column < 0
    invalid = ~np.isfinite(distance) | (distance < 0.0)
    matrix = np.full((n_fix, len(beacons)), np.nan)
    keep = ~unknown & ~invalid
    matrix[fix[keep], column[keep]] = distance[keep]
    first = np.flatnonzero(starts)
    return Bursts(
        t_ns=t[first],
        address_hedge=hedge[first],
        beacon_addresses=beacons.addresses.copy(),
        distances_m=matrix,
        n_messages=np.bincount(fix, minlength=n_fix).astype(np.int64),
        n_unknown=np.bincount(fix[unknown], minlength=n_fix).astype(np.int64),
        n_invalid=np.bincount(fix[invalid & ~unknown], minlength=n_fix).astype(np.int64),
        fix_of_message=fix,
    )


def is_sequential(bursts: Bursts, dims: int = 2) -> bool:
    """Whether the ranges come one per measurement (round robin) rather than in bursts.

    True when most bursts hold fewer valid distances than a fix needs (``dims + 1``).
    """
    if len(bursts) == 0:
        return False
    return bool(np.median(bursts.n_valid) < dims + 1)


def sliding_windows(
    t_ns: ArrayLike,
    address_hedge: ArrayLike,
    address_beacon: ArrayLike,
    distance_m: ArrayLike,
    beacons: BeaconMap,
    *,
    max_age_ns: int | None = None,
) -> tuple[Bursts, int]:
    """One fix per message from the latest distance of each beacon: for sequential ranges.

    Systems that range one beacon at a time (round robin) send one distance per message, so
    bursts hold a single range. Here every message closes a window holding, per map beacon,
    the latest valid distance of the same hedgehog no older than ``max_age_ns``.

    Args:
        t_ns: Receive time of each message, shape (n,), int ns, non-decreasing.
        address_hedge: Hedgehog address of each message, shape (n,).
        address_beacon: Beacon address of each message, shape (n,).
        distance_m: Distance of each message, shape (n,), metres.
        beacons: Map that fixes the column order.
        max_age_ns: Oldest distance a window keeps, ns; default 1.5 times the median time
            between two distances of the same beacon (one round of the round robin).

    Returns:
        The windows as :class:`Bursts` (``t_ns`` is the newest message's time,
        ``n_messages`` the distances in the window) and the maximum age used, ns.

    Raises:
        ConfigError: If the arrays differ in length or the times decrease.
    """
    t = np.asarray(t_ns, dtype=np.int64).reshape(-1)
    hedge = np.asarray(address_hedge, dtype=np.int64).reshape(-1)
    beacon = np.asarray(address_beacon, dtype=np.int64).reshape(-1)
    distance = np.asarray(distance_m, dtype=np.float64).reshape(-1)
    n = t.size
    if hedge.size != n or beacon.size != n or distance.size != n:
        msg = f"sliding_windows: arrays differ in length: {n}, {hedge.size}, {beacon.size}"
        raise ConfigError(msg)
    if np.any(np.diff(t) < 0):
        msg = "sliding_windows: t_ns must be non-decreasing"
        raise ConfigError(msg)
    column = beacons.index_of(beacon)
    unknown = column < 0
    invalid = ~np.isfinite(distance) | (distance < 0.0)
    keep = ~unknown & ~invalid
    index = np.arange(n)
    # The messages of each hedgehog (rows in time order): the work below is per hedgehog.
    order = np.argsort(hedge, kind="stable")
    sorted_hedge = hedge[order]
    starts = np.flatnonzero(sorted_hedge[1:] != sorted_hedge[:-1]) + 1
    groups = np.split(order, starts) if n else []
    if max_age_ns is None:
        periods = [
            np.diff(t[rows[keep[rows] & (column[rows] == k)]])
            for rows in groups
            for k in range(len(beacons))
        ]
        joined = np.concatenate([p for p in periods if p.size] or [np.zeros(0, dtype=np.int64)])
        max_age_ns = int(1.5 * np.median(joined)) if joined.size else DEFAULT_MAX_GAP_NS
    matrix = np.full((n, len(beacons)), np.nan)
    for rows in groups:
        mine_keep = keep[rows]
        mine_column = column[rows]
        mine_t = t[rows]
        for k in range(len(beacons)):
            # The latest usable message of this beacon at or before each of the hedgehog's.
            latest = np.maximum.accumulate(np.where(mine_keep & (mine_column == k), rows, -1))
            fresh = latest >= 0
            fresh[fresh] &= mine_t[fresh] - t[latest[fresh]] <= max_age_ns
            matrix[rows[fresh], k] = distance[latest[fresh]]
    windows = Bursts(
        t_ns=t.copy(),
        address_hedge=hedge.copy(),
        beacon_addresses=beacons.addresses.copy(),
        distances_m=matrix,
        n_messages=np.count_nonzero(np.isfinite(matrix), axis=1).astype(np.int64),
        n_unknown=unknown.astype(np.int64),
        n_invalid=(invalid & ~unknown).astype(np.int64),
        fix_of_message=index.astype(np.intp),
    )
    return windows, int(max_age_ns)
