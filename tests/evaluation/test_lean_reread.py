"""A long recording evaluated with less held at once (issue "Scale", session 7): omnical's
multilateration located from what it reads alone, before the other tables are read; the
truth and the vendor IPS let go through the smoothing and read again after it — the same
tables, fixes and measures, bit for bit."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from omnical.bags.bag import write_bag
from omnical.estimation.smoother import SmootherParams
from omnical.evaluation import metrics
from omnical.evaluation.metrics import Handover, track_recording
from omnical.ips.from_recording import locate
from omnical.recording.recording import Recording
from omnical.recording.topics import (
    BEACON_RAW_DISTANCE,
    BEACONS_POS_A,
    CMD_VEL,
    EVALUATED,
    GROUND_TRUTH,
    HEDGE_POS_ANG,
    IMU,
    ODOM,
)
from omnical.reports.evaluate import _read_located, _read_slim
from omnical.robot.description import RobotDescription

TOPICS = EVALUATED  # what `omnical evaluate` reads


def _same(full: dict[str, metrics.Tracked], lean: dict[str, metrics.Tracked]) -> None:
    assert list(lean) == list(full)
    for name, a in full.items():
        b = lean[name]
        assert b.metrics == a.metrics, name
        assert b.sigma_rms_m == a.sigma_rms_m, name
        assert metrics.smoothing_summary(b) == metrics.smoothing_summary(a), name


@pytest.mark.parametrize("long_run_s", [None, 10.0])
def test_tables_read_again_after_the_smoothing_give_the_same_measures(
    default_tour: Recording,
    rosy: RobotDescription,
    monkeypatch: pytest.MonkeyPatch,
    long_run_s: float | None,
) -> None:
    """Full rate (the odometry asked for once) and keyframes (asked for again for each round
    of the noise scales and the bridge): the truth and the vendor IPS are read again once
    each, after the smoothing (not held while it ran); every measure is the in-memory one."""
    params = SmootherParams(long_run_s=long_run_s)
    offset = rosy.hedge_offset_m
    full = track_recording(default_tour, hedge_offset_m=offset, smoother=params)
    monkeypatch.setattr(metrics, "FIGURE_ROWS", 500)
    asked: list[tuple[str, ...]] = []
    held_while_smoothing: list[bool] = []

    def reread(names: tuple[str, ...]) -> Recording:
        asked.append(names)
        return Recording({n: default_tour.topic(n) for n in names})

    smoothed_from = metrics._smoothed_from

    def spy(odom: Callable[[], np.ndarray], *args: Any, **kwargs: Any) -> Any:
        def odometry() -> np.ndarray:
            out = odom()
            held_while_smoothing.append(bool(asked))  # read again only once it is through
            return out

        return smoothed_from(odometry, *args, **kwargs)

    monkeypatch.setattr(metrics, "_smoothed_from", spy)
    lean = track_recording(
        Handover(default_tour), hedge_offset_m=offset, smoother=params, lean=True, reread=reread
    )
    _same(full, lean)
    assert asked == [(GROUND_TRUTH,), (HEDGE_POS_ANG,)]  # each when first needed
    smoothing = lean[metrics.SMOOTHED_KEY].smoothing
    assert smoothing is not None and smoothing.check is not None
    calls = 1 if long_run_s is None else smoothing.check.rounds + 1
    assert held_while_smoothing == [False] * calls
    assert (smoothing.keyframe_stride > 1) == (long_run_s is not None)


def test_fixes_handed_over_are_taken(default_tour: Recording, rosy: RobotDescription) -> None:
    """Omnical's multilateration given (handed over): the same measures as located inside."""
    full = track_recording(default_tour, hedge_offset_m=rosy.hedge_offset_m)
    hand = Handover(locate(default_tour)[0])
    lean = track_recording(
        Handover(default_tour), hedge_offset_m=rosy.hedge_offset_m, fixes=hand, lean=True
    )
    _same(full, lean)
    with pytest.raises(ValueError, match="taken already"):
        hand.take()


def test_located_first_is_one_read_and_locate(default_tour: Recording, tmp_path: Path) -> None:
    """What the multilateration reads, read and located alone, then the rest: the tables,
    start and notes of one read (without the raw distances and the beacons), and its fixes."""
    bag = write_bag(default_tour, tmp_path / "tour.mcap")
    whole = _read_slim(bag, TOPICS)
    recording, located = _read_located(bag, TOPICS)
    assert located is not None
    fixes, expected = located.take(), locate(whole)[0]
    np.testing.assert_array_equal(fixes.positions_map_m, expected.positions_map_m)
    np.testing.assert_array_equal(fixes.covariance_xy_m2, expected.covariance_xy_m2)
    np.testing.assert_array_equal(fixes.status, expected.status)
    assert fixes.t_ns is not None and expected.t_ns is not None
    np.testing.assert_array_equal(fixes.t_ns, expected.t_ns)
    assert recording.start_ns == whole.start_ns and recording.notes == whole.notes
    assert not recording.has(BEACON_RAW_DISTANCE) and not recording.has(BEACONS_POS_A)
    for name in (CMD_VEL, ODOM, IMU, GROUND_TRUTH, HEDGE_POS_ANG):
        a, b = whole.topic(name), recording.topic(name)
        assert a.names == b.names
        np.testing.assert_array_equal(a.t_ns, b.t_ns)
        for column in a.names:
            np.testing.assert_array_equal(a[column], b[column])
    # no raw distances to locate: one read, nothing located
    plain, none = _read_located(bag, (CMD_VEL, ODOM))
    assert none is None and plain.topics == _read_slim(bag, (CMD_VEL, ODOM)).topics
