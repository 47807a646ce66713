"""The monitor's page in a real browser (Playwright driving Debian's chromium) against real
``omnical monitor``, ``twin serve`` and ``run`` processes: frames arrive, the page draws without
an error, a late joiner gets the map and the beacons, a recording replays, the token guards."""

from __future__ import annotations

import re
import signal
import statistics
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from monitor_procs import Monitor, figures, new_page, start, start_monitor, wait_until

from omnical.bags.bag import write_bag
from omnical.errors import ProtocolError
from omnical.recording.recording import RecordingBuilder
from omnical.recording.topics import BEACONS_POS_A, CMD_VEL, EVENTS, HEDGE_POS_ANG, ODOM
from omnical.web.protocol import MonitorTarget, map_payload
from omnical.web.replay import load_replay
from omnical.web.tee import MonitorLink
from omnical.web.wsclient import WebSocketClient


def _inked_pixels(page: Any) -> int:
    """Pixels of the map canvas that are not blank (something was drawn)."""
    return int(page.evaluate(
        """() => { const c = document.getElementById('map'); const d = c.getContext('2d')
        .getImageData(0, 0, c.width, c.height).data; let n = 0;
        for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++; return n; }"""
    ))  # fmt: skip


def test_a_served_twin_streams_to_the_page_which_draws_it(monitor: Monitor, browser: Any) -> None:
    served = start("twin", "serve", "--monitor", str(monitor.port))
    try:
        page, errors = new_page(browser, monitor.url)
        wait_until(page, "(m.byStream.truth || 0) > 60 && (m.byStream.status || 0) > 0", 30)
        f = figures(page)
        assert f["connected"] and f["latched"].get("beacons") and f["latched"].get("source")
        assert f["odomDraws"] >= 20 and f["draws"] >= f["odomDraws"]
        assert "odom" not in f["byStream"]  # the odometry is the run's to send
        lat = f["latency"]
        assert lat and all(-5.0 < x < 5000.0 for x in lat)  # same machine: ms, not garbage
        assert page.inner_text("#badge") == "live"
        assert page.inner_text("#battery") == "12.3 V"
        assert page.inner_text("#watchdog") == "firmware off"
        assert "omnical twin serve" in page.inner_text("#source")
        assert "odom" in page.inner_text("#rates") or f["frames"] > 0
        assert _inked_pixels(page) > 5000
        assert errors == [] and f["errors"] == []
        page.close()
    finally:
        assert served.stop(signal.SIGINT) == 130


def test_a_run_streams_fixes_commands_events_and_the_error(
    monitor: Monitor, browser: Any, tmp_path: Path
) -> None:
    page, errors = new_page(browser, monitor.url)
    wait_until(page, "m.connected", 10)
    run = start("run", "straight-10m", "--robot", "twin", "--out", str(tmp_path / "r.mcap"),
                "--monitor", str(monitor.port))  # fmt: skip
    run.wait_for(r"^wrote ", 120)
    assert run.popen.wait(30) == 0
    wait_until(page, "(m.byStream.error || 0) > 0 && (m.byStream.fused || 0) > 0", 20)
    f = figures(page)
    for stream in ("odom", "fix", "cmd", "truth", "events", "origin"):
        assert f["byStream"].get(stream, 0) > 0, stream
    assert page.locator("#log li").count() >= 1  # "omnical run connected", the run's events
    # the odometry − IPS error plot has points (uPlot draws its series into a canvas)
    points = page.evaluate("() => window.__monitor.state.err.t.length")
    assert points > 20
    # the run sent its whole odometry before its fixes: each fix is paired with the odometry
    # of its time (centimetres, as the replay shows), not the last pose (metres); the fused
    # pose ends where the robot ended, not at its start (audit item 1)
    e = page.evaluate("() => window.__monitor.state.err.e")
    assert statistics.median(e) < 0.3 and max(e) < 1.0, (statistics.median(e), max(e))
    end = page.evaluate("""() => { const S = window.__monitor.state, t = S.truth[S.truth.length - 1];
        return Math.hypot(S.fused.x - t[0], S.fused.y - t[1]); }""")  # fmt: skip
    assert end < 0.5
    # sent whole, faster than real time: said so, not as rates of thousands of Hz (item 5)
    wait_until(page, "document.getElementById('rates').innerText.startsWith('sent whole')", 5)
    assert "(robot time)" in page.inner_text("#runtime")
    # its step markers at the times a replay of its recording shows (audit item 9)
    replayed = load_replay(tmp_path / "r.mcap")
    want = {e["text"]: e["t"] - replayed["t0"] for e in replayed["events"] if e["kind"] == "step"}
    shown = {}
    for li in page.locator("#log li").all_inner_texts():
        stamp, _, text = li.partition(" s")
        if text in want:
            shown[text] = float(stamp.removeprefix("t+"))
    assert len(shown) == len(want) >= 4
    assert all(abs(shown[k] - want[k]) < 0.06 for k in want), (shown, want)
    lines = page.locator("#log li").all_inner_texts()
    assert all(sum(li.endswith(k) for li in lines) == 1 for k in want), lines  # each once
    # the plots' time 0 is the run clock's: the first row at 0 (item 4)
    assert page.evaluate("() => window.__monitor.state.meas.t[0]") == pytest.approx(0.0, abs=0.1)
    # the speed plot's axis is at least ±0.5 m/s (item 11)
    y = page.evaluate(
        "() => [window.__monitor.plots.speed.scales.y.min, window.__monitor.plots.speed.scales.y.max]"
    )
    assert y[0] <= -0.5 and 0.5 <= y[1] < 5.0
    assert errors == [] and f["errors"] == []


