"""``locate`` frees a handed-over recording's raw distances before solving (issue "Scale").

The raw-distance columns of a long run (and the rest of its recording) were held through the
whole solve, whose peak they raised; now :func:`omnical.ips.from_recording.locate` lets go of
them once the fixes are grouped (:func:`group_ranges`, then :func:`locate_bursts`), and
``omnical locate`` hands its recording over.
"""

from __future__ import annotations

import tracemalloc
import weakref
from typing import Any

import numpy as np
import pytest
from ips_synthetic import locate_recording

from omnical.ips import from_recording
from omnical.ips.beacons import default_beacon_map
from omnical.ips.solve import locate as locate_module
from omnical.ips.solve.fixes import Fixes
from omnical.ips.solve.locate import group_ranges, locate_bursts
from omnical.recording.recording import Recording, RecordingBuilder


def _recording(n: int = 400, hedges: int = 2, *, seed: int = 0) -> Recording:
    """Bursts of four ranges from ``hedges`` hedgehogs walking in the seed-000 room."""
    beacons = default_beacon_map()
    rng = np.random.default_rng(seed)
    m = len(beacons)
    points = np.column_stack(
        [
            1.0 + np.cumsum(rng.normal(0.0, 0.01, n)),
            1.5 + np.cumsum(rng.normal(0.0, 0.01, n)),
            np.full(n, 0.4),
        ]
    )
    distances = np.linalg.norm(points[:, None, :] - beacons.positions_m[None], axis=2)
    distances += rng.normal(0.0, 0.02, distances.shape)
    distances[rng.random(distances.shape) < 0.05] += 0.5  # NLOS
    t_ns = (np.repeat(np.arange(n), m) * 50_000_000 + np.tile(np.arange(m), n) * 1_000_000).astype(
        np.int64
    )
    builder = RecordingBuilder()
    builder.add_many(
        "/beacon_raw_distance",
        1_000_000_000 + t_ns,
        address_hedge=np.repeat(10 + np.arange(n) % hedges, m),
        address_beacon=np.tile(beacons.addresses, n),
        distance_m=distances.reshape(-1),
    )
    return builder.build()


def _same(a: Fixes, b: Fixes) -> None:
    for name in ("positions_map_m", "covariance_xy_m2", "hdop", "status", "reason", "t_ns"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.notes == b.notes


@pytest.mark.parametrize("sequential", [None, True])
def test_grouped_ranges_hold_only_what_the_solve_uses(sequential: bool | None) -> None:
    d = _recording().topic("/beacon_raw_distance")
    beacons = default_beacon_map()
    columns = (d.t_ns, d["address_hedge"], d["address_beacon"], d["distance_m"])
    bursts, notes = group_ranges(*columns, beacons, sequential=sequential)
    assert bursts.fix_of_message.size == 0  # not held while solving
    assert bool(notes) == bool(sequential)
    fixes = locate_bursts(bursts, beacons, notes=notes, hedge_z_m=0.4)
    assert len(fixes) == (d.t_ns.size if sequential else 400)
    assert fixes.notes == notes


def test_a_handed_over_recording_is_freed_before_the_solve(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    loaded = [_recording()]
    distance = weakref.ref(loaded[0].topic("/beacon_raw_distance")["distance_m"])
    alive_at_solve: list[bool] = []
    solve = locate_module.locate_bursts

    def spy(*args: Any, **kwargs: Any) -> Fixes:
        alive_at_solve.append(distance() is not None)
        return solve(*args, **kwargs)

    monkeypatch.setattr(from_recording, "locate_bursts", spy)
    fixes, _ = from_recording.locate(loaded.pop(), hedge_z_m=0.4)
    assert alive_at_solve == [False]
    kept = _recording()  # a caller that keeps its recording gets the same fixes
    again, _ = from_recording.locate(kept, hedge_z_m=0.4)
    assert kept.topic("/beacon_raw_distance")["distance_m"].size == 1600
    _same(fixes, again)


def test_a_kept_recording_is_not_touched(monkeypatch: pytest.MonkeyPatch) -> None:
    """The 3D height pass, then the 2D one, both from the same columns."""
    kept = _recording(hedges=1)
    fixes, _ = from_recording.locate(kept)  # no height: the seed-000 map's, or estimated
    assert len(fixes) == 400
    assert len(kept.topic("/beacon_raw_distance")) == 1600


def _locate_peak(n: int, *, hand_over: bool) -> tuple[int, int]:
    """Traced peak of ``locate`` above the recording it is given, and the recording's
    raw-distance bytes (the recording is built while tracing, so that freeing it counts)."""
    tracemalloc.start()
    try:
        loaded = [_recording(n, hedges=1)]
        d = loaded[0].topic("/beacon_raw_distance")
        raw = d.t_ns.nbytes + sum(d[c].nbytes for c in d.names)
        del d
        base = tracemalloc.get_traced_memory()[0]
        if hand_over:
            fixes, _ = from_recording.locate(loaded.pop(), hedge_z_m=0.4)
        else:
            fixes, _ = from_recording.locate(loaded[0], hedge_z_m=0.4)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert len(fixes) == n
    return peak, raw


def test_handing_the_recording_over_lowers_the_peak_by_its_columns() -> None:
    kept, raw = _locate_peak(20_000, hand_over=False)
    handed, _ = _locate_peak(20_000, hand_over=True)
    assert handed < kept - 0.8 * raw, (kept, handed, raw)


def test_learning_passes_read_nothing_that_is_freed(monkeypatch: pytest.MonkeyPatch) -> None:
    """The learning passes' covariances and statistics are dropped before the learning: the
    fixes and the learned model are those of keeping them (the learning never reads them)."""
    d = _recording(2000, hedges=1, seed=3).topic("/beacon_raw_distance")
    columns = (d.t_ns, d["address_hedge"], d["address_beacon"], d["distance_m"])
    beacons = default_beacon_map()
    dropped: list[int] = []
    slim = locate_module._for_learning

    def counted(fixes: Fixes) -> Fixes:
        out = slim(fixes)
        assert out.covariance_xy_m2.strides == (0, 0, 0)  # no memory of its own
        dropped.append(len(fixes))
        return out

    monkeypatch.setattr(locate_module, "_for_learning", counted)
    freed = locate_recording(*columns, beacons, hedge_z_m=0.4)
    assert dropped == [2000] * 4
    monkeypatch.setattr(locate_module, "_for_learning", lambda fixes: fixes)
    kept = locate_recording(*columns, beacons, hedge_z_m=0.4)
    _same(freed, kept)
    assert np.all(np.isfinite(freed.covariance_xy_m2[freed.status == 0]))
    (model_freed,), (model_kept,) = freed.noise, kept.noise
    np.testing.assert_array_equal(model_freed.sigma_m, model_kept.sigma_m)
    np.testing.assert_array_equal(model_freed.bias_m, model_kept.bias_m)


def test_no_ranges_give_no_fixes() -> None:
    nothing = np.zeros(0, dtype=np.int64)
    fixes = locate_recording(nothing, nothing, nothing, np.zeros(0), default_beacon_map())
    assert len(fixes) == 0
    assert fixes.t_ns is not None and fixes.t_ns.size == 0
