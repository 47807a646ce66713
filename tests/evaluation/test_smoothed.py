"""The smoothed estimate: trusted fixes, the report's statement, and issue 11's validation target."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from omnical.evaluation.metrics import (
    SMOOTHED_KEY,
    smoothing_summary,
    track_recording,
    trusted_fixes,
)
from omnical.ips.from_recording import locate
from omnical.ips.solve.fixes import FixStatus
from omnical.recording.recording import Recording
from omnical.reports.tracking import write_evaluation
from omnical.robot.description import RobotDescription
from omnical.services.demo import (
    LISSAJOUS_CENTRE_MAP_M,
    lissajous_run,
    lissajous_smoother,
)
from omnical.trajectory.references import lissajous
from omnical.twin.bench import run_twin_campaign
from omnical.twin.params import default_twin


def test_trusted_fixes_are_ok_and_consistent_degraded_ones(default_tour: Recording) -> None:
    fixes, _ = locate(default_tour)
    trusted = trusted_fixes(fixes)
    ok = fixes.status == FixStatus.OK
    finite = np.isfinite(fixes.positions_map_m[:, 0])
    assert np.array_equal(trusted & ok, ok & finite)
    assert not np.any(trusted & (fixes.status >= FixStatus.REJECTED))


def test_smoothed_estimate_is_reported_with_its_uncertainty_and_latency(
    default_tour: Recording, rosy: RobotDescription, tmp_path: Path
) -> None:
    tracked = track_recording(default_tour, hedge_offset_m=rosy.hedge_offset_m)
    smoothed = tracked[SMOOTHED_KEY]
    assert smoothed.smoothing is not None
    summary = smoothing_summary(smoothed)
    # the twin's IPS latency is ≈ 50 ms (10 ms + one 25 Hz period)
    assert 0.02 < summary["latency_s"] < 0.08
    assert 0.0 < summary["sigma_rms_m"] < 0.01
    # the smoothed track is far closer to the truth than the fixes it came from
    assert smoothed.metrics.rmse_m < 0.5 * tracked["multilateration"].metrics.rmse_m
    files = write_evaluation(tracked, default_tour, tmp_path, name="tour", align="se2")
    text = files.report.read_text(encoding="utf-8")
    assert "The estimate to quote is `smoothed`" in text
    assert "IPS latency found" in text and "Self-check (passed)" in text
    data = json.loads(files.metrics.read_text(encoding="utf-8"))
    assert data[SMOOTHED_KEY]["latency_s"] == pytest.approx(summary["latency_s"])
    assert "sigma_rms_m" in data[SMOOTHED_KEY]
    assert data[SMOOTHED_KEY]["converged"] == 1.0 and data[SMOOTHED_KEY]["iterations"] >= 1
    assert data[SMOOTHED_KEY]["check_passed"] == 1.0 and data[SMOOTHED_KEY]["quote"] == 1.0
    assert 0.5 < data[SMOOTHED_KEY]["check_fix_chi2_per_dof"] < 1.5
    assert data[SMOOTHED_KEY]["check_fixes_in_band_95"] > 0.9
    # a smoother that ran out of iterations is not presented as the estimate to quote (review:
    # one burst of fixes a minute over an hour gave 1.5 m RMSE with "its own 1σ" 5 cm)
    import dataclasses

    stuck = dict(tracked)
    stuck[SMOOTHED_KEY] = dataclasses.replace(
        smoothed, smoothing=dataclasses.replace(smoothed.smoothing, converged=False)
    )
    files = write_evaluation(stuck, default_tour, tmp_path / "stuck", name="tour", align="se2")
    text = files.report.read_text(encoding="utf-8")
    assert "The smoother did not converge" in text
    assert "The estimate to quote is `smoothed`" not in text
    assert json.loads(files.metrics.read_text(encoding="utf-8"))[SMOOTHED_KEY]["converged"] == 0
    # without the smoother, no smoothed entry
    assert SMOOTHED_KEY not in track_recording(default_tour, smooth=False)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])  # seed 0: tests/test_demo.py, the demo's runs
def test_sensor_based_improvement_over_seeds(rosy: RobotDescription, seed: int) -> None:
    """Issue 11 validation over several seed pairs (the demo's, seed 0, is checked on the demo
    itself in tests/test_demo.py), with what the smoother must be told
    (:func:`omnical.services.demo.lissajous_smoother`): the sensor-based Lissajous RMSE within
    5 mm of the ground truth's, before and after calibration, and the sensor-measured
    improvement within 20 % of the true one.

    Two things kept the sensor-measured improvement 13–21 % below the true one (seeds 0–7,
    default smoother): (1) the twin stamps ``/odom`` one control period (10 ms) after the
    firmware tick that computed it; from fixes and odometry only their relative latency is
    observable (≈ 41 ms found for the IPS's ≈ 52 ms), so the smoothed track lagged the truth by
    10 ms — about 1 mm more error against the reference after calibration, where the truth's is
    5–6 mm. Told the delay (``odometry_delay_s``), the worst of seeds 0–7 is +20 % (seed 5, the
    rest within ±7 %). (2) The IPS latency itself is found to ±3.5 ms from one 60 s Lissajous
    (≈ 1 700 fixes of 2 cm at 0.14 m/s): ±0.5 mm on the calibrated RMSE. The same IPS measures
    both runs, so the latency found before calibration is the prior after it: worst of seeds
    0–7 then 11 % (measured −4.1, +7.9, −2.8, +4.8 % for seeds 0–3).
    """
    params = default_twin(rosy)
    ref = lissajous(origin_m=LISSAJOUS_CENTRE_MAP_M)
    before_run = lissajous_run(rosy, params, ref, seed, "uncalibrated")
    campaign = run_twin_campaign(rosy, params, seed=seed)
    calibrated = params.with_installed(campaign.factors)
    told = lissajous_smoother(rosy, before_run)  # the latency found before: the prior after
    before = before_run.tracked
    after = lissajous_run(rosy, calibrated, ref, seed + 1, "calibrated", told).tracked
    rmse = {
        phase: {name: t.metrics.rmse_m for name, t in tracked.items()}
        for phase, tracked in (("before", before), ("after", after))
    }
    for m in rmse.values():
        assert abs(m[SMOOTHED_KEY] - m["ground_truth"]) < 0.005
    true_gain = rmse["before"]["ground_truth"] / rmse["after"]["ground_truth"]
    sensor_gain = rmse["before"][SMOOTHED_KEY] / rmse["after"][SMOOTHED_KEY]
    assert abs(sensor_gain / true_gain - 1.0) < 0.20, (sensor_gain, true_gain)