def test_a_late_joiner_gets_the_map_and_the_beacons(browser: Any) -> None:
    mon = start_monitor("--map", "lab-8x6")
    try:
        link = MonitorLink(MonitorTarget("127.0.0.1", mon.port), "test run").start()
        link.latch("beacons", {"beacons": [{"address": 3, "x": 0.5, "y": 0.5, "z": 0.4},
                                           {"address": 4, "x": 7.5, "y": 0.5, "z": 0.4}]})  # fmt: skip
        link.event("procedure step 1")
        t0 = time.time()
        for k in range(0, 300, 30):  # 7.5 s of odometry at 40 Hz before the page joins
            ks = np.arange(k, k + 30)
            one = np.ones(30)
            link.rows(ODOM, np.round((t0 + 0.025 * ks) * 1e9).astype(np.int64),
                      {"x_m": 0.01 * ks, "y_m": one, "yaw_rad": 0 * one, "vx_mps": 0.5 * one,
                       "vy_mps": 0 * one, "wz_radps": 0 * one})  # fmt: skip
        deadline = time.monotonic() + 10
        while link.sent < 13 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert link.sent >= 13 and not link.dropped  # hello, beacons, the event, the odometry
        page, errors = new_page(browser, mon.url)  # joins after the run said all that
        wait_until(page, "m.latched.map && m.latched.beacons && m.latched.runclock", 10)
        wait_until(page, "m.state.odomRaw.length + m.state.odom.length >= 300", 10)
        state = page.evaluate(
            "() => ({b: window.__monitor.state.beacons.length, m: !!window.__monitor.state.mapImage})"
        )
        assert state == {"b": 2, "m": True}
        assert "procedure step 1" in page.inner_text("#log")
        # run time from the run's start, not from joining: the run is a few seconds old
        runtime = float(page.inner_text("#runtime").removeprefix("t+").removesuffix(" s"))
        assert runtime >= time.time() - t0 - 0.5
        assert page.evaluate("() => window.__monitor.state.meas.t.length") >= 300
        link.close()
        assert _inked_pixels(page) > 5000
        assert errors == []
    finally:
        mon.proc.stop()


def _recording(path: Path) -> Path:
    """A 20-s circle: odometry at 20 Hz, fixes at 8 Hz, commands, beacons and events."""
    b = RecordingBuilder()
    t0 = 1_700_000_000_000_000_000
    t = np.arange(0.0, 20.0, 0.05)
    ang = 2 * np.pi * t / 20.0
    b.add_many(ODOM, t0 + (t * 1e9).astype(np.int64), x_m=np.sin(ang), y_m=1 - np.cos(ang),
               yaw_rad=ang, vx_mps=np.full_like(t, 0.314), vy_mps=np.zeros_like(t),
               wz_radps=np.full_like(t, 0.314))  # fmt: skip
    b.add_many(CMD_VEL, t0 + (t * 1e9).astype(np.int64), vx_mps=np.full_like(t, 0.3),
               vy_mps=np.zeros_like(t), wz_radps=np.full_like(t, 0.3))  # fmt: skip
    tf = np.arange(0.0, 20.0, 0.125)
    af = 2 * np.pi * tf / 20.0
    n = len(tf)
    b.add_many(HEDGE_POS_ANG, t0 + (tf * 1e9).astype(np.int64), address=np.full(n, 10),
               timestamp_ms=(tf * 1e3).astype(np.int64), x_m=2 + np.sin(af) + 0.02,
               y_m=2 + 1 - np.cos(af), z_m=np.full(n, 0.4), flags=np.full(n, 2),
               angle_deg=np.zeros(n))  # fmt: skip
    b.add_many(BEACONS_POS_A, np.array([t0, t0]), address=np.array([3, 4]),
               x_m=np.array([0.0, 5.0]), y_m=np.array([0.0, 0.0]), z_m=np.array([0.4, 0.4]))  # fmt: skip
    b.add_many(EVENTS, np.array([t0, t0 + 10**10]),
               text=np.array(['{"script": "circle", "step": 1, "kind": "move", "edge": "start"}',
                              "hedgehog silent"], dtype=object))  # fmt: skip
    return write_bag(b.build(), path)


