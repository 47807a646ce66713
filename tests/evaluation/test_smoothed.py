"""The smoothed estimate: trusted fixes, the report's statement, and issue 11's validation target."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from omnical.evaluation.metrics import (
    SMOOTHED_KEY,
    smoothing_summary,
    track_recording,
    trusted_fixes,
)
from omnical.experiment.script import TwistSequence
from omnical.ips.from_recording import locate
from omnical.ips.solve import FixStatus
from omnical.recording.recording import Recording
from omnical.reports.tracking import write_evaluation
from omnical.robot import RobotDescription
from omnical.trajectory import feedforward_commands, lissajous
from omnical.twin import default_twin
from omnical.twin.bench import run_twin_campaign
from omnical.twin.params import TwinParams
from omnical.twin.session import simulate_run


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
    assert "IPS latency found" in text
    data = json.loads(files.metrics.read_text(encoding="utf-8"))
    assert data[SMOOTHED_KEY]["latency_s"] == pytest.approx(summary["latency_s"])
    assert "sigma_rms_m" in data[SMOOTHED_KEY]
    # without the smoother, no smoothed entry
    assert SMOOTHED_KEY not in track_recording(default_tour, smooth=False)


def _lissajous(robot: RobotDescription, params: TwinParams, seed: int) -> dict[str, float]:
    """The demo's open-loop Lissajous (services.demo), evaluated as the demo does."""
    ref = lissajous(origin_m=(2.9, 2.4))
    t, twists = feedforward_commands(ref, 50.0, limits=robot.limits)
    commands = TwistSequence.from_arrays("lissajous", t, twists, rate_hz=50.0)
    start = (float(ref.poses[0, 0]), float(ref.poses[0, 1]), float(ref.poses[0, 2]))
    rec = simulate_run(commands, robot, replace(params, start_pose_map=start), seed=seed)
    tracked = track_recording(
        rec,
        (ref.t_s + 1.0, ref.poses),
        align="none",
        odometry_align="origin",
        hedge_offset_m=robot.hedge_offset_m,
    )
    return {name: t.metrics.rmse_m for name, t in tracked.items()}


def test_sensor_based_lissajous_rmse_shows_the_calibration(rosy: RobotDescription) -> None:
    """Issue 11 target on the twin (default NLOS), the demo's seed 0."""
    params = default_twin(rosy)
    before = _lissajous(rosy, params, 0)
    campaign = run_twin_campaign(rosy, params, seed=0)
    after = _lissajous(rosy, params.with_installed(campaign.factors), 1)
    for m in (before, after):
        assert abs(m[SMOOTHED_KEY] - m["ground_truth"]) < 0.005
    true_gain = before["ground_truth"] / after["ground_truth"]
    sensor_gain = before[SMOOTHED_KEY] / after[SMOOTHED_KEY]
    assert abs(sensor_gain / true_gain - 1.0) < 0.20
