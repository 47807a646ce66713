"""The monitor's derived streams pair each fix with the odometry at the fix's stamp: an
in-process run sends its whole odometry before its fixes, and the error and the fused pose are
then what a run streamed in time order gives (audit item 1)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from omnical.web.live import LiveView


def _drive(seconds: float = 20.0) -> tuple[dict[str, Any], dict[str, Any]]:
    """A robot driving a 1 m radius circle at 0.2 m/s from (2, 1) in the map: odometry 50 Hz
    (its own frame, starting at zero), fixes 8 Hz (map, 2 cm noise)."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, seconds, 0.02)
    a = 0.2 * t  # the angle along the circle, rad
    x, y, yaw = np.sin(a), 1.0 - np.cos(a), a
    odom = {"t": list(1000.0 + t), "x": list(x), "y": list(y), "yaw": list(yaw)}
    tf = np.arange(0.0, seconds, 0.125)
    af = 0.2 * tf
    fx = 2.0 + np.sin(af) + rng.normal(0, 0.02, len(tf))
    fy = 1.0 + 1.0 - np.cos(af) + rng.normal(0, 0.02, len(tf))
    fix = {"t": list(1000.0 + tf), "x": list(fx), "y": list(fy), "flags": [0] * len(tf)}
    return odom, fix


def _chunks(data: dict[str, Any], n: int) -> list[dict[str, Any]]:
    size = len(data["t"])
    return [{k: v[i : i + n] for k, v in data.items()} for i in range(0, size, n)]


def _run(frames: list[tuple[str, dict[str, Any]]]) -> tuple[list[float], dict[str, Any]]:
    view, errors, fused = LiveView(), [], {}
    for stream, data in frames:
        for derived, payload in view.on_frame(stream, data):
            if derived == "error":
                errors += payload["e"]
            elif derived == "fused":
                fused = payload
    return errors, fused


def test_a_run_sent_whole_pairs_each_fix_with_the_odometry_of_its_time() -> None:
    odom, fix = _drive()
    whole, whole_fused = _run([("odom", c) for c in _chunks(odom, 500)] + [("fix", fix)])
    # in time order, as a live robot streams: 0.5 s of odometry, then the fixes of that time
    inter: list[tuple[str, dict[str, Any]]] = []
    for o, f in zip(_chunks(odom, 25), _chunks(fix, 4), strict=True):
        inter += [("fix", f), ("odom", o)]  # each fix a little before its odometry
    live, live_fused = _run(inter)
    assert len(whole) == len(fix["t"]) and len(live) == len(fix["t"])
    assert max(whole) < 0.12 and float(np.median(whole)) < 0.05, max(whole)
    np.testing.assert_allclose(whole, live, atol=1e-9)
    # the fused pose ends where the robot is (not at its start): the circle at 4 rad
    end = 0.2 * odom["t"][-1] - 0.2 * 1000.0
    for fused in (whole_fused, live_fused):
        assert abs(fused["t"] - odom["t"][-1]) < 1e-9
        assert math.hypot(fused["x"] - (2 + math.sin(end)), fused["y"] - (2 - math.cos(end))) < 0.1


def test_a_fix_waits_for_the_odometry_of_its_time() -> None:
    odom, fix = _drive(4.0)
    view = LiveView()
    assert view.on_frame("fix", fix) == []  # no odometry yet: nothing to pair with
    derived = dict(view.on_frame("odom", odom))
    assert len(derived["error"]["e"]) == len(fix["t"]) and max(derived["error"]["e"]) < 0.1
    assert derived["origin"]["from"] == "first fix"


def test_a_run_without_fixes_costs_one_prediction_per_odometry_row(
    monkeypatch: Any,
) -> None:
    """The fused pose is carried forward from the last one, not from the filter's start."""
    from omnical.web import live

    calls = [0]
    predict = live.fusion_predict

    def counted(*args: Any) -> Any:
        calls[0] += 1
        return predict(*args)

    monkeypatch.setattr(live, "fusion_predict", counted)
    odom, _ = _drive(40.0)
    view = LiveView()
    view.on_frame("origin", {"x": 2.0, "y": 1.0, "yaw": 0.0})
    fused: dict[str, Any] = {}
    for chunk in _chunks(odom, 5):
        fused = dict(view.on_frame("odom", chunk)).get("fused", fused)
    assert calls[0] <= len(odom["t"]) + 10
    end = 0.2 * (odom["t"][-1] - 1000.0)
    assert math.hypot(fused["x"] - (2 + math.sin(end)), fused["y"] - (2 - math.cos(end))) < 1e-6


def test_a_long_run_without_fixes_keeps_a_bounded_odometry() -> None:
    odom, _ = _drive(400.0)  # 20 000 rows at 50 Hz
    view = LiveView()
    view.on_frame("origin", {"x": 2.0, "y": 1.0, "yaw": 0.0})
    for chunk in _chunks(odom, 50):
        view.on_frame("odom", chunk)
    kept = view.on_frame("odom", {k: v[-1:] for k, v in odom.items()})  # a repeat: skipped
    assert kept[-1][0] == "fused"
    assert len(view._ts) < 8192  # the bound is the point