def test_a_recording_replays_with_play_pause_and_the_slider(browser: Any, tmp_path: Path) -> None:
    bag = _recording(tmp_path / "circle.mcap")
    mon = start_monitor(str(bag), "--map", "lab-8x6")  # a navigate run's floor plan
    try:
        page, errors = new_page(browser, mon.url)
        wait_until(page, "m.mode === 'replay'", 15)
        assert page.is_visible("#replay")
        assert page.locator("#log li").count() == 1  # at 0 s: the event at 10 s is still ahead
        assert page.inner_text("#log li .t") == "t+0.0 s"
        page.click("#play")
        wait_until(page, "m.odomDraws > 10", 10)
        page.click("#play")  # pause
        page.evaluate("""() => { const s = document.getElementById('slider');
            s.value = s.max; s.dispatchEvent(new Event('input')); }""")
        page.wait_for_timeout(300)
        done, total = page.inner_text("#replaytime").removesuffix(" s").split(" / ")
        assert done == total and float(total) == pytest.approx(19.95, abs=0.06)
        assert page.locator("#log li .t").all_inner_texts() == ["t+0.0 s", "t+10.0 s"]
        page.evaluate("""() => { const s = document.getElementById('slider');
            s.value = 50; s.dispatchEvent(new Event('input')); }""")  # back to 5 s
        wait_until(page, "m.eventsShown === 1", 5)
        assert page.locator("#log li").count() == 1 and page.inner_text("#runtime") == "t+5.0 s"
        assert page.evaluate("() => window.__monitor.state.beacons.length") == 2
        assert page.evaluate("() => !!window.__monitor.state.mapImage")  # item 9: kept
        assert page.inner_text("#step") == "circle: step 1 move start"  # the step at 5 s
        assert _inked_pixels(page) > 5000
        # a run streaming to a replaying monitor is refused, said once; the replay stays
        heard: list[str] = []
        link = MonitorLink(MonitorTarget("127.0.0.1", mon.port), "run", on_warning=heard.append)
        link.start()
        deadline = time.monotonic() + 10
        while link.refused is None and time.monotonic() < deadline:
            time.sleep(0.05)
        link.close()
        assert link.connects == 0 and link.refused is not None and "409" in link.refused
        assert len(heard) == 1 and "replaying a recording" in heard[0]
        assert page.evaluate("() => window.__monitor.mode") == "replay"
        assert page.inner_text("#source") == "replay of circle"
        assert errors == [] and figures(page)["errors"] == []
    finally:
        mon.proc.stop()


def test_with_a_token_every_url_needs_it(browser: Any) -> None:
    mon = start_monitor("--token", "s3cret")
    try:
        assert mon.url.endswith("/?token=s3cret")
        base = f"http://127.0.0.1:{mon.port}/"
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(base, timeout=5)
        assert refused.value.code == 403
        with urllib.request.urlopen(base + "?token=s3cret", timeout=5) as ok:
            assert b"omnical monitor" in ok.read()
        with pytest.raises((ProtocolError, ConnectionError, OSError)):
            WebSocketClient.connect("127.0.0.1", mon.port, "/ingest?token=wrong")
        WebSocketClient.connect("127.0.0.1", mon.port, "/ingest?token=s3cret").close()
        page, errors = new_page(browser, mon.url)
        wait_until(page, "m.connected && m.latched.source === undefined && m.frames > 0", 10)
        assert errors == []
    finally:
        mon.proc.stop()


