"""Real data is the judge: the smoothed track on the TU Chemnitz labyrinth (a small
differential-drive robot's wheel speeds and one UWB range at a time, with its truth) says
whether it is the estimate to quote, and is right about it."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from omnical.evaluation.association import Trajectory
from omnical.evaluation.metrics import MULTILATERATION_KEY, SMOOTHED_KEY, track_recording
from omnical.recording.recording import Recording, RecordingBuilder

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "ips"))
import uwb_bags as uwb


def _labyrinth() -> tuple[Recording, Trajectory]:
    """The run with ``/odom`` dead-reckoned from its wheel speeds, and its truth."""
    run = uwb.tuc_run()
    path = uwb.tuc_dir() / "odometry.csv"
    if not path.is_file():
        pytest.skip("the TU Chemnitz odometry is in the shared datasets only")
    names, od = uwb._csv(path)
    t = od[:, names.index("t_s")]
    right, left = od[:, names.index("v_right_mps")], od[:, names.index("v_left_mps")]
    speed = 0.5 * (right + left)
    rate = (right - left) / od[:, names.index("wheel_base_m")]
    dt = np.diff(t, prepend=t[0])
    yaw = np.cumsum(rate * dt)
    builder = RecordingBuilder()
    builder.add_many(
        "/odom",
        run.t_ns[0] + np.round((t - t[0]) * 1e9).astype(np.int64),
        x_m=np.cumsum(speed * np.cos(yaw) * dt),
        y_m=np.cumsum(speed * np.sin(yaw) * dt),
        yaw_rad=np.angle(np.exp(1j * yaw)),
        vx_mps=speed,
        vy_mps=np.zeros_like(speed),
        wz_radps=rate,
    )
    rec = Recording({**run.recording.tables, **builder.build().tables})
    t_truth = (run.t_ns - rec.start_ns).astype(np.float64) / 1e9
    return rec, Trajectory(t_truth, run.truth_xy_m, None, "map")


def test_the_smoothed_track_on_real_data_is_right_about_itself() -> None:
    """Its odometry (wheel speeds at 7.8 Hz of a robot 8 cm wide, 52 rad of turning in 30 s)
    is far noisier than the model: the smoothed track is not an estimate to quote, and it says
    so (it claimed a 2 cm 1σ at 0.60 m RMSE before it checked itself). Whatever it says, its
    claim must hold: trustworthy only if its RMSE is within 3 of its own 1σ."""
    rec, truth = _labyrinth()
    tracked = track_recording(rec, truth, align="none", hedge_offset_m=(0.0, 0.0))
    sm = tracked[SMOOTHED_KEY]
    assert sm.smoothing is not None and sm.smoothing.check is not None
    error, sigma = sm.metrics.rmse_m, float(sm.sigma_rms_m or 0.0)
    assert not sm.smoothing.trustworthy or error <= 3.0 * sigma  # (now: 1.1 m, not trusted)
    assert tracked[MULTILATERATION_KEY].metrics.rmse_m < 0.25


def test_evaluate_says_a_failed_self_checks_latency_is_not_to_be_used(tmp_path: Path) -> None:
    """Found by a new user: on this run `omnical evaluate` printed 'IPS latency -1576 ± 138
    ms' as if it were found; the line now says the self-check failed, and that a negative
    latency is impossible."""
    from typer.testing import CliRunner

    from omnical.bags.bag import write_bag
    from omnical.cli.main import app

    rec, truth = _labyrinth()
    bag = write_bag(rec, tmp_path / "tuc.mcap")
    ref = tmp_path / "tuc.csv"
    rows = [f"{t:.6f},{x:.4f},{y:.4f}" for t, (x, y) in zip(truth.t_s, truth.xy_m, strict=True)]
    ref.write_text("t_s,x_m,y_m\n" + "\n".join(rows) + "\n", encoding="utf-8")
    robot = tmp_path / "tag.yaml"
    robot.write_text("base: rosy-mecanum\nhedge_offset_m: [0, 0, 0.965]\n", encoding="utf-8")
    result = CliRunner().invoke(
        app,
        ["evaluate", str(bag), "--robot", str(robot), "--reference-file", str(ref),
         "--align", "none", "--no-figures", "--out", str(tmp_path / "ev")],
    )  # fmt: skip
    text = " ".join(result.output.split())
    assert result.exit_code == 0, result.output
    assert "; the self-check failed: neither is to be used" in text
    latency, sigma = (float(v) for v in text.split("IPS latency ")[1].split(" ")[0:3:2])
    assert (latency + 2 * sigma < 0) == ("(negative: no IPS reports before it measures)" in text)
