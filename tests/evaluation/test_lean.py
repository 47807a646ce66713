"""The lean evaluation of a long run (issue "Scale"): the recording handed over and its tables
let go once used, every estimate reduced to what the figures draw, the smoother's fixes
linearised a run of intervals at a time — and the same numbers as the in-memory path. Each
bound is shrunk here (``FIGURE_ROWS``, ``_FIX_CHUNKED``, ``_CHUNK``) so a short twin run takes
every one of these paths."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from omnical.choices import AlignMode
from omnical.errors import GeometryError
from omnical.estimation import smoother as smoother_module
from omnical.estimation.handover import Handover, taken
from omnical.estimation.smoother import SmootherParams, smooth_track
from omnical.evaluation import metrics
from omnical.evaluation.metrics import (
    GROUND_TRUTH_KEY,
    SMOOTHED_KEY,
    figure_rows,
    let_go,
    track_recording,
)
from omnical.recording.recording import Recording
from omnical.recording.topics import BEACON_RAW_DISTANCE, CMD_VEL, IMU, ODOM, START
from omnical.reports import evaluate as evaluate_module
from omnical.robot.description import RobotDescription


def test_handover_is_taken_once() -> None:
    hand = Handover(np.arange(3.0))
    np.testing.assert_array_equal(taken(hand), [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="taken already"):
        hand.take()
    plain = np.ones(2)
    assert taken(plain) is plain


def test_letting_go_of_the_topic_that_starts_a_run_keeps_its_start(
    default_tour: Recording,
) -> None:
    start = default_tour.start_ns
    first = next(n for n in default_tour.topics if default_tour.topic(n).t_ns[0] == start)
    rest = let_go(default_tour, first)
    assert first not in rest.topics and rest.start_ns == start
    starts = {n: int(default_tour.topic(n).t_ns[0]) for n in default_tour.topics}
    if sum(v == start for v in starts.values()) == 1:  # it alone started the run
        assert len(rest.topic(START)) == 1 and rest.topic(START).names == ()
    assert let_go(default_tour, "/not/there") is default_tour


def test_figure_rows_keep_every_extreme_and_the_ends() -> None:
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(size=50_000))
    y = np.sin(np.arange(50_000) / 700.0)
    rows = figure_rows((x, y), 2_000)
    assert rows[0] == 0 and rows[-1] == x.size - 1
    assert np.all(np.diff(rows) > 0)
    assert 2_000 <= rows.size <= 2_000 + 4 * 1_000 + 1
    assert x.argmax() in rows and x.argmin() in rows and y.argmax() in rows
    np.testing.assert_array_equal(figure_rows((x[:100], y[:100]), 2_000), np.arange(100))


def _same_results(
    full: dict[str, metrics.Tracked], lean: dict[str, metrics.Tracked], *, exact: bool
) -> None:
    assert list(lean) == list(full)
    for name, a in full.items():
        b = lean[name]
        if exact:
            assert b.metrics == a.metrics, name
            assert b.sigma_rms_m == a.sigma_rms_m, name
        else:
            for key in metrics.METRIC_KEYS:
                assert getattr(b.metrics, key) == pytest.approx(getattr(a.metrics, key), rel=1e-9)
            assert b.metrics.n == a.metrics.n
        assert len(b.association) <= len(a.association)
        assert len(b.alignment.xy_m) == len(b.association)
        if a.smoothing is not None:
            assert b.smoothing is not None
            assert b.smoothing.latency_s == pytest.approx(a.smoothing.latency_s, rel=1e-9)
            assert metrics.smoothing_summary(b) == pytest.approx(
                metrics.smoothing_summary(a), rel=1e-9
            )


def test_lean_tracking_measures_what_the_in_memory_one_does(
    default_tour: Recording, rosy: RobotDescription, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Estimates one at a time, reduced to 500 rows for the figures, tables let go: the same
    measures, bit for bit, and the own 1σ of every sample."""
    full = track_recording(default_tour, hedge_offset_m=rosy.hedge_offset_m)
    monkeypatch.setattr(metrics, "FIGURE_ROWS", 500)
    lean = track_recording(Handover(default_tour), hedge_offset_m=rosy.hedge_offset_m, lean=True)
    _same_results(full, lean, exact=True)
    odometry = lean["odometry"]
    assert len(odometry.association) < len(full["odometry"].association)
    assert 500 <= len(odometry.association) <= 500 + 4 * 1000 + 1
    assert lean[SMOOTHED_KEY].smoothing is not None
    assert len(lean[SMOOTHED_KEY].smoothing.t_s) == len(lean[SMOOTHED_KEY].association)
    # the ground truth as the reference: evaluated only when nothing else is
    alone = track_recording(
        Handover(default_tour), smooth=False, ground_truth_alone=True, lean=True
    )
    assert GROUND_TRUTH_KEY not in alone and "odometry" in alone


