"""Evaluate benchmark (issue "Scale", item 3): the batch smoother at 1, 10 and 60 minutes.

Figures, each measured in a fresh process (time, and peak memory as VmHWM — the process's
own high-water mark, not ru_maxrss, which keeps the parent's across fork + exec):

* :func:`omnical.estimation.smoother.smooth_track` on a synthetic run at the twin's rates
  (odometry 50 Hz, IPS fixes 25 Hz with 2 cm noise and 50 ms latency, gyro 100 Hz; loops
  round a 3 × 2 m area, the odometry 10 % long sideways and turning 3 % too far), with the
  banded solver (banded Cholesky of the poses + Schur complement on the shared parameters) and
  with the baseline measured in the same run: ``solver="sparse"``, the general sparse LU of
  the whole normal matrix and the per-pose selected inversion it replaced;
* the ratios baseline / banded, and the peak above the process's state before smoothing
  (imports and inputs), per pose.

``--bags R1 R10 …`` also times ``omnical evaluate`` end to end on recordings (each in a fresh
process; e.g. twin runs made with ``omnical simulate``). ``--no-baseline-above M`` skips the
sparse baseline on runs longer than M minutes (it takes minutes and gigabytes at 60).

Run: ``.venv/bin/python bench/bench_evaluate.py [--bags DIR …]``.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

MINUTES = (1, 10, 60)
OFFSET = (0.04, -0.03)


def _vmhwm_mb() -> float:
    status = Path("/proc/self/status").read_text().splitlines()
    return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:")) / 1024


def synthetic_run(minutes: float, seed: int = 0) -> dict[str, np.ndarray]:
    """Odometry (N, 4), fixes (times, positions, covariances) and gyro (G, 2) of a run."""
    from omnical.estimation.se2 import between_poses

    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 60.0 * minutes, 0.02)
    truth = np.column_stack(
        [
            3.0 + 1.5 * np.sin(0.05 * t),
            2.5 + 1.0 * np.sin(0.1 * t),
            0.25 * t + 0.5 * np.sin(0.03 * t),
        ]
    )
    inc = between_poses(truth[:-1], truth[1:])
    inc[:, 1] *= 1.1
    inc[:, 2] *= 1.03
    inc[:, :2] += rng.normal(0.0, 2e-5, (inc.shape[0], 2))
    yaw = np.concatenate([[0.0], np.cumsum(inc[:, 2])])
    c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    odom = np.column_stack(
        [
            t,
            np.concatenate([[0.0], np.cumsum(c * inc[:, 0] - s * inc[:, 1])]),
            np.concatenate([[0.0], np.cumsum(s * inc[:, 0] + c * inc[:, 1])]),
            np.angle(np.exp(1j * yaw)),
        ]
    )
    tf = np.arange(0.5, t[-1] - 0.5, 0.04)
    at = np.column_stack([np.interp(tf - 0.05, t, truth[:, k]) for k in range(3)])
    c, s = np.cos(at[:, 2]), np.sin(at[:, 2])
    hedge = at[:, :2] + np.column_stack(
        [c * OFFSET[0] - s * OFFSET[1], s * OFFSET[0] + c * OFFSET[1]]
    )
    tg = np.arange(0.0, t[-1], 0.01)
    gyro = np.column_stack([tg, np.interp(tg, t, np.gradient(truth[:, 2], t)) + 0.002])
    return {
        "truth": truth,
        "odom": odom,
        "fix_t": tf,
        "fixes": hedge + rng.normal(0.0, 0.02, hedge.shape),
        "cov": np.broadcast_to(np.eye(2) * 0.02**2, (tf.size, 2, 2)).copy(),
        "gyro": gyro,
    }


def _smoother_child(minutes: float, solver: str) -> None:
    """One smoothing in this fresh process: prints a JSON line of its figures."""
    from omnical.estimation.smoother import SmootherParams, smooth_track

    run = synthetic_run(minutes)
    before_mb = _vmhwm_mb()
    start = time.perf_counter()
    sm = smooth_track(
        SmootherParams(hedge_offset_m=OFFSET),
        run["odom"],
        run["fix_t"],
        run["fixes"],
        run["cov"],
        gyro=run["gyro"],
        solver=solver,  # type: ignore[arg-type]
    )
    seconds = time.perf_counter() - start
    err = np.hypot(*(sm.poses[:, :2] - run["truth"][:, :2]).T)
    out = {
        "seconds": seconds,
        "peak_mb": _vmhwm_mb(),
        "before_mb": before_mb,
        "poses": int(sm.poses.shape[0]),
        "iterations": sm.iterations,
        "rmse_mm": 1e3 * float(np.sqrt(np.mean(err**2))),
        "sigma_mm": 1e3 * sm.position_sigma_rms_m,
    }
    print(json.dumps(out))


def _evaluate_child(bag: str, out: str) -> None:
    """``omnical evaluate BAG --out OUT`` in this fresh process: prints seconds and peak MB."""
    from omnical.cli.main import main as omnical_main

    sys.argv = ["omnical", "evaluate", bag, "--out", out, "--overwrite"]
    start = time.perf_counter()
    try:
        omnical_main()
    except SystemExit as stop:
        if stop.code not in (0, None):
            raise
    print(json.dumps({"seconds": time.perf_counter() - start, "peak_mb": _vmhwm_mb()}))


def _run_child(*args: str) -> dict[str, float]:
    out = subprocess.run(
        [sys.executable, __file__, *args], check=True, capture_output=True, text=True
    ).stdout
    result: dict[str, float] = json.loads(out.strip().splitlines()[-1])
    return result


def smoother(no_baseline_above: float) -> None:
    print("smooth_track, synthetic run at the twin's rates (each in a fresh process)")
    for minutes in MINUTES:
        new = _run_child("--smoother", str(minutes), "banded")
        grown = new["peak_mb"] - new["before_mb"]
        print(
            f"{minutes:3d} min {new['poses']:7,d} poses  banded {new['seconds']:7.2f} s "
            f"peak {new['peak_mb']:6.0f} MB (+{grown:5.0f} MB, "
            f"{1e6 * grown / new['poses']:4.0f} B/pose)  {new['iterations']:.0f} it  "
            f"RMSE {new['rmse_mm']:.2f} mm (own 1σ {new['sigma_mm']:.2f})"
        )
        if minutes > no_baseline_above:
            print("        sparse baseline skipped (--no-baseline-above)")
            continue
        old = _run_child("--smoother", str(minutes), "sparse")
        old_grown = old["peak_mb"] - old["before_mb"]
        print(
            f"        sparse baseline {old['seconds']:7.2f} s peak {old['peak_mb']:6.0f} MB "
            f"(+{old_grown:5.0f} MB)   ratio {old['seconds'] / new['seconds']:.1f}x faster, "
            f"{old_grown / max(grown, 1.0):.1f}x less memory grown"
        )


def bags(paths: list[str]) -> None:
    print("omnical evaluate end to end (each in a fresh process)")
    with tempfile.TemporaryDirectory() as tmp:
        for i, bag in enumerate(paths):
            got = _run_child("--evaluate", bag, str(Path(tmp) / f"ev{i}"))
            print(f"{bag:<40} {got['seconds']:7.2f} s  peak {got['peak_mb']:6.0f} MB")


def main(argv: list[str]) -> None:
    no_baseline_above = float("inf")
    if "--no-baseline-above" in argv:
        no_baseline_above = float(argv[argv.index("--no-baseline-above") + 1])
    smoother(no_baseline_above)
    if "--bags" in argv:
        listed = argv[argv.index("--bags") + 1 :]
        bags([p for p in listed if not p.startswith("--")])


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--smoother":
        _smoother_child(float(sys.argv[2]), sys.argv[3])
    elif len(sys.argv) > 1 and sys.argv[1] == "--evaluate":
        _evaluate_child(sys.argv[2], sys.argv[3])
    else:
        main(sys.argv[1:])
