"""The monitor's fan-out (per page and stream, drop-oldest, round-robin, latched data for late
joiners) and the live view's fused pose and odometry − IPS error."""

from __future__ import annotations

import asyncio
import json
import math
from typing import Any

import pytest

from omnical.web.hub import HISTORY_BLOCK_ROWS, History, Hub, PageQueue
from omnical.web.live import LiveView
from omnical.web.protocol import HISTORY_POINTS, QUEUE_DEPTH, dumps


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
    assert {"beacons", "source", "runclock", "events", "hub", "odom"} <= set(streams)
    text = hub.frame_text("odom", '{"a":1}')
    assert json.loads(text) == {"s": "odom", "ts": 100000.0, "d": {"a": 1}}
    with pytest.raises(ValueError, match="object"):
        hub.ingest(1, "[1, 2]")
    hub.source_gone(1)
    assert hub.sources == {}


def _hello(hub: Hub, key: int, since: float, *, reset: bool = True, name: str = "run") -> None:
    data = {"source": name, "pid": 7, "since": since, "reset": reset}
    hub.ingest(key, json.dumps({"kind": "hello", "stream": "source", "data": data}))


def _drain(page: PageQueue) -> dict[str, list[dict[str, Any]]]:
    got: dict[str, list[dict[str, Any]]] = {}
    while (item := page.take()) is not None:
        got.setdefault(item[0], []).append(json.loads(item[1]))
    return got


def test_a_late_page_gets_a_bounded_trail_history_in_blocks() -> None:
    hub = Hub(clock=lambda: 1000.0)
    _hello(hub, 1, 990.0)
    cap, block = HISTORY_POINTS["odom"], HISTORY_BLOCK_ROWS
    n = cap + 555
    for k in range(n):  # more than is kept, a frame of one row each
        t = 990.0 + 0.02 * k
        hub.ingest(1, json.dumps({"kind": "frame", "stream": "odom",
                                  "data": _odom([t], [0.001 * k], [0.0], [0.0])}))  # fmt: skip
    page = hub.attach()
    got = _drain(page)
    # blocks, not a frame a row: the page's queue (64 deep) would drop most of 4555
    assert not page.dropped and all(len(f["t"]) <= block for f in got["odom"])
    odom = {k: [v for f in got["odom"] for v in f[k]] for k in got["odom"][0]}
    assert len(odom["x"]) == len(odom["t"]) == len(odom["vx"])
    assert cap <= len(odom["t"]) < cap + block  # at least the page's bound, whole blocks
    assert odom["x"] == pytest.approx([0.001 * k for k in range(n - len(odom["x"]), n)])
    [clock] = got["runclock"]
    assert clock == {"since": 990.0, "source": "run", "end": None}
    _hello(hub, 2, 995.0)  # a new run: its history starts afresh
    assert "odom" not in _drain(hub.attach())


def test_joining_encodes_no_history_but_the_open_blocks(monkeypatch: pytest.MonkeyPatch) -> None:
    """A page joining a long run does not hold the monitor's loop while its whole history is
    encoded (4000 rows a trail: 54-61 ms once, every other page's frames waiting): the full
    blocks were encoded as they filled."""
    hub = Hub(clock=lambda: 1000.0)
    _hello(hub, 1, 990.0)
    for k in range(0, 4000, 40):  # 80 s of 50 Hz odometry, fixes and commands, 40 rows a frame
        t = [990.0 + 0.02 * (k + j) for j in range(40)]
        x = [0.001 * (k + j) for j in range(40)]
        hub.publish("odom", _odom(t, x, x, x))
        hub.publish("fix", {"t": t, "x": x, "y": x, "flags": [0] * 40})
        hub.publish("cmd", {"t": t, "vx": x, "vy": x, "wz": x})
    encoded: list[int] = []

    def counting(message: Any) -> str:
        text = dumps(message)
        encoded.append(len(text))
        return text

    monkeypatch.setattr("omnical.web.hub.dumps", counting)
    got = _drain(hub.attach())
    sent = sum(len(json.dumps(f)) for s in ("odom", "fix", "cmd") for f in got[s])
    assert sum(len(f["t"]) for f in got["odom"]) >= HISTORY_POINTS["odom"]
    assert sum(encoded) < 0.1 * sent, (sum(encoded), sent)  # at most the open blocks


def test_a_streams_history_keeps_whole_blocks_in_order() -> None:
    kept = History(frozenset({"t"}), cap=10, block=4)
    assert kept.frames() == []
    for k in range(0, 23, 3):  # 24 rows, 3 at a time: blocks fill across frames
        kept.extend({"t": [k, k + 1, k + 2]})
    rows = [v for text in kept.frames() for v in json.loads(text)["t"]]
    assert rows == list(range(12, 24))  # >= 10 rows, < 10 + 4: the oldest blocks went whole
    assert [len(json.loads(text)["t"]) for text in kept.frames()] == [4, 4, 4]
    kept.extend({"t": [24]})
    assert [json.loads(text)["t"] for text in kept.frames()][-1] == [24]  # the open block