def test_fixes_linearised_with_their_intervals_give_the_same_track(
    default_tour: Recording, rosy: RobotDescription, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The fixes taken a run of 64 intervals at a time (as above 32,768 fixes), on the
    full-rate and the keyframe paths: the same track to rounding, the same measures to 1e-9."""
    od = default_tour.topic(ODOM)
    t0 = default_tour.start_ns
    odom = np.column_stack([od.t_s(t0), od["x_m"], od["y_m"], od["yaw_rad"]])
    imu = default_tour.topic(IMU)
    gyro = np.column_stack([imu.t_s(t0), imu["gyro_z_radps"]])
    fixed = metrics._fixes_trajectory(metrics.locate(default_tour)[0], t0)
    assert fixed is not None and fixed.covariance_xy_m2 is not None
    base = SmootherParams(hedge_offset_m=tuple(rosy.hedge_offset_m[:2]))
    for params in (base, replace(base, long_run_s=10.0)):
        args = (fixed.t_s, fixed.xy_m, fixed.covariance_xy_m2)
        whole = smooth_track(params, odom, *args, gyro=gyro)
        with monkeypatch.context() as m:
            m.setattr(smoother_module, "_FIX_CHUNKED", 100)
            m.setattr(smoother_module, "_CHUNK", 64)
            parts = smooth_track(params, Handover(odom.copy()), *args, gyro=Handover(gyro.copy()))
        assert parts.iterations == whole.iterations and parts.fixes_used == whole.fixes_used
        assert parts.fixes_downweighted == whole.fixes_downweighted
        np.testing.assert_allclose(parts.poses, whole.poses, rtol=0, atol=1e-9)
        np.testing.assert_allclose(parts.shared, whole.shared, rtol=1e-7, atol=1e-12)
        assert parts.fix_residual_rms_m == pytest.approx(whole.fix_residual_rms_m, rel=1e-9)
        assert parts.position_sigma_rms_m == pytest.approx(whole.position_sigma_rms_m, rel=1e-9)


def test_cli_lean_path_writes_the_same_metrics(
    default_tour: Recording, rosy: RobotDescription, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``_evaluate_and_write`` as a long run takes it (speeds for the figures first, the rest
    handed over and let go, 300 rows per estimate): the same metrics.json, figures written."""
    common = {
        "reference": None,
        "align": AlignMode.SE2,
        "hedge_offset_m": rosy.hedge_offset_m,
        "drop_ground_truth": True,
    }
    full, _ = evaluate_module._evaluate_and_write(
        [default_tour], "tour", tmp_path / "full", **common
    )
    monkeypatch.setattr(metrics, "FIGURE_ROWS", 300)
    lean, figures = evaluate_module._evaluate_and_write(
        [default_tour], "tour", tmp_path / "lean", **common, lean=True
    )
    assert figures == 3
    assert (tmp_path / "lean" / "metrics.json").read_text() == (
        tmp_path / "full" / "metrics.json"
    ).read_text()
    _same_results(dict(full), dict(lean), exact=True)
    drawn = evaluate_module._for_figures(default_tour, lean=True)
    assert drawn.start_ns == default_tour.start_ns
    assert drawn.topic(ODOM).names == ("vx_mps", "vy_mps", "wz_radps")
    assert len(drawn.topic(ODOM)) < len(default_tour.topic(ODOM))
    cmd, kept = default_tour.topic(CMD_VEL), drawn.topic(CMD_VEL)
    changes = np.flatnonzero(
        np.any(np.diff(np.column_stack([cmd["vx_mps"], cmd["wz_radps"]]), axis=0) != 0, axis=1)
    )
    assert np.isin(cmd.t_ns[changes + 1], kept.t_ns).all()  # every step of the commands kept
    tracking = evaluate_module._for_tracking(default_tour)
    assert CMD_VEL not in tracking.topics and tracking.start_ns == default_tour.start_ns
    assert tracking.topic(ODOM).names == ("x_m", "y_m", "yaw_rad")
    assert tracking.has(BEACON_RAW_DISTANCE)


def test_odometry_asked_for_again_for_the_bridge(
    default_tour: Recording, rosy: RobotDescription
) -> None:
    """On the keyframe path, an odometry given as a function is asked for again (at set-up,
    for each further round of the noise scales, and for the bridge) rather than held: the same
    track, bit for bit; a different one at the bridge is refused."""
    od = default_tour.topic(ODOM)
    t0 = default_tour.start_ns
    odom = np.column_stack([od.t_s(t0), od["x_m"], od["y_m"], od["yaw_rad"]])
    fixed = metrics._fixes_trajectory(metrics.locate(default_tour)[0], t0)
    assert fixed is not None and fixed.covariance_xy_m2 is not None
    params = SmootherParams(long_run_s=10.0)
    args = (fixed.t_s, fixed.xy_m, fixed.covariance_xy_m2)
    held = smooth_track(params, odom, *args)
    calls: list[int] = []

    def again() -> np.ndarray:
        calls.append(1)
        return odom

    asked = smooth_track(params, again, *args)
    assert asked.check is not None and asked.check.rounds >= 2  # the noise scales took rounds
    assert len(calls) == asked.check.rounds + 1 and asked.keyframe_stride > 1
    np.testing.assert_array_equal(asked.poses, held.poses)
    np.testing.assert_array_equal(asked.covariance, held.covariance)
    np.testing.assert_array_equal(asked.t_s, held.t_s)
    answers = iter([odom] * asked.check.rounds + [odom[:-50]])
    with pytest.raises(GeometryError, match="not the one smoothed"):
        smooth_track(params, lambda: next(answers), *args)


def test_lean_tracking_against_an_external_reference(
    default_tour: Recording, rosy: RobotDescription, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A reference of its own (the truth moved, as a motion-capture file would give it): the
    ground truth is then an estimate like the others; with and without the smoother."""
    truth = metrics.reference_of(default_tour)
    moved = metrics.Trajectory(
        truth.t_s, truth.xy_m + np.array([1.5, -2.0]), truth.yaw_rad, "mocap"
    )
    monkeypatch.setattr(metrics, "FIGURE_ROWS", 700)
    for smooth in (True, False):
        common = {"hedge_offset_m": rosy.hedge_offset_m, "smooth": smooth}
        full = track_recording(default_tour, moved, **common)
        lean = track_recording(Handover(default_tour), moved, lean=True, **common)
        assert GROUND_TRUTH_KEY in lean and (SMOOTHED_KEY in lean) == smooth
        _same_results(full, lean, exact=True)
