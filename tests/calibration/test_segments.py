"""Segmentation of a run into stand-stills and moves from ``/cmd_vel`` alone."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from numpy.typing import NDArray

from omnical.calibration.procedures.segments import Segment, segment_commands, segment_mask, settled
from omnical.errors import CalibrationError
from omnical.experiment.script import parse_script
from omnical.robot.loader import load_robot

RATE_HZ = 50.0
DT = 1.0 / RATE_HZ

# (duration_s, twist at the plateau; zero for a stand-still)
Step = tuple[float, tuple[float, float, float]]


def commands(
    steps: list[Step], ramp_s: float = 0.5, t0_s: float = 100.0
) -> tuple[NDArray[np.float64], NDArray[np.float64], list[tuple[float, float]]]:
    """Sample a sequence of trapezoidal moves at 50 Hz; returns t (N,), twist (N, 3), bounds."""
    bounds = []
    start = t0_s
    for duration, _ in steps:
        bounds.append((start, start + duration))
        start += duration
    t = np.arange(t0_s, start + 0.5 * DT, DT)
    twist = np.zeros((len(t), 3))
    for (duration, peak), (a, b) in zip(steps, bounds, strict=True):
        inside = (t > a) & (t < b)
        tau = t[inside] - a
        fraction = np.minimum(1.0, np.minimum(tau, duration - tau) / ramp_s)
        twist[inside] = np.outer(fraction, peak)
    return t, twist, bounds


STILL = (0.0, 0.0, 0.0)
ROTATION_PROCEDURE: list[Step] = [
    (3.0, STILL),
    (10.0, (0.2, 0.0, 0.0)),
    (3.0, STILL),
    (3 * 2 * math.pi / 0.6 + 0.5, (0.0, 0.0, 0.6)),  # three turns at 0.6 rad/s, 0.5 s ramps
    (3.0, STILL),
    (10.0, (-0.2, 0.0, 0.0)),
    (3.0, STILL),
]
KINDS = ["still", "forward", "still", "rotate_ccw", "still", "reverse", "still"]


def test_rotation_procedure_segments_exactly() -> None:
    t, twist, bounds = commands(ROTATION_PROCEDURE)
    segments = segment_commands(t, *twist.T)
    assert [s.kind for s in segments] == KINDS
    assert [s.direction for s in segments] == [0, 1, 0, 1, 0, -1, 0]
    for seg, (a, b) in zip(segments, bounds, strict=True):
        # a move starts at its first sample above the tolerance, within two ticks of the step
        assert abs(seg.t_start_s - a) <= 2 * DT
        assert abs(seg.t_end_s - b) <= 2 * DT
    for before, after in itertools.pairwise(segments):
        assert before.t_end_s == after.t_start_s
    assert segments[0].truncated_start and segments[-1].truncated_end
    assert not any(s.truncated_start or s.truncated_end for s in segments[1:-1])
    # the commanded distance and angle: plateau minus one ramp
    assert segments[1].commanded_integral == pytest.approx((0.2 * 9.5, 0.0, 0.0), abs=1e-4)
    assert segments[3].commanded_integral[2] == pytest.approx(6.0 * math.pi, rel=1e-4)
    assert segments[5].commanded_integral[0] == pytest.approx(-1.9, rel=1e-4)


def test_motion_script_of_the_runner_segments_at_its_steps() -> None:
    limits = load_robot("rosy-mecanum").limits
    script = parse_script(
        {
            "steps": [
                {"hold": {"duration_s": 3}},
                {"move": {"vy_mps": 0.2, "distance_m": 2.0}},
                {"hold": {"duration_s": 2}},
                {"move": {"wz_radps": -0.6, "angle_deg": 720}},
                {"hold": {"duration_s": 2}},
                {"move": {"vy_mps": -0.2, "distance_m": 2.0}},
                {"hold": {"duration_s": 3}},
            ]
        },
        limits,
    )
    t = np.arange(0.0, script.duration_s + 0.5 * DT, DT)
    twist = np.array([script.twist_at(x) for x in t])
    segments = segment_commands(t, *twist.T)
    assert [s.kind for s in segments] == [
        "still", "left", "still", "rotate_cw", "still", "right", "still"
    ]  # fmt: skip
    for seg, step in zip(segments, script.steps, strict=True):
        assert abs(seg.t_start_s - step.start_s) <= DT + 1e-9
        assert abs(seg.t_end_s - step.end_s) <= DT + 1e-9
    assert segments[1].commanded_integral[1] == pytest.approx(2.0, rel=1e-3)
    assert segments[3].commanded_integral[2] == pytest.approx(-4.0 * math.pi, rel=1e-3)


def test_jitter_below_the_tolerance_changes_nothing() -> None:
    t, twist, _ = commands(ROTATION_PROCEDURE)
    clean = segment_commands(t, *twist.T)
    rng = np.random.default_rng(5)
    noisy = twist + rng.uniform(-1.5e-3, 1.5e-3, size=twist.shape)
    jittered = segment_commands(t, *noisy.T)
    assert [s.kind for s in jittered] == KINDS
    for a, b in zip(clean, jittered, strict=True):
        assert abs(a.t_start_s - b.t_start_s) <= DT + 1e-9
        assert abs(a.t_end_s - b.t_end_s) <= DT + 1e-9
    # a larger jitter needs a larger tolerance
    noisier = twist + rng.uniform(-8e-3, 8e-3, size=twist.shape)
    assert [s.kind for s in segment_commands(t, *noisier.T)] != KINDS
    tolerant = segment_commands(
        t, *noisier.T, linear_tol_mps=0.01, angular_tol_radps=0.01, min_still_s=1.0
    )
    assert [s.kind for s in tolerant] == KINDS


def test_crosstalk_compensation_keeps_a_translation_pure() -> None:
    t, twist, _ = commands([(2.0, STILL), (10.0, (0.0, -0.3, 0.0)), (2.0, STILL)])
    twist[:, 2] = 0.0277 * np.abs(twist[:, 1])  # injected yaw rate, a few mrad/s
    segments = segment_commands(t, *twist.T)
    assert [s.kind for s in segments] == ["still", "right", "still"]


def test_diagonal_and_combined_moves_are_mixed() -> None:
    t, twist, _ = commands(
        [(2.0, STILL), (5.0, (0.2, 0.2, 0.0)), (2.0, STILL), (5.0, (0.2, 0.0, 0.5)), (2.0, STILL)]
    )
    segments = segment_commands(t, *twist.T)
    assert [(s.kind, s.direction) for s in segments] == [
        ("still", 0), ("mixed", 0), ("still", 0), ("mixed", 0), ("still", 0)
    ]  # fmt: skip


def test_dropout_inside_a_move_is_merged() -> None:
    t, twist, bounds = commands([(2.0, STILL), (10.0, (0.2, 0.0, 0.0)), (2.0, STILL)])
    mid = len(t) // 2
    twist[mid : mid + 3] = 0.0  # the command drops to zero for 60 ms
    segments = segment_commands(t, *twist.T)
    assert [s.kind for s in segments] == ["still", "forward", "still"]
    assert abs(segments[1].t_end_s - bounds[1][1]) <= 2 * DT
    assert segments[1].commanded_integral[0] == pytest.approx(0.2 * 9.5 - 0.2 * 3 * DT, rel=1e-6)


def test_short_pause_between_different_moves_belongs_to_no_segment() -> None:
    t, twist, _ = commands(
        [(2.0, STILL), (5.0, (0.2, 0.0, 0.0)), (0.5, STILL), (5.0, (-0.2, 0.0, 0.0)), (2.0, STILL)]
    )
    segments = segment_commands(t, *twist.T)
    assert [s.kind for s in segments] == ["still", "forward", "reverse", "still"]
    gap = segments[2].t_start_s - segments[1].t_end_s
    assert gap == pytest.approx(0.5, abs=DT + 1e-9)
    # with a shorter threshold the pause is a stand-still of its own
    kinds = [s.kind for s in segment_commands(t, *twist.T, min_still_s=0.3)]
    assert kinds == ["still", "forward", "still", "reverse", "still"]


def test_direction_reversal() -> None:
    t = np.arange(0.0, 10.0, DT)
    vx = 0.2 * np.sin(2.0 * np.pi * t / 10.0)  # forward, then reverse through one zero sample
    segments = segment_commands(t, vx, np.zeros_like(t), np.zeros_like(t))
    assert [s.kind for s in segments] == ["forward", "reverse"]
    assert segments[0].t_end_s == pytest.approx(5.0)  # the one zero sample
    assert segments[1].t_start_s == pytest.approx(5.0 + DT)
    wobble = 0.2 + 0.1 * np.sin(2.0 * np.pi * t)  # never zero, but turns around in vy
    both = segment_commands(
        t, np.zeros_like(t), np.where(t < 5.0, -1.0, 1.0) * wobble, np.zeros_like(t)
    )
    assert [s.kind for s in both] == ["mixed"]


def test_recording_starting_mid_motion_and_never_stopping() -> None:
    t, twist, _ = commands(ROTATION_PROCEDURE)
    cut = (t > 105.0) & (t < 120.0)  # starts during the forward move, ends during the turns
    segments = segment_commands(t[cut], *twist[cut].T)
    assert [s.kind for s in segments] == ["forward", "still", "rotate_ccw"]
    assert segments[0].truncated_start and not segments[0].truncated_end
    assert segments[0].t_start_s == t[cut][0]
    assert segments[-1].truncated_end and not segments[-1].truncated_start
    assert segments[-1].t_end_s == t[cut][-1]


def test_commands_published_only_on_change_hold_until_the_next() -> None:
    t = np.array([0.0, 5.0, 10.0, 15.0])
    segments = segment_commands(t, [0.0, 0.3, 0.0, 0.0], [0.0] * 4, [0.0] * 4)
    assert [(s.kind, s.t_start_s, s.t_end_s) for s in segments] == [
        ("still", 0.0, 5.0), ("forward", 5.0, 10.0), ("still", 10.0, 15.0)
    ]  # fmt: skip
    assert segments[1].commanded_integral == (1.5, 0.0, 0.0)


def test_trivial_inputs() -> None:
    assert segment_commands([], [], [], []) == []
    t = np.arange(0.0, 0.5, DT)
    zero = np.zeros_like(t)
    assert segment_commands(t, zero, zero, zero) == []  # a pause shorter than min_still_s
    t = np.arange(0.0, 5.0, DT)
    zero = np.zeros_like(t)
    (only,) = segment_commands(t, zero, zero, zero)
    assert only.kind == "still"
    assert only.duration_s == pytest.approx(t[-1])
    (one,) = segment_commands([0.0], [0.1], [0.0], [0.0])
    assert (one.kind, one.duration_s, one.truncated_start, one.truncated_end) == (
        "forward", 0.0, True, True
    )  # fmt: skip


@pytest.mark.parametrize(
    ("t", "vx", "match"),
    [
        ([0.0, 1.0, 2.0], [0.0, 0.0], "one length"),
        ([[0.0, 1.0]], [[0.0, 1.0]], "one length"),
        ([0.0, 2.0, 1.0], [0.0, 0.0, 0.0], "non-decreasing"),
        ([0.0, 1.0, 2.0], [0.0, np.nan, 0.0], "non-finite"),
    ],
)
def test_invalid_commands(t: list[float], vx: list[float], match: str) -> None:
    n = np.shape(t)
    with pytest.raises(CalibrationError, match=match):
        segment_commands(t, vx, np.zeros(n), np.zeros(n))


def test_invalid_options() -> None:
    t = np.arange(3.0)
    with pytest.raises(CalibrationError, match="mixed_ratio"):
        segment_commands(t, t, t, t, mixed_ratio=0.5)
    with pytest.raises(CalibrationError, match="min_still_s"):
        segment_commands(t, t, t, t, min_still_s=-1.0)


def test_settled_trims_the_start_of_a_stand_still() -> None:
    still = Segment("still", 10.0, 13.0, 0, truncated_start=True)
    trimmed = settled(still, 0.8)
    assert (trimmed.t_start_s, trimmed.t_end_s) == (10.8, 13.0)
    assert trimmed.duration_s == pytest.approx(2.2)
    assert not trimmed.truncated_start
    assert settled(still, 0.0) == still
    with pytest.raises(CalibrationError, match="not more than"):
        settled(still, 3.0)
    with pytest.raises(CalibrationError, match="≥ 0"):
        settled(still, -0.1)
    with pytest.raises(CalibrationError, match="only a still"):
        settled(Segment("forward", 0.0, 10.0, 1), 0.5)


def test_segment_mask_selects_samples_of_another_stream() -> None:
    t, twist, _ = commands(ROTATION_PROCEDURE)
    forward = segment_commands(t, *twist.T)[1]
    t_ips = np.arange(100.0, 140.0, 1.0 / 8.0)  # IPS fixes at 8 Hz
    mask = segment_mask(t_ips, forward)
    assert mask.dtype == np.bool_
    assert t_ips[mask][0] >= forward.t_start_s
    assert t_ips[mask][-1] <= forward.t_end_s
    assert int(mask.sum()) == pytest.approx(8 * forward.duration_s, abs=1)