def test_run_time_is_from_the_runs_own_start_stamp() -> None:
    now = [1000.0]
    hub = Hub(clock=lambda: now[0])
    _hello(hub, 1, 990.0)
    _hello(hub, 2, 900.0, reset=False, name="twin serve")  # not the run: not its clock
    assert hub.run_clock is not None and hub.run_clock["since"] == 990.0
    hub.ingest(1, json.dumps({"kind": "frame", "stream": "events",
                              "data": {"t": 1002.5, "text": "step 2"}}))  # fmt: skip
    hub.ingest(1, json.dumps({"kind": "frame", "stream": "events",
                              "data": {"t": 1003.0, "text": "x", "run_s": 12.0}}))  # fmt: skip
    # a simulated run's bag time (seed 000's epoch): since its first stamp
    sim = 1_667_865_600.0
    hub.ingest(1, json.dumps({"kind": "frame", "stream": "odom",
                              "data": _odom([sim], [0.0], [0.0], [0.0])}))  # fmt: skip
    hub.ingest(1, json.dumps({"kind": "frame", "stream": "events",
                              "data": {"t": sim + 4.25, "text": "sim"}}))  # fmt: skip
    events = {e["text"]: e["run_s"] for e in _drain(hub.attach())["events"]}
    assert events["step 2"] == pytest.approx(12.5)
    assert events["x"] == 12.0  # the run's own figure is kept
    assert events["sim"] == pytest.approx(4.25)
    assert events["run connected (pid 7)"] == pytest.approx(10.0)
    now[0] = 1020.0
    hub.source_gone(1)
    # the simulated rows' time 0 is every page's time 0 (audit item 4)
    assert hub.run_clock == {"since": 990.0, "source": "run", "end": None, "t0": sim}
    [clock] = _drain(hub.attach())["runclock"]
    assert clock["end"] == 1020.0  # the page's run time stops at the run's end


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


def _say(hub: Hub, key: int, kind: str, stream: str, data: dict[str, Any]) -> None:
    hub.ingest(key, json.dumps({"kind": kind, "stream": stream, "data": data}))


def _frames(page: PageQueue) -> list[tuple[str, dict[str, Any]]]:
    out = []
    while (item := page.take()) is not None:
        out.append((item[0], json.loads(item[1])))
    return out


def test_a_device_beside_an_in_process_run_is_shown_as_that_device_only() -> None:
    """Audit item 2: ``twin serve --monitor`` (wall-clock stamps) stays connected while an
    in-process run (simulated stamps) streams: its truth does not join the run's, its status
    is the device's, and the page's source stays the run."""
    wall = 1.7e9
    hub = Hub(clock=lambda: wall)
    page = hub.attach()
    _say(hub, 1, "hello", "source", {"source": "omnical twin serve", "pid": 1, "since": wall,
                                      "reset": False})  # fmt: skip
    _say(hub, 1, "latch", "beacons", {"beacons": [{"address": 1, "x": 0, "y": 0, "z": 2}]})
    _say(hub, 1, "frame", "truth", _odom([wall + 1], [5.0], [5.0], [0.0]))
    _say(hub, 2, "hello", "source", {"source": "omnical run", "pid": 2, "since": wall + 2})
    _say(hub, 2, "frame", "truth", _odom([1.6e9, 1.6e9 + 1], [0.0, 0.1], [0.0, 0.0], [0.0, 0.0]))
    _say(hub, 1, "frame", "truth", _odom([wall + 3], [5.0], [5.0], [0.0]))
    _say(hub, 1, "frame", "status", {"t": wall + 3, "battery_v": 12.3})
    _say(
        hub,
        1,
        "hello",
        "source",
        {"source": "omnical twin serve", "pid": 1, "since": wall, "reset": False},
    )  # fmt: skip  (it reconnected)
    got = _frames(page)
    truth = [d["x"] for s, d in got if s == "truth"]
    # the run's only: the device's truth the page had not taken when the run started is not
    # sent (the page starts afresh on the run's source, which goes first)
    assert truth == [[0.0, 0.1]]
    sources = [d["source"] for s, d in got if s == "source"]
    assert sources == ["omnical twin serve", "omnical run"]
    assert [d["source"] for s, d in got if s == "device"] == ["omnical twin serve"] * 2
    assert not [d for s, d in got if s == "status"]
    assert hub.latched["source"].count("omnical run") == 1 and hub.held_back == 1
    # the device's beacons stay (it is still connected); the run's source says so
    assert [d["kept"] for s, d in got if s == "source"][-1] == ["beacons"]
    # and beacons it sends while the run is shown are latched (review: they were held back)
    moved = {"beacons": [{"address": 1, "x": 1, "y": 0, "z": 2}]}
    _say(hub, 1, "latch", "beacons", moved)
    assert json.loads(hub.latched["beacons"]) == moved


