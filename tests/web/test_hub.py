"""The monitor's fan-out (per page and stream, drop-oldest, round-robin, latched data for late
joiners) and the live view's fused pose and odometry − IPS error."""

from __future__ import annotations

import asyncio
import json
import math

import pytest

from omnical.web.hub import Hub, PageQueue
from omnical.web.live import LiveView
from omnical.web.protocol import QUEUE_DEPTH


def _odom(t: list[float], x: list[float], y: list[float], yaw: list[float]) -> dict[str, object]:
    z = [0.0] * len(t)
    return {"t": t, "x": x, "y": y, "yaw": yaw, "vx": z, "vy": z, "wz": z}


def test_a_stalled_page_drops_its_oldest_odometry_but_keeps_every_event() -> None:
    page = PageQueue()
    for k in range(1000):
        page.put("odom", json.dumps({"k": k}))
        if k % 100 == 0:
            page.put("events", json.dumps({"k": k}))
    depth = QUEUE_DEPTH["odom"]
    assert page.dropped == {"odom": 1000 - depth}
    got: dict[str, list[int]] = {"odom": [], "events": []}
    while (item := page.take()) is not None:
        got[item[0]].append(json.loads(item[1])["k"])
    assert got["odom"] == list(range(1000 - depth, 1000))  # the newest, in order
    assert got["events"] == list(range(0, 1000, 100))


def test_streams_are_served_in_turn() -> None:
    page = PageQueue()
    for k in range(50):
        page.put("odom", str(k))
    page.put("factors", "f")
    first = [page.take() for _ in range(3)]
    assert ("factors", "f") in first  # not behind 50 odometry frames


def test_a_late_page_gets_the_latched_data_and_the_recent_events() -> None:
    hub = Hub(clock=lambda: 100.0)
    hub.ingest(
        1, json.dumps({"kind": "hello", "stream": "source", "data": {"source": "run", "pid": 7}})
    )
    hub.ingest(1, json.dumps({"kind": "latch", "stream": "beacons", "data": {"beacons": []}}))
    hub.ingest(
        1,
        json.dumps({"kind": "frame", "stream": "odom", "data": _odom([1.0], [0.0], [0.0], [0.0])}),
    )
    hub.ingest(
        1, json.dumps({"kind": "frame", "stream": "events", "data": {"t": 1.0, "text": "step 1"}})
    )
    page = hub.attach()
    streams = []
    while (item := page.take()) is not None:
        streams.append(item[0])
    assert {"beacons", "source", "events", "hub"} <= set(streams)
    assert "odom" not in streams  # live data is not replayed to late joiners
    text = hub.frame_text("odom", '{"a":1}')
    assert json.loads(text) == {"s": "odom", "ts": 100000.0, "d": {"a": 1}}
    with pytest.raises(ValueError, match="object"):
        hub.ingest(1, "[1, 2]")
    hub.source_gone(1)
    assert hub.sources == {}


def test_page_get_waits_for_a_frame() -> None:
    async def main() -> tuple[str, str]:
        page = PageQueue()
        waiter = asyncio.create_task(page.get())
        await asyncio.sleep(0.01)
        assert not waiter.done()
        page.put("fix", "x")
        return await asyncio.wait_for(waiter, 1.0)

    assert asyncio.run(main()) == ("fix", "x")


def test_the_live_view_aligns_the_odometry_at_the_first_fix_and_fuses() -> None:
    live = LiveView(offset_m=(0.1, 0.0))
    assert live.on_frame("odom", _odom([0.0, 0.1], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0])) == []
    frames = dict(live.on_frame("fix", {"t": [0.1], "x": [2.1], "y": [3.0], "flags": [2]}))
    assert frames["origin"]["x"] == pytest.approx(2.0) and frames["origin"]["y"] == pytest.approx(
        3.0
    )
    assert frames["error"]["e"] == [pytest.approx(0.0)]
    fused = live.on_frame("odom", _odom([0.2, 0.3], [0.1, 0.2], [0.0, 0.0], [0.0, 0.0]))
    [(name, data)] = fused
    assert name == "fused" and data["x"] == pytest.approx(2.2, abs=1e-6)
    assert data["cov"][0] > 0 and data["cov"][2] > 0
    errs = dict(live.on_frame("fix", {"t": [0.3], "x": [2.45], "y": [3.0], "flags": [2]}))
    assert errs["error"]["e"] == [pytest.approx(0.15)]  # odometry hedgehog at 2.3
    assert live.on_frame("fix", {"t": [0.4], "x": [9.0], "y": [9.0], "flags": [3]}) == []


def test_a_latched_origin_wins_over_the_first_fix() -> None:
    live = LiveView()
    live.on_frame("origin", {"x": 1.0, "y": 2.0, "yaw": math.pi / 2, "offset": [0.0, 0.0]})
    [(_, fused)] = live.on_frame("odom", _odom([0.0], [1.0], [0.0], [0.0]))
    assert (fused["x"], fused["y"]) == (pytest.approx(1.0), pytest.approx(3.0))
    frames = dict(live.on_frame("fix", {"t": [0.0], "x": [1.0], "y": [3.0], "flags": [2]}))
    assert "origin" not in frames and frames["error"]["e"] == [pytest.approx(0.0)]


def test_an_odometry_restarting_at_zero_is_anchored_where_the_filter_has_the_robot() -> None:
    live = LiveView()
    live.on_frame("origin", {"x": 1.0, "y": 1.0, "yaw": 0.0})
    live.on_frame("odom", _odom([0.0, 1.0], [0.0, 2.0], [0.0, 0.0], [0.0, 0.0]))  # at (3, 1)
    frames = dict(live.on_frame("odom", _odom([1.1], [0.0], [0.0], [0.0])))  # the next run
    assert frames["origin"]["from"] == "odometry reset"
    assert (frames["origin"]["x"], frames["origin"]["y"]) == (
        pytest.approx(3.0),
        pytest.approx(1.0),
    )
    assert frames["fused"]["x"] == pytest.approx(3.0)
