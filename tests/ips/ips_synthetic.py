"""Synthetic range data for the multilateration tests (seeded, generated in the tests)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from omnical.ips import BeaconMap


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