def test_latency_figures_are_milliseconds(monitor: Monitor, browser: Any) -> None:
    """Not a timing bound (bench/bench_monitor.py measures it): the stamps are comparable."""
    link = MonitorLink(MonitorTarget("127.0.0.1", monitor.port), "test").start()
    page, _ = new_page(browser, monitor.url)
    wait_until(page, "m.connected", 10)
    for k in range(50):
        link.rows(ODOM, [1_700_000_000_000_000_000 + k * 20_000_000],
                  {c: [0.01 * k] for c in ("x_m", "y_m", "yaw_rad", "vx_mps", "vy_mps", "wz_radps")})  # fmt: skip
    wait_until(page, "(m.byStream.odom || 0) >= 50", 10)
    lat = figures(page)["latency"]
    assert 0.0 <= statistics.median(lat) < 1000.0
    link.close()


def test_a_campaign_streams_its_steps_and_factors(
    monitor: Monitor, browser: Any, tmp_path: Path
) -> None:
    page, errors = new_page(browser, monitor.url)
    wait_until(page, "m.connected", 10)
    campaign = start(
        "calibrate", "campaign", "--out", str(tmp_path / "c"), "--no-figures", "--no-validate",
        "--max-iterations", "2", "--monitor", str(monitor.port),
    )  # fmt: skip
    assert campaign.popen.wait(300) == 0
    wait_until(page, "(m.byStream.factors || 0) >= 1", 10)
    factors = page.evaluate("() => window.__monitor.state.factors")
    assert [f["iteration"] for f in factors] == list(range(1, len(factors) + 1))
    assert (
        "scale_rotational" in factors[-1]["values"] and "scale_rotational" in factors[-1]["sigma"]
    )
    log = page.inner_text("#log")
    assert "iteration 1: rotation procedure" in log and "translation analysis" in log
    step = page.inner_text("#step")
    assert step.startswith("measures after") and "s left" in step  # the campaign's last step
    # the factors plot: a key entry per estimated factor, drawn with its ±1σ band
    keys = page.inner_text("#plot-factors .key")
    assert "scale_rotational" in keys and keys.count("■") >= 3
    assert errors == [] and figures(page)["errors"] == []


def test_navigate_latches_its_map(monitor: Monitor, browser: Any, tmp_path: Path) -> None:
    nav = start(
        "navigate", "--map", "lab-8x6", "--world", "lab-8x6", "--start", "1,1,0", "--goal", "3,2",
        "--out", str(tmp_path / "n.mcap"), "--monitor", str(monitor.port),
    )  # fmt: skip
    assert nav.popen.wait(300) == 0
    page, errors = new_page(browser, monitor.url)  # after the run: the latched map and origin
    wait_until(page, "m.latched.map && m.latched.origin", 10)
    assert page.evaluate("() => window.__monitor.state.origin") == [1.0, 1.0, 0.0]
    # the error of each fix against the odometry of its time (audit items 1 and 7)
    wait_until(page, "m.state.err.e.length > 20", 10)
    e = page.evaluate("() => window.__monitor.state.err.e")
    assert statistics.median(e) < 0.3, statistics.median(e)
    step = page.inner_text("#step")
    assert page.inner_text("#quality") != "–" and step.startswith("1 leg(s)")
    # the odometry's distance (review: 0.00 m, the tally never reached the progress line)
    travelled_m = float(re.search(r"· ([0-9.]+) m", step).group(1))  # type: ignore[union-attr]
    assert travelled_m > 1.0, step  # (1, 1) → (3, 2): at least the 2.2 m straight line
    assert errors == []


