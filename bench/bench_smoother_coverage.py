"""Does the smoothed track's own 1σ hold? Its error against the truth over many recordings.

Recordings shaped like a user's (``/odom``, the Marvelmind topics, **no** ``/imu``), evaluated
as ``omnical evaluate`` does (:func:`~omnical.evaluation.metrics.track_recording`, the robot's
lever arm given), against the truth they were simulated with:

- ``twin-lissajous``: seed 000's open-loop Lissajous on the default twin with its cross-talks ×3
  (heading held: the lever arm is not observable and is held);
- ``twin-tour``: the tour (forward, left, three turns, reverse, right), cross-talks ×3;
- ``foreign-lissajous``: two minutes of a turning Lissajous on the independent simulator of the
  tests (``tests/calibration/foreign_sim.py``), cross-talks of 12–33 mrad/m of random signs;
- ``foreign-wrong-arm``: the same, the robot's lever arm given 13 cm off (rosy-mecanum's);
- ``twin-lissajous-imu``, ``twin-tour-imu``: the twin's cases with their gyro kept.

Per recording: the smoothed RMSE against the reference minus the truth's (``ΔRMSE``; the
reference is the commanded path for the twin's Lissajous, else the truth itself, so ΔRMSE is
then the smoothed track's own RMS error), its own 1σ (RMS), the share of samples whose error
lies inside the 1σ ellipse's 68 % region (χ²(2) ≤ 2.28: the 2-D meaning of "within 1σ"), and
the self-check; "axes in 1σ": the share of samples and axes with |error| ≤ that axis's 1σ (68 %
for an honest Gaussian σ). Per case both pooled over the recordings (68 ± 10 % is the target).

Measured (10 recordings per case; each axis within its 1σ, pooled; before the noise scales
and the lever arm, the same 8 first recordings):

==================  ==========  ============  ==================  ==============
case                before      after         inside 1σ ellipse   worst |ΔRMSE|
==================  ==========  ============  ==================  ==============
twin-lissajous      86.2 %      71.8 %        95.8 → 76.1 %       0.65 mm
twin-tour           83.2 %      69.2 %        88.0 → 68.0 %       2.48 mm
foreign-lissajous   83.0 %      63.6 %        88.2 → 60.5 %       2.25 mm
foreign-wrong-arm    2.2 %      63.6 %         0.0 → 60.5 %       94.6 → 2.25 mm
twin-lissajous-imu              73.7 %        76.7 %              0.68 mm
twin-tour-imu                   70.8 %        70.5 %              2.04 mm
==================  ==========  ============  ==================  ==============

Every check passed on these recordings (fixes' χ²/dof 0.77–0.92, 95–97 % in the band).

Run: ``.venv/bin/python bench/bench_smoother_coverage.py [--seeds 8] [--cases ...]``
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CHI2_2_68 = 2.2788
CASES = (
    "twin-lissajous",
    "twin-tour",
    "foreign-lissajous",
    "foreign-wrong-arm",
    "twin-lissajous-imu",
    "twin-tour-imu",
)


def _foreign() -> Any:
    spec = importlib.util.spec_from_file_location(
        "foreign_sim", ROOT / "tests" / "calibration" / "foreign_sim.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["foreign_sim"] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def _twin(case: str, seed: int) -> tuple[Any, Any, Any, Any]:
    """(recording without /imu, reference, lever arm, smoother params) of a twin case."""
    from omnical.experiment.script import TwistSequence, load_script
    from omnical.kinematics.correction import CorrectionFactors
    from omnical.robot.loader import load_robot
    from omnical.services.demo import LEAD_IN_S, LISSAJOUS_CENTRE_MAP_M, lissajous_smoother
    from omnical.trajectory.references import lissajous
    from omnical.trajectory.scripts import feedforward_commands
    from omnical.twin.params import default_twin
    from omnical.twin.session import simulate_run

    robot = load_robot("rosy-mecanum")
    params = default_twin(robot)
    tf = params.true_factors
    params = replace(
        params,
        true_factors=CorrectionFactors(*tf.scales, *(3 * c for c in tf.crosstalks_rad_per_m)),
    )
    smoother = lissajous_smoother(robot)  # told the odometry's stamping delay (10 ms)
    if case.startswith("twin-lissajous"):
        ref = lissajous(origin_m=LISSAJOUS_CENTRE_MAP_M)
        t, twists = feedforward_commands(ref, 50.0, limits=robot.limits)
        commands = TwistSequence.from_arrays("lissajous", t, twists, rate_hz=50.0)
        start = tuple(float(v) for v in ref.poses[0])
        rec = simulate_run(commands, robot, replace(params, start_pose_map=start), seed=seed)
        reference = (ref.t_s + LEAD_IN_S, ref.poses)
    else:
        rec = simulate_run(load_script("tour", robot.limits), robot, params, seed=seed)
        reference = None
    kept = rec if case.endswith("-imu") else rec.without("/imu")
    return kept, reference, robot.hedge_offset_m, smoother


def _foreign_case(case: str, seed: int) -> tuple[Any, Any, Any, Any]:
    fs = _foreign()
    rng = np.random.default_rng(1000 + seed)
    talks = tuple(float(v) for v in rng.uniform(0.012, 0.033, 4) * rng.choice([-1.0, 1.0], 4))
    truth = fs.ForeignTruth(crosstalks=talks)
    rec = fs.simulate(fs.lissajous, 120.0, truth, seed, ground_truth=True)
    arm = truth.hedge_offset_m if case == "foreign-lissajous" else (0.04, -0.03)
    return rec, None, arm, None


def run_one(case: str, seed: int) -> dict[str, float]:
    """One recording of ``case``: its evaluation and the smoothed track against the truth."""
    from omnical.evaluation.metrics import SMOOTHED_KEY, reference_of, track_recording

    make = _twin if case.startswith("twin") else _foreign_case
    rec, reference, arm, smoother = make(case, seed)
    truth = reference_of(rec)
    cpu0 = time.process_time()
    tracked = track_recording(
        rec.without("/ground_truth") if reference is None else rec,
        reference if reference is not None else truth,
        align="none",
        odometry_align="origin",
        hedge_offset_m=arm,
        smoother=smoother,
    )
    cpu = time.process_time() - cpu0
    sm = tracked[SMOOTHED_KEY]
    track = sm.smoothing
    assert track is not None
    check = getattr(track, "check", None)  # None: a smoother from before the self-check
    gx = np.interp(track.t_s, truth.t_s, truth.xy_m[:, 0])
    gy = np.interp(track.t_s, truth.t_s, truth.xy_m[:, 1])
    inside = (track.t_s >= truth.t_s[0]) & (track.t_s <= truth.t_s[-1])
    err = (track.poses[:, :2] - np.column_stack([gx, gy]))[inside]
    cov = track.covariance[inside, :2, :2]
    d2 = np.einsum("ni,nij,nj->n", err, np.linalg.inv(cov), err)
    axis_sigma = np.sqrt(np.stack([cov[:, 0, 0], cov[:, 1, 1]], axis=1))
    true_rmse = tracked["ground_truth"].metrics.rmse_m if reference is not None else 0.0
    return {
        "delta_rmse_m": sm.metrics.rmse_m - true_rmse,
        "error_rms_m": float(np.sqrt(np.mean(np.sum(err**2, axis=1)))),
        "sigma_rms_m": float(np.sqrt(np.mean(cov[:, 0, 0] + cov[:, 1, 1]))),
        "inside_68": float(np.mean(d2 <= CHI2_2_68)),
        "axis_68": float(np.mean(np.abs(err) <= axis_sigma)),
        "n": float(d2.size),
        "chi2": math.nan if check is None else check.fix_chi2_per_dof,
        "band": math.nan if check is None else check.fixes_in_band_95,
        "odometry_scale": math.nan if check is None else check.odometry_noise_scale,
        "fix_scale": math.nan if check is None else check.fix_noise_scale,
        "passed": math.nan if check is None else float(check.passed),
        "cpu_s": cpu,
        "multilateration_rmse_m": tracked["multilateration"].metrics.rmse_m,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    args = parser.parse_args()
    for case in args.cases:
        rows = [run_one(case, seed) for seed in range(args.seeds)]
        gyro = "with /imu" if case.endswith("-imu") else "no /imu"
        print(f"{case} ({args.seeds} recordings, {gyro})")
        print(
            "  seed  ΔRMSE mm  error mm  own 1σ mm  axes in 1σ  in 1σ ellipse  χ²/dof  in band  "
            "odo×  fix×  check"
        )
        for seed, r in enumerate(rows):
            print(
                f"  {seed:4d}  {1e3 * r['delta_rmse_m']:+8.2f}  {1e3 * r['error_rms_m']:8.2f}  "
                f"{1e3 * r['sigma_rms_m']:9.2f}  {r['axis_68']:10.2f}  {r['inside_68']:13.2f}  "
                f"{r['chi2']:6.2f}  "
                f"{r['band']:7.3f}  {r['odometry_scale']:4.2f}  {r['fix_scale']:4.2f}  "
                f"{'pass' if r['passed'] else 'FAIL'}"
            )
        n = np.array([r["n"] for r in rows])
        pooled = float(np.sum(n * np.array([r["inside_68"] for r in rows])) / np.sum(n))
        axes = float(np.sum(n * np.array([r["axis_68"] for r in rows])) / np.sum(n))
        per_run = np.array([r["axis_68"] for r in rows])
        worst = max(abs(r["delta_rmse_m"]) for r in rows)
        print(
            f"  pooled: each axis within its 1σ {100 * axes:.1f} % of the time (target 68 ± 10; "
            f"per recording {100 * per_run.min():.0f}–{100 * per_run.max():.0f} %), inside the "
            f"1σ ellipse's 68 % region {100 * pooled:.1f} %; worst |ΔRMSE| "
            f"{1e3 * worst:.2f} mm; checks passed {sum(r['passed'] for r in rows):.0f}/{len(rows)}; "
            f"CPU {np.mean([r['cpu_s'] for r in rows]):.2f} s per evaluation"
        )


if __name__ == "__main__":
    main()
