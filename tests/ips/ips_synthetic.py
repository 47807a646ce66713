"""Synthetic range data for the multilateration tests (seeded, generated in the tests)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.ips.beacons import BeaconMap
from omnical.ips.solve.fixes import Fixes
from omnical.ips.solve.locate import Method, group_ranges, locate_bursts
from omnical.recording.recording import Recording, RecordingBuilder


@dataclass(frozen=True)
class RangeSet:
    """True hedgehog positions and the distances measured from them."""

    truth_m: NDArray[np.float64]
    """True positions, (n, 3), metres."""
    distances_m: NDArray[np.float64]
    """Measured distances, (n, m), metres."""
    outlier: NDArray[np.bool_]
    """Which distances carry an NLOS bias, (n, m)."""


def exact_distances(beacons: BeaconMap, points_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return the true distances (n, m) from points (n, 3) to the map's beacons."""
    delta = points_m[:, None, :] - beacons.positions_m[None, :, :]
    distances: NDArray[np.float64] = np.sqrt(np.sum(delta * delta, axis=2))
    return distances


def trajectory_inside(rng: np.random.Generator, n: int, z_m: float = 0.4) -> NDArray[np.float64]:
    """Return a random-walk trajectory (n, 3) inside the default map's quadrilateral."""
    steps = rng.normal(0.0, 0.05, (n, 2))
    walk = np.cumsum(steps, axis=0)
    x = 0.8 + np.abs(np.mod(walk[:, 0], 8.4) - 4.2)  # reflect into [0.8, 5.0]
    y = 0.8 + np.abs(np.mod(walk[:, 1], 6.4) - 3.2)  # reflect into [0.8, 4.0]
    return np.stack([x, y, np.full(n, z_m)], axis=1)


def trajectory_near_edges(
    rng: np.random.Generator, n: int, z_m: float = 0.4
) -> NDArray[np.float64]:
    """Return points (n, 3) along the edges of the default map, up to 0.3 m outside it."""
    corners = np.array([[0.0, 0.0], [5.767, 0.0], [5.445, 4.813], [0.485, 4.809]])
    edge = rng.integers(0, 4, n)
    along = rng.uniform(0.0, 1.0, n)
    start, end = corners[edge], corners[(edge + 1) % 4]
    points = start + along[:, None] * (end - start)
    points += rng.uniform(-0.3, 0.3, (n, 2))
    return np.column_stack([points, np.full(n, z_m)])


def measure(
    rng: np.random.Generator,
    beacons: BeaconMap,
    truth_m: NDArray[np.float64],
    *,
    sigma_m: float,
    outlier_rate: float,
    bias_m: tuple[float, float] = (0.1, 1.0),
) -> RangeSet:
    """Return distances with Gaussian noise and NLOS outliers (positive bias) per range."""
    exact = exact_distances(beacons, truth_m)
    noisy = exact + rng.normal(0.0, sigma_m, exact.shape)
    outlier = rng.random(exact.shape) < outlier_rate
    noisy += np.where(outlier, rng.uniform(*bias_m, exact.shape), 0.0)
    return RangeSet(truth_m, noisy, outlier)


def hedgehogs_on_circles(
    hedges: int = 3, seconds: float = 60.0, seed: int = 0, nlos: float = 0.05, missing: float = 0.01
) -> Recording:
    """Several hedgehogs on circles, bursts of four ranges at 8 Hz each, 5 % NLOS, a few
    ranges missing, vendor heights with noise."""
    rng = np.random.default_rng(seed)
    beacons = np.array([[0.0, 0.0, 2.0], [6.0, 0.0, 2.1], [6.0, 5.0, 1.9], [0.0, 5.0, 2.0]])
    addresses = np.array([3, 4, 5, 6])
    z = 0.4
    rows: list[tuple[int, int, int, float]] = []
    vendor: list[tuple[int, int, float, int]] = []
    steps = int(seconds * 8)
    for h in range(hedges):
        phase = rng.uniform(0, 2 * np.pi)
        for k in range(steps):
            t0 = int(k * 125_000_000 + h * 37_000_000 + rng.integers(0, 2_000_000))
            angle = phase + 0.3 * k / 8.0
            p = np.array([3.0 + 2.0 * np.cos(angle), 2.5 + 1.8 * np.sin(angle), z])
            for j, (b, a) in enumerate(zip(beacons, addresses, strict=True)):
                if rng.random() < missing:
                    continue  # a range missing
                d = float(np.linalg.norm(p - b) + rng.normal(0.0, 0.02 + 0.005 * j))
                if rng.random() < nlos:
                    d += rng.uniform(0.2, 0.8)
                rows.append((t0 + j * 1_000_000, 10 + h, int(a), d))
            vendor.append((t0 + 5_000_000, 10 + h, z + rng.normal(0.0, 0.01), 0))
    rows.sort()
    vendor.sort()
    builder = RecordingBuilder()
    for t, hedge, beacon, d in rows:
        builder.add(
            "/beacon_raw_distance", t, address_hedge=hedge, address_beacon=beacon, distance_m=d
        )
    for t, hedge, zv, flags in vendor:
        builder.add(
            "/hedge_pos_ang", t, address=hedge, timestamp_ms=t // 1_000_000, x_m=0.0, y_m=0.0,
            z_m=zv, flags=flags, angle_deg=0.0,
        )  # fmt: skip
    for a, b in zip(addresses, beacons, strict=True):
        builder.add("/beacons_pos_a", 0, address=int(a), x_m=b[0], y_m=b[1], z_m=b[2])
    return builder.build()


def locate_recording(
    t_ns: ArrayLike,
    address_hedge: ArrayLike,
    address_beacon: ArrayLike,
    distance_m: ArrayLike,
    beacons: BeaconMap,
    *,
    method: Method = "robust",
    hedge_z_m: float | None = None,
    sequential: bool | None = None,
) -> Fixes:
    """Raw-distance messages grouped into fixes and solved, as ``omnical locate`` does."""
    bursts, notes = group_ranges(
        t_ns, address_hedge, address_beacon, distance_m, beacons, sequential=sequential
    )
    return locate_bursts(bursts, beacons, notes=notes, method=method, hedge_z_m=hedge_z_m)