def _wait(cond: Any, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond() and time.monotonic() < deadline:
        time.sleep(0.02)


def test_a_new_run_starts_the_page_afresh_and_a_device_is_shown_as_itself(
    monitor: Monitor, browser: Any
) -> None:
    """Audit items 2, 3 and 10: the last run's map, step and factors go when a new run starts;
    a served twin beside the run has its own line; each factor is drawn as its deviation from
    its first estimate, scalings and cross-talks on their own axes."""
    page, errors = new_page(browser, monitor.url)
    wait_until(page, "m.connected", 10)
    first = MonitorLink(MonitorTarget("127.0.0.1", monitor.port), "omnical navigate").start()
    first.latch("map", map_payload(np.zeros((20, 30), dtype=np.int8), 0.1, (0.0, 0.0, 0.0)))
    first.send("progress", {"step": "to goal 1"})
    for k, (scale, cross) in enumerate([(1.020, 0.0010), (1.012, 0.0004), (1.010, 0.0002)]):
        first.send("factors", {"iteration": k + 1, "values": {"scale_x": scale, "cross_xy": cross},
                               "sigma": {"scale_x": 0.004 / (k + 1), "cross_xy": 0.0003}})  # fmt: skip
    wait_until(
        page, "m.state.map && m.state.factors.length === 3 && m.plots && m.plots.factors", 10
    )
    plot = page.evaluate("() => window.__monitor.factorPlot")
    assert plot["scale_x"]["scale"] == "pct" and plot["cross_xy"]["scale"] == "xt"
    assert plot["scale_x"]["dev"] == pytest.approx([0.0, -0.8, -1.0])  # % from the first
    assert plot["cross_xy"]["dev"] == pytest.approx([0.0, -0.6, -0.8])  # mrad/m from the first
    pct = page.evaluate(
        "() => { const s = window.__monitor.plots.factors.scales.pct; return [s.min, s.max]; }"
    )
    assert -2.0 < pct[0] < -1.0 and 0.3 < pct[1] < 2.0  # the band (0.4 %) is a visible part
    assert page.inner_text("#step") == "to goal 1"
    first.close()
    served = MonitorLink(MonitorTarget("127.0.0.1", monitor.port), "omnical twin serve",
                         reset=False).start()  # fmt: skip
    _wait(lambda: served.connected)
    second = MonitorLink(MonitorTarget("127.0.0.1", monitor.port), "omnical run").start()
    second.rows(ODOM, [1_667_865_600_000_000_000],
                {c: [0.0] for c in ("x_m", "y_m", "yaw_rad", "vx_mps", "vy_mps", "wz_radps")})  # fmt: skip
    wait_until(page, "m.state.source && m.state.source.source === 'omnical run'", 10)
    served.send("status", {"t": time.time(), "battery_v": 12.3, "firmware_watchdog": "off"})
    wait_until(page, "document.getElementById('device').innerText.includes('12.3 V')", 10)
    state = page.evaluate("""() => { const S = window.__monitor.state;
        const plot = document.getElementById('plot-factors').innerHTML;
        return {map: S.map, factors: S.factors.length, plot}; }""")  # fmt: skip
    assert state == {"map": None, "factors": 0, "plot": ""}
    assert page.inner_text("#step") == "–" and page.inner_text("#battery") == "–"
    assert page.inner_text("#source").startswith("omnical run")
    log = page.inner_text("#log")  # the log is the new run's: the last run's lines went
    assert "omnical navigate" not in log and "omnical run connected" in log, log
    assert page.is_visible("#deviceitem")
    served.close()  # the device server went: its line goes with it, the run's stays
    wait_until(page, "document.getElementById('deviceitem').hidden", 10)
    assert page.inner_text("#source").startswith("omnical run")
    second.close()
    assert errors == [] and figures(page)["errors"] == []


def test_a_late_joiner_draws_before_its_socket_opens_and_lays_its_log_out_once_a_draw(
    monitor: Monitor, browser: Any
) -> None:
    """The page's start, where its slowest frames were (p99 latency): the socket opens once the
    page has drawn itself (its first layout and plots made), and a burst of events (the 200 a
    late joiner gets) lays the page out once per draw, not once per event."""
    link = MonitorLink(MonitorTarget("127.0.0.1", monitor.port), "test run").start()
    for k in range(250):
        link.event(f"step {k}")
    _wait(lambda: link.sent >= 251)
    assert link.sent >= 251 and not link.dropped
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    cdp = page.context.new_cdp_session(page)
    cdp.send("Performance.enable")
    page.goto(monitor.url)
    wait_until(page, "m.connected && document.querySelectorAll('#log li').length === 200", 15)
    page.wait_for_timeout(100)  # a draw or two after the last event
    layouts = {m["name"]: m["value"] for m in cdp.send("Performance.getMetrics")["metrics"]}
    assert layouts["LayoutCount"] < 60, layouts["LayoutCount"]  # it was > 200: one per event
    assert page.evaluate("() => window.__monitor.drawsAtConnect") >= 1
    assert page.inner_text("#log li:last-child").endswith("step 249")
    box = page.evaluate(
        "() => { const b = document.getElementById('logbox'); return [b.scrollTop + b.clientHeight, b.scrollHeight]; }"
    )
    assert box[0] >= box[1] - 2  # scrolled to the newest line all the same
    link.close()
    assert errors == [] and figures(page)["errors"] == []