def test_a_new_run_drops_what_the_last_run_sent() -> None:
    """Audit item 3: the map, beacons, origin and factors of the last run do not stay."""
    hub = Hub(clock=lambda: 100.0)
    _say(hub, 1, "hello", "source", {"source": "omnical navigate", "pid": 1})
    _say(hub, 1, "latch", "map", {"width": 1, "height": 1, "resolution": 0.1, "origin": [0, 0, 0],
                                  "cells": "AA=="})  # fmt: skip
    _say(hub, 1, "latch", "beacons", {"beacons": []})
    _say(hub, 1, "frame", "factors", {"iteration": 1, "values": {}, "sigma": {}})
    hub.source_gone(1)
    _say(hub, 2, "hello", "source", {"source": "omnical run", "pid": 2})
    assert not {"map", "beacons", "origin"} & set(hub.latched)
    assert not hub.history["factors"]
    late = [s for s, _ in _frames(hub.attach())]
    assert "map" not in late and "factors" not in late
    assert json.loads(hub.latched["source"])["kept"] == []


def test_an_earlier_run_still_connected_does_not_draw_on_the_new_runs_page() -> None:
    """Review: after run B's hello, run A (still streaming) had its truth published, its origin
    latched and its stamps moving B's run clock back. Held back now (counted)."""
    hub = Hub(clock=lambda: 1.7e9)
    page = hub.attach()
    a, b = 1.667865600e9 + 10, 1.667865600e9 + 50
    _say(hub, 1, "hello", "source", {"source": "omnical run A", "pid": 1})
    _say(hub, 1, "frame", "truth", {"t": [a], "x": [1.0], "y": [0.0], "yaw": [0.0]})
    _say(hub, 2, "hello", "source", {"source": "omnical run B", "pid": 2})
    _say(hub, 2, "frame", "truth", {"t": [b], "x": [2.0], "y": [0.0], "yaw": [0.0]})
    held = hub.held_back
    _say(hub, 1, "frame", "truth", {"t": [a - 5], "x": [9.0], "y": [0.0], "yaw": [0.0]})
    _say(hub, 1, "latch", "origin", {"x": 9, "y": 9, "yaw": 0})
    assert hub.held_back == held + 2
    truth = [d["x"] for s, d in _frames(page) if s == "truth"]
    assert truth == [[2.0]]  # A's the page had not taken when B started are not sent either
    assert "origin" not in hub.latched
    assert hub.run_clock is not None and hub.run_clock["t0"] == b


def test_a_new_run_goes_first_and_its_page_keeps_nothing_of_the_last_run() -> None:
    """A page that has not had the last run's frames yet gets the new run's source and clock
    first, then only the new run's frames; a later page gets only the new run's events (the
    hub kept 200 across runs)."""
    hub = Hub(clock=lambda: 100.0)
    page = hub.attach()
    _say(hub, 1, "hello", "source", {"source": "run A", "pid": 1, "since": 90.0})
    _frames(page)
    for k in range(10):  # waiting for the page when run B starts
        _say(hub, 1, "frame", "odom", _odom([91.0 + k], [0.0], [0.0], [0.0]))
        _say(hub, 1, "frame", "events", {"t": 91.0 + k, "text": f"A step {k}"})
    _say(hub, 1, "latch", "origin", {"x": 9.0, "y": 9.0, "yaw": 0.0})  # A's: not B's
    hub.source_gone(1)
    _say(hub, 2, "hello", "source", {"source": "run B", "pid": 2, "since": 99.0})
    _say(hub, 2, "frame", "odom", _odom([99.5], [1.0], [0.0], [0.0]))
    got = _frames(page)
    assert [s for s, _ in got[:2]] == ["source", "runclock"]
    assert got[0][1]["source"] == "run B"
    assert [d["x"] for s, d in got if s == "odom"] == [[1.0]]
    assert "origin" not in [s for s, _ in got]
    texts = [d["text"] for s, d in got if s == "events"]
    assert texts == ["run B connected (pid 2)"]
    late = [d["text"] for s, d in _frames(hub.attach()) if s == "events"]
    assert late == ["run B connected (pid 2)"]


def test_a_device_that_disconnects_takes_its_line_with_it() -> None:
    hub = Hub(clock=lambda: 100.0)
    _say(hub, 1, "hello", "source", {"source": "omnical run", "pid": 1, "since": 99.0})
    _say(hub, 2, "hello", "source", {"source": "omnical twin serve", "pid": 2, "reset": False})
    page = hub.attach()
    _say(hub, 2, "frame", "status", {"t": 100.0, "battery_v": 12.3})
    hub.source_gone(2)
    device = [d for s, d in _frames(page) if s == "device"]
    assert device[0]["battery_v"] == 12.3 and "gone" not in device[0]
    assert device[-1] == {"source": "omnical twin serve", "gone": True}
    hub.source_gone(1)  # a run is not a device: no device frame
    assert not [d for s, d in _frames(page) if s == "device"]


def test_a_joiners_history_blocks_fit_its_queues() -> None:
    """Every kept block reaches a joining page: a stream's blocks (and the open one) are
    fewer than its queue's depth, else the page's own queue would drop the oldest."""
    for stream, cap in HISTORY_POINTS.items():
        blocks = -(-cap // HISTORY_BLOCK_ROWS) + 1
        assert blocks < QUEUE_DEPTH.get(stream, 16), stream
