"""Benchmark: vectorised multilateration against per-fix SciPy and the 1 mm grid search.

10^6 fixes on the default 4-beacon map (seed 000, Table 3), Gaussian noise σ = 2 cm, each
range NLOS-biased (+0.1…1 m) with probability 5 %. Times the robust method on all of them,
the vectorised plain least squares, ``scipy.optimize.least_squares`` called once per fix on
a 2,000-fix subsample and the grid method on a 2,000-fix subsample; the subsample rates are
extrapolated to fixes per second. All in the same run; the ratios are what to compare. Then a
whole self-calibrated solve (``solve_self_calibrated``: learning, link covariance, calibration
uncertainty) of a run of 8 biased beacons, which is what ``omnical locate`` does per hedgehog.

Run: ``PYTHONPATH=src .venv/bin/python bench/bench_multilateration.py [--fixes N]``
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from omnical.ips.beacons import BeaconMap, default_beacon_map
from omnical.ips.solve.locate import solve_fixes, solve_self_calibrated

SUBSAMPLE = 2_000


def synthetic_distances(n: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """Return distances (n, 4) from random points inside the default map, with NLOS."""
    beacons = default_beacon_map()
    truth = np.column_stack([rng.uniform(0.3, 5.5, n), rng.uniform(0.3, 4.5, n), np.full(n, 0.4)])
    distances: NDArray[np.float64] = np.linalg.norm(
        truth[:, None, :] - beacons.positions_m[None], axis=2
    )
    distances += rng.normal(0.0, 0.02, distances.shape)
    distances += (rng.random(distances.shape) < 0.05) * rng.uniform(0.1, 1.0, distances.shape)
    return distances


def biased_ring_run(n: int, rng: np.random.Generator) -> tuple[NDArray[np.float64], BeaconMap]:
    """Return distances (n, 8) of a tag looping inside a ring of 8 beacons (z = 1 m) whose links
    read long by 5–25 cm and 1.5 % (as raw UWB ranges), σ 3 cm, and the ring."""
    angle = np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)
    positions = np.column_stack([5.0 * np.cos(angle), 4.0 * np.sin(angle), np.ones(8)])
    t = np.linspace(0.0, n / 20.0, n)
    truth = np.column_stack([2.5 * np.sin(0.21 * t), 2.0 * np.sin(0.34 * t + 0.5), np.ones(n)])
    rho = np.linalg.norm(truth[:, None, :] - positions[None], axis=2)
    distances: NDArray[np.float64] = rng.uniform(0.05, 0.25, 8) + 1.015 * rho
    distances += rng.normal(0.0, 0.03, distances.shape)
    return distances, BeaconMap(np.arange(1, 9), positions)


def best_time_s(run: Callable[[], object], repeats: int) -> float:
    """Return the shortest wall time of ``repeats`` runs, seconds."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def scipy_per_fix(distances: NDArray[np.float64]) -> NDArray[np.float64]:
    """Solve each fix with ``scipy.optimize.least_squares`` (2D, from the beacons' centroid)."""
    beacons = default_beacon_map().positions_m
    start = beacons[:, :2].mean(axis=0)
    out = np.empty((distances.shape[0], 2))
    for i, d in enumerate(distances):

        def residual(p: NDArray[np.float64], d: NDArray[np.float64] = d) -> NDArray[np.float64]:
            modelled: NDArray[np.float64] = np.hypot(p[0] - beacons[:, 0], p[1] - beacons[:, 1])
            return modelled - d

        out[i] = least_squares(residual, start, method="lm").x
    return out


def main() -> None:
    """Run the benchmark and print fixes per second and ratios."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fixes", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--self-calibrated-fixes", type=int, default=20_000)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    beacons = default_beacon_map()
    distances = synthetic_distances(args.fixes, rng)
    sub = distances[:SUBSAMPLE]
    n = args.fixes

    rates = {}

    def robust(workers: int) -> Callable[[], object]:
        return lambda: solve_fixes(distances, beacons, method="robust", workers=workers)

    for workers in (1, 2):
        seconds = best_time_s(robust(workers), args.repeats)
        rates[f"robust, vectorised, {workers} thread(s)"] = n / seconds
    seconds = best_time_s(lambda: solve_fixes(distances, beacons, method="lsq"), args.repeats)
    rates["lsq, vectorised, 1 thread"] = n / seconds
    seconds = best_time_s(lambda: scipy_per_fix(sub), 1)
    rates[f"scipy least_squares per fix ({SUBSAMPLE} fixes, extrapolated)"] = SUBSAMPLE / seconds
    seconds = best_time_s(lambda: solve_fixes(sub, beacons, method="grid"), 1)
    rates[f"grid 1 mm, vectorised ({SUBSAMPLE} fixes, extrapolated)"] = SUBSAMPLE / seconds

    robust = rates["robust, vectorised, 1 thread(s)"]
    print(f"multilateration, {n:,} fixes, 4 beacons, 5 % NLOS ranges (best of {args.repeats})")
    for name, rate in rates.items():
        print(f"  {name:60s} {rate:12,.0f} fixes/s   robust(1 thread)/this = {robust / rate:8.2f}")
    best = max(rates[k] for k in rates if k.startswith("robust"))
    target = 2e6
    print(
        f"  robust best {best:,.0f} fixes/s; target {target:,.0f}: "
        f"{'met' if best >= target else 'NOT met'} ({best / target:.2f} of target)"
    )
    k = args.self_calibrated_fixes
    ring, ring_map = biased_ring_run(k, rng)
    seconds = best_time_s(
        lambda: solve_self_calibrated(ring, ring_map, hedge_z_m=1.0), args.repeats
    )
    print(
        f"self-calibrated solve, {k:,} fixes, 8 biased beacons: {seconds:.3f} s "
        f"({k / seconds:,.0f} fixes/s, best of {args.repeats})"
    )


if __name__ == "__main__":
    main()
