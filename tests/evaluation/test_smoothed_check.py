"""Issue 29: the smoothed track on recordings without ``/imu`` and with large cross-talk, its own
1σ, and its self-check — passed where the model explains the fixes, failed (and said so by
``omnical evaluate``) where it does not."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from omnical.bags.bag import write_bag
from omnical.cli.main import app
from omnical.estimation.se2 import between_poses
from omnical.estimation.smoother import SmootherParams
from omnical.evaluation.metrics import (
    GROUND_TRUTH_KEY,
    SMOOTHED_KEY,
    reference_of,
    smoothing_summary,
    track_recording,
)
from omnical.experiment.script import TwistSequence
from omnical.kinematics.correction import CorrectionFactors
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import GROUND_TRUTH
from omnical.robot.description import RobotDescription
from omnical.services.demo import LEAD_IN_S, LISSAJOUS_CENTRE_MAP_M, lissajous_smoother
from omnical.trajectory.references import lissajous
from omnical.trajectory.scripts import feedforward_commands
from omnical.twin.params import default_twin
from omnical.twin.session import simulate_run

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "calibration"))
import foreign_sim as fs

ROSY_ARM = (0.04, -0.03)
"""rosy-mecanum's lever arm: 13 cm from the independent simulator's (−0.06, 0.05)."""


@pytest.fixture(scope="module")
def foreign() -> Recording:
    """Two minutes of a turning Lissajous on the independent simulator: cross-talks of 12 to
    33 mrad/m, no /imu (its truth as /ground_truth, for the test only)."""
    truth = fs.ForeignTruth(crosstalks=(0.012, -0.02, 0.033, -0.025))
    return fs.simulate(fs.lissajous, 120.0, truth, 0, ground_truth=True)


def test_foreign_lissajous_without_gyro_and_a_wrong_lever_arm(foreign: Recording) -> None:
    """The user's case: no gyro, cross-talk up to 33 mrad/m, the robot's lever arm 13 cm off.
    The smoother finds the arm, tracks the truth within 5 mm with an own 1σ of the error's
    size, and its check passes; held at the wrong arm (the former model) the track is
    centimetres off and the check says so."""
    truth = reference_of(foreign)
    run = foreign.without(GROUND_TRUTH)
    common = {"align": "none", "odometry_align": "origin", "hedge_offset_m": ROSY_ARM}
    found = track_recording(run, truth, **common)[SMOOTHED_KEY]
    error, sigma = found.metrics.rmse_m, float(found.sigma_rms_m or 0.0)  # against the truth
    assert error < 0.005
    assert 0.6 < error / sigma < 1.6  # was 93 mm against an own 1σ of 2.9 mm
    assert found.smoothing is not None and found.smoothing.check is not None
    assert found.smoothing.check.passed and found.smoothing.trustworthy
    assert np.hypot(*np.subtract(found.smoothing.hedge_offset_m, (-0.06, 0.05))) < 0.005
    held = track_recording(
        run, truth, smoother=SmootherParams(estimate_hedge_offset=False), **common
    )[SMOOTHED_KEY]
    assert held.smoothing is not None and held.smoothing.check is not None
    assert held.metrics.rmse_m > 0.05 and not held.smoothing.check.passed
    assert any("odometry" in why for why in held.smoothing.check.reasons)
    assert smoothing_summary(held)["quote"] == 0.0 and smoothing_summary(found)["quote"] == 1.0


def test_twin_lissajous_without_gyro_and_cross_talk_tripled(rosy: RobotDescription) -> None:
    """Seed 000's Lissajous on the twin with its cross-talks ×3 and the gyro topic removed:
    the smoothed RMSE against the reference within 5 mm of the truth's, the check passed."""
    params = default_twin(rosy)
    tf = params.true_factors
    params = replace(
        params,
        true_factors=CorrectionFactors(*tf.scales, *(3 * c for c in tf.crosstalks_rad_per_m)),
    )
    ref = lissajous(origin_m=LISSAJOUS_CENTRE_MAP_M)
    t, twists = feedforward_commands(ref, 50.0, limits=rosy.limits)
    commands = TwistSequence.from_arrays("lissajous", t, twists, rate_hz=50.0)
    start = (float(ref.poses[0, 0]), float(ref.poses[0, 1]), float(ref.poses[0, 2]))
    rec = simulate_run(commands, rosy, replace(params, start_pose_map=start), seed=1)
    tracked = track_recording(
        rec.without("/imu"),
        (ref.t_s + LEAD_IN_S, ref.poses),
        align="none",
        odometry_align="origin",
        hedge_offset_m=rosy.hedge_offset_m,
        smoother=lissajous_smoother(rosy),
    )
    sm = tracked[SMOOTHED_KEY]
    assert abs(sm.metrics.rmse_m - tracked[GROUND_TRUTH_KEY].metrics.rmse_m) < 0.005
    assert sm.smoothing is not None and sm.smoothing.check is not None
    assert sm.smoothing.check.passed
    assert 0.0 < float(sm.sigma_rms_m or 0.0) < 0.005


def _odometry_scaled_after(rec: Recording, factor_x: float, after: float = 0.5) -> Recording:
    """``rec`` with its odometry's forward increments ``factor_x`` times too long from
    ``after`` of the run on (a wheel changing mid-run: one scale cannot fit both halves)."""
    od = rec.topic("/odom")
    p = np.column_stack([od["x_m"], od["y_m"], np.unwrap(od["yaw_rad"])])
    inc = between_poses(p[:-1], p[1:])
    inc[:, 2] = np.diff(p[:, 2])
    inc[int(after * inc.shape[0]) :, 0] *= factor_x
    q = np.empty_like(p)
    q[0] = p[0]
    for k, d in enumerate(inc):
        c, s = np.cos(q[k, 2]), np.sin(q[k, 2])
        q[k + 1] = (q[k, 0] + c * d[0] - s * d[1], q[k, 1] + s * d[0] + c * d[1], q[k, 2] + d[2])
    columns = {n: od[n] for n in od.names}
    columns.update(x_m=q[:, 0], y_m=q[:, 1], yaw_rad=np.angle(np.exp(1j * q[:, 2])))
    return rec.with_table("/odom", Table(od.t_ns, columns))


def test_evaluate_says_when_the_smoothed_track_fails_its_check(
    foreign: Recording, tmp_path: Path
) -> None:
    """An odometry whose forward scale changes by 15 % half-way: the smoother can only fit the
    fixes with an odometry many times noisier than modelled; ``omnical evaluate`` prints the
    failed check, does not call the smoothed track the estimate to quote, and writes the check
    to metrics.json."""
    bag = tmp_path / "changing"
    write_bag(_odometry_scaled_after(foreign, 1.15), bag)
    out = tmp_path / "ev"
    result = CliRunner().invoke(
        app, ["evaluate", str(bag), "--no-figures", "--out", str(out)], env={"COLUMNS": "200"}
    )
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert "smoothed self-check:" in text and "FAILED" in text
    assert "fails its self-check" in text and "nor its own 1σ is the estimate to quote" in text
    data = json.loads((out / "metrics.json").read_text(encoding="utf-8"))[SMOOTHED_KEY]
    assert data["check_passed"] == 0.0 and data["quote"] == 0.0
    assert data["check_odometry_noise_scale"] > 3.0
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "fails its self-check" in report
    assert "The estimate to quote is `smoothed`" not in report
