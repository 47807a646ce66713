"""The run's side: the tee writes the run's sink whole and never waits for the monitor, which
may be absent, slow, or restarted (the link reconnects and sends the latched data again)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from monitor_procs import page_frames, start_monitor

from omnical.recording.recording import RecordingBuilder
from omnical.recording.topics import GROUND_TRUTH, ODOM
from omnical.web import tee
from omnical.web.protocol import MonitorTarget
from omnical.web.tee import MonitorLink, MonitorTee
from omnical.web.wsclient import WebSocketClient, encode_frame

COLS = ("x_m", "y_m", "yaw_rad", "vx_mps", "vy_mps", "wz_radps")


def _rows(k: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    return np.array([1_700_000_000_000_000_000 + k * 10**7]), {
        c: np.array([0.01 * k]) for c in COLS
    }


def test_without_a_monitor_the_run_writes_everything_and_never_waits() -> None:
    link = MonitorLink(MonitorTarget("127.0.0.1", 9), "run").start()  # port 9: nothing there
    builder = RecordingBuilder()
    tee = MonitorTee(builder, link)
    started = time.perf_counter()
    for k in range(2000):
        t, cols = _rows(k)
        tee.write_rows(ODOM, t, **cols)
    spent = time.perf_counter() - started
    link.close()
    assert len(builder.build().topic(ODOM)) == 2000
    assert link.sent == 0 and not link.connected
    assert link.dropped["rows:/odom"] == 2000 - 64  # bounded: the newest 64 kept
    assert spent < 2.0  # 2000 writes; each is a copy and an append, not a network wait
    assert tee.build == builder.build  # the sink's own methods pass through


def test_no_monitor_listening_is_said_once() -> None:
    """``--monitor PORT`` with nothing there: one warning, not silence (audit item 6)."""
    heard: list[str] = []
    link = MonitorLink(MonitorTarget("127.0.0.1", 9), "run", on_warning=heard.append).start()
    deadline = time.monotonic() + 5
    while link.connects == 0 and not heard and time.monotonic() < deadline:
        time.sleep(0.02)
    time.sleep(0.6)  # a few more attempts (every 0.25 s): still one warning
    link.close()
    assert len(heard) == 1 and heard[0].startswith("warning: --monitor: no monitor answered at")


def test_the_link_reconnects_to_a_restarted_monitor_and_latches_again() -> None:
    mon = start_monitor()
    link = MonitorLink(MonitorTarget("127.0.0.1", mon.port), "run").start()
    try:
        link.latch("beacons", {"beacons": [{"address": 3, "x": 0.0, "y": 0.0, "z": 0.4}]})
        deadline = time.monotonic() + 10
        while link.sent < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert link.connected and link.connects == 1
        port = mon.port
        mon.proc.stop()
        t, cols = _rows(1)
        link.rows(ODOM, t, cols)  # notices the monitor is gone
        mon = start_monitor(port=port)
        deadline = time.monotonic() + 10
        while link.connects < 2 and time.monotonic() < deadline:
            link.rows(ODOM, t, cols)
            time.sleep(0.05)
        assert link.connects == 2
        page = WebSocketClient.connect("127.0.0.1", port, "/ws")
        page.sock.settimeout(5)
        seen: set[str] = set()
        while "beacons" not in seen:
            seen.update(f["s"] for f in page_frames(page))
        page.close()
    finally:
        link.close()
        mon.proc.stop()


def test_client_frames_are_masked_and_sized() -> None:
    short = encode_frame(1, b"hi")
    assert short[0] == 0x81 and short[1] == 0x80 | 2 and len(short) == 2 + 4 + 2
    key, body = short[2:6], short[6:]
    assert bytes(b ^ key[i % 4] for i, b in enumerate(body)) == b"hi"
    medium = encode_frame(1, b"x" * 300)
    assert medium[1] == 0x80 | 126 and int.from_bytes(medium[2:4], "big") == 300
    key, body = medium[4:8], medium[8:]
    assert bytes(b ^ key[i % 4] for i, b in enumerate(body)) == b"x" * 300
    big = encode_frame(2, b"y" * 70000, mask=False)
    assert big[1] == 127 and int.from_bytes(big[2:10], "big") == 70000


def test_a_refused_handshake_is_said_once_on_stderr(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(tee, "_REFUSED_RETRY_S", 0.05)  # many refusals within the test
    mon = start_monitor("--token", "sekrit")
    link = MonitorLink(MonitorTarget("127.0.0.1", mon.port), "run").start()  # no token
    try:
        time.sleep(1.0)
        assert not link.connected and link.connects == 0
        assert link.refused is not None and "403" in link.refused
        lines = [ln for ln in capsys.readouterr().err.splitlines() if "--monitor" in ln]
        assert len(lines) == 1, lines
        assert lines[0].startswith(
            f"omnical: warning: --monitor: the monitor at 127.0.0.1:{mon.port}"
        )
        assert "?token=" in lines[0] and "not streaming" in lines[0]
        heard: list[str] = []
        good = MonitorLink(
            MonitorTarget("127.0.0.1", mon.port, "sekrit"), "run", on_warning=heard.append
        )
        good.start()
        deadline = time.monotonic() + 10
        while not good.connected and time.monotonic() < deadline:
            time.sleep(0.02)
        good.close()
        assert good.connects == 1 and good.refused is None and heard == []
    finally:
        link.close()
        mon.proc.stop()


def test_a_frame_that_cannot_be_sent_is_dropped_and_the_link_goes_on() -> None:
    mon = start_monitor()
    heard: list[str] = []
    link = MonitorLink(MonitorTarget("127.0.0.1", mon.port), "run", on_warning=heard.append)
    link.start()
    try:
        page = WebSocketClient.connect("127.0.0.1", mon.port, "/ws")
        page.sock.settimeout(5)
        t, cols = _rows(1)
        link.rows(GROUND_TRUTH, t, {"x_m": cols["x_m"]})  # KeyError: no y_m
        link.send("status", {"t": 1.0, "battery_v": object()})  # TypeError in dumps
        link.latch("origin", {"x": 0.0, "y": 0.0, "yaw": 0.0, "from": {1, 2}})  # TypeError
        link.rows(ODOM, t, cols)
        seen: set[str] = set()
        deadline = time.monotonic() + 5
        while "odom" not in seen and time.monotonic() < deadline:
            seen.update(f["s"] for f in page_frames(page))
        page.close()
        assert "odom" in seen  # the frames after the bad ones were sent
        assert link.dropped == {"rows:/ground_truth": 1, "status": 1, "origin": 1}
        assert len(heard) == 3 and all("cannot be sent" in h for h in heard), heard
        link.rows(ODOM, t, cols)
        started = time.monotonic()
        link.close(timeout_s=5.0)
        assert time.monotonic() - started < 1.0  # the thread is alive and empties its queue
    finally:
        link.close()
        mon.proc.stop()


@pytest.mark.parametrize("batch", [1, 32])
def test_frames_that_wait_for_a_page_go_in_one_message(batch: int) -> None:
    """A late page's backlog (latched data, history, the hub's status) is one message, not one
    per frame; ``--batch 1`` (the benchmark's baseline) sends each on its own."""
    mon = start_monitor("--beacons", "default", "--batch", str(batch))
    link = MonitorLink(MonitorTarget("127.0.0.1", mon.port), "run").start()
    try:
        link.event("step 1")
        t, cols = _rows(1)
        link.rows(ODOM, t, cols)
        deadline = time.monotonic() + 10
        while link.sent < 3 and time.monotonic() < deadline:  # hello, the event, the odometry
            time.sleep(0.02)
        page = WebSocketClient.connect("127.0.0.1", mon.port, "/ws")
        page.sock.settimeout(5)
        sizes: list[int] = []
        seen: set[str] = set()
        while not {"beacons", "source", "runclock", "events", "odom", "hub"} <= seen:
            assert time.monotonic() < deadline, seen
            frames = page_frames(page)
            sizes.append(len(frames))
            seen.update(f["s"] for f in frames)
        page.close()
        if batch == 1:
            assert set(sizes) == {1}
        else:
            assert sizes[0] >= 5, sizes  # all that waited for the page: one message
    finally:
        link.close()
        mon.proc.stop()


def test_the_tee_sends_step_markers_live_then_their_recorded_stamps() -> None:
    """The recorded marker comes flagged ``recorded``: the page re-times its live line with it
    (the run's own clock) instead of adding a second one."""
    from omnical.recording.topics import EVENTS

    link = MonitorLink(MonitorTarget("127.0.0.1", 9), "run")  # not started: the queues stay
    mt = MonitorTee(RecordingBuilder(), link)
    step = '{"script": "s", "step": 1, "kind": "move", "edge": "start"}'
    mt.live_event(3.0, step)
    mt.write_rows(EVENTS, np.array([1, 2]), text=np.array([step, "hedgehog silent"], dtype=object))
    assert len(mt.sink.build().topic(EVENTS)) == 2  # the recording has both
    live, recorded = link._queues["events"]
    assert live[2]["kind"] == "step" and live[2]["run_s"] >= 0.0 and "recorded" not in live[2]
    assert recorded[2]["recorded"] is True and recorded[2]["t"] == 1e-9
    assert recorded[2]["text"] == live[2]["text"]
    [(_, _, t_ns, cols)] = link._queues[f"rows:{EVENTS}"]
    assert list(cols["text"]) == ["hedgehog silent"] and list(t_ns) == [2]
