"""The grid method of seed 000 (Eq. 4 minimised at 1 mm): coarse-to-fine equals brute force."""

from __future__ import annotations

import numpy as np
from ips_synthetic import exact_distances, measure, trajectory_inside
from numpy.typing import NDArray

from omnical.ips.beacons import BeaconMap, default_beacon_map
from omnical.ips.solve._fit import SolverOptions
from omnical.ips.solve.fixes import FixStatus
from omnical.ips.solve.locate import solve_fixes


def brute_force_mm(
    beacons: BeaconMap,
    distances_m: NDArray[np.float64],
    hedge_z_m: float,
    x_mm: NDArray[np.int64],
    y_mm: NDArray[np.int64],
) -> NDArray[np.float64]:
    """Return the 1 mm lattice point (x, y) in metres minimising Eq. 4 over a whole lattice."""
    x = (x_mm * 1e-3)[:, None]
    y = (y_mm * 1e-3)[None, :]
    cost = np.zeros((x_mm.size, y_mm.size))
    for (bx, by, bz), d in zip(beacons.positions_m, distances_m, strict=True):
        cost += (np.sqrt((x - bx) ** 2 + (y - by) ** 2 + (hedge_z_m - bz) ** 2) - d) ** 2
    i, j = np.unravel_index(np.argmin(cost), cost.shape)
    return np.array([x_mm[i] * 1e-3, y_mm[j] * 1e-3])


def test_coarse_to_fine_equals_brute_force_on_a_small_map() -> None:
    beacons = BeaconMap(
        np.arange(4),
        np.array([[0.0, 0.0, 0.0], [1.2, 0.0, 0.0], [0.0, 1.0, 0.0], [1.1, 1.1, 0.0]]),
    )
    rng = np.random.default_rng(21)
    truth = np.column_stack([rng.uniform(-0.1, 1.3, 6), rng.uniform(-0.1, 1.2, 6), np.zeros(6)])
    data = measure(rng, beacons, truth, sigma_m=0.03, outlier_rate=0.0)
    options = SolverOptions(grid_margin_m=0.2)
    fixes = solve_fixes(data.distances_m, beacons, method="grid", hedge_z_m=0.0, options=options)
    # The whole search box, every millimetre.
    x_mm = np.arange(-200, 1401)
    y_mm = np.arange(-200, 1301)
    for i in range(6):
        best = brute_force_mm(beacons, data.distances_m[i], 0.0, x_mm, y_mm)
        np.testing.assert_allclose(fixes.positions_map_m[i, :2], best, atol=1e-12)


def test_grid_is_the_millimetre_minimum_on_the_default_map() -> None:
    rng = np.random.default_rng(22)
    beacons = default_beacon_map()
    data = measure(rng, beacons, trajectory_inside(rng, 8), sigma_m=0.02, outlier_rate=0.1)
    fixes = solve_fixes(data.distances_m, beacons, method="grid")
    for i in range(8):
        centre = np.round(fixes.positions_map_m[i, :2] * 1000).astype(np.int64)
        x_mm = np.arange(centre[0] - 150, centre[0] + 151)
        y_mm = np.arange(centre[1] - 150, centre[1] + 151)
        best = brute_force_mm(beacons, data.distances_m[i], 0.4, x_mm, y_mm)
        np.testing.assert_allclose(fixes.positions_map_m[i, :2], best, atol=1e-12)


def test_grid_agrees_with_least_squares_to_a_millimetre() -> None:
    rng = np.random.default_rng(23)
    beacons = default_beacon_map()
    data = measure(rng, beacons, trajectory_inside(rng, 300), sigma_m=0.02, outlier_rate=0.05)
    grid = solve_fixes(data.distances_m, beacons, method="grid")
    lsq = solve_fixes(data.distances_m, beacons, method="lsq")
    # The lattice point of least cost is next to the continuous minimum, not always the
    # nearest lattice point: within a couple of millimetres when the valley is elongated.
    offset = np.linalg.norm(grid.positions_map_m - lsq.positions_map_m, axis=1)
    assert np.max(offset) < 2e-3
    assert np.mean(offset) < 0.5e-3
    np.testing.assert_array_equal(grid.status, lsq.status)
    positions_mm = grid.positions_map_m[:, :2] * 1000
    np.testing.assert_allclose(positions_mm, np.round(positions_mm), atol=1e-6)


def test_grid_reports_eq4() -> None:
    beacons = default_beacon_map()
    truth = np.array([[1.0005, 2.0, 0.4]])  # half a millimetre off the lattice
    distances = exact_distances(beacons, truth)
    fixes = solve_fixes(distances, beacons, method="grid")
    assert fixes.status[0] == FixStatus.OK
    position = fixes.positions_map_m[0]
    residual = np.linalg.norm(beacons.positions_m - position, axis=1) - distances[0]
    assert fixes.error_eq4_m[0] == np.sqrt(np.sum(residual**2)) / 16
    assert 0.0 < fixes.error_eq4_m[0] < 1e-4
