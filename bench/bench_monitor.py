"""Monitor benchmark: server → page latency, the page's odometry draw rate, and the control loop
of a live twin run with 0 and 3 pages (one of them stalled) on ``omnical monitor``.

A live twin run: the twin served on pseudo-terminals in this process (``TwinDeviceServer``, as
``twin serve``), a motion script run on it over serial (``SerialRig``, as ``omnical run --robot
serial:...``) recording through the monitor's tee, and the served twin's own feed — both
streaming to an ``omnical monitor`` subprocess. The loop's period is the wall time between the
runner's ticks (the script's command rate); its figures with 0 pages are the baseline of the
ratio. The three pages: two chromium pages (Playwright, Debian's /usr/bin/chromium) and one
client that completes the WebSocket handshake and never reads (a stalled browser: its socket
buffers fill up, its queues drop their oldest frames).

Targets (issue 26): latency median <= 5 ms, p99 <= 50 ms; odometry drawn at >= 40 Hz (here: the
page's redraws that had a new pose to draw, the run's 20 Hz odometry and the served twin's 50 Hz
truth); the loop's period within 1 % with three pages connected, one stalled.

Before/after: the whole measure with the monitor sending every frame in a message of its own
(``--batch 1``, the baseline) and with the frames that waited in one message (the default);
the ratio of the latency figures is printed, with the load average. The p99 is printed over
everything a page got, and apart: on joining (latched data, history, before the run), the
run's first 50 frames (its start) and the rest (steady state).

Against another commit's monitor (its server and page), alternately in one process:
``--baseline-src DIR`` (e.g. ``git archive COMMIT src | tar -x -C /tmp/old`` and
``/tmp/old/src``), batched only, ``--repeats`` rounds.

``--history-s 80``: before the pages join, an earlier run of 80 s is sent whole (50 Hz rows),
so they join the full history the monitor keeps (4000 rows a trail), not the last run's few
hundred. ``--why``: for each page, where its joining frames' and its slowest 1 %'s latency went
(the server's attach and the longest call holding its loop; the page's wait before a message's
task ran, with the draws and long tasks in it, its parse and the handlers before each frame).

Run: ``.venv/bin/python bench/bench_monitor.py [--seconds 12] [--repeats 1] [--why]``.
"""

from __future__ import annotations

import argparse
import re
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time
from typing import Any

import numpy as np

from omnical.experiment.rig import run_script_on
from omnical.experiment.script import parse_script
from omnical.recording.recording import RecordingBuilder
from omnical.robot.loader import load_robot
from omnical.services.hil import HostClock, SerialRig, serial_devices
from omnical.twin.device import TwinDeviceServer
from omnical.twin.params import default_twin
from omnical.web.device_feed import feed_device
from omnical.web.protocol import MonitorTarget
from omnical.web.tee import MonitorLink, MonitorTee
from omnical.web.wsclient import WebSocketClient

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]  # fmt: skip


def start_monitor(batch: int, src: str | None = None) -> tuple[subprocess.Popen[str], int]:
    """``omnical monitor --port 0 --batch BATCH`` and the port it listens on; ``src``: the
    monitor (server and page) from that source tree instead (``PYTHONPATH``)."""
    import os

    env = dict(os.environ, PYTHONPATH=src) if src is not None else None
    proc = subprocess.Popen(
        [sys.executable, "-c", "from omnical.cli.main import main; main()", "monitor",
         "--port", "0", "--beacons", "default", "--batch", str(batch)],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env,
    )  # fmt: skip
    assert proc.stdout is not None
    for line in proc.stdout:
        if m := re.search(r"http://\S+:(\d+)/", line):
            threading.Thread(target=proc.stdout.read, daemon=True).start()
            return proc, int(m.group(1))
    msg = "omnical monitor did not start"
    raise RuntimeError(msg)


def stalled_client(port: int) -> WebSocketClient:
    """A page that connects and never reads (small receive buffer: it stalls at once)."""
    ws = WebSocketClient.connect("127.0.0.1", port, "/ws")
    ws.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    return ws


def live_twin_run(port: int, seconds: float) -> dict[str, Any]:
    """A script of ``seconds`` on the served twin over serial, teed to the monitor at ``port``;
    the wall-clock intervals between the runner's ticks."""
    robot = load_robot("rosy-mecanum")
    server = TwinDeviceServer(robot, default_twin(robot))
    server.start()
    target = MonitorTarget("127.0.0.1", port)
    feed_link = MonitorLink(target, "twin serve", reset=False).start()
    stop = threading.Event()
    feeder = threading.Thread(target=feed_device, args=(server, feed_link, stop), daemon=True)
    feeder.start()
    link = MonitorLink(target, "run").start()
    script = parse_script(
        {
            "name": "bench",
            "steps": [{"move": {"vx_mps": 0.2, "vy_mps": 0.1, "duration_s": seconds}}],
        },
        robot.limits,
    )
    ticks: list[float] = []
    clock = HostClock()
    try:
        with serial_devices(
            server.vehicle_path, 115200, server.hedge_path, 115200, robot, clock,
            host_watchdog_s=0.5, say=lambda _: None,
        ) as (driver, hedge):  # fmt: skip
            rig = SerialRig(driver, hedge, clock, abort_key=False, flush_every_s=0.05)
            sink = MonitorTee(RecordingBuilder(), link)
            log = run_script_on(
                rig, script, sink, lead_in_s=0.5, tail_s=0.2,
                on_tick=lambda _e, _t: ticks.append(time.perf_counter()),
            )  # fmt: skip
    finally:
        stop.set()
        feeder.join(2.0)
        link.close()
        feed_link.close()
        server.stop()
    period = np.diff(np.array(ticks)) * 1e3
    return {
        "interrupted": log.interrupted,
        "rate_hz": script.rate_hz,
        "mean_ms": float(period.mean()),
        "median_ms": float(np.median(period)),
        "p99_ms": float(np.percentile(period, 99)),
        "max_ms": float(period.max()),
        "sent": link.sent + feed_link.sent,
        "dropped": sum(link.dropped.values()) + sum(feed_link.dropped.values()),
        "connects": link.connects + feed_link.connects,
    }


def feed_history(port: int, seconds: float) -> None:
    """An earlier run of ``seconds`` sent whole before the pages join: odometry, truth, fixes
    and commands at 49.75 Hz (under the link's 50 Hz thinning: all kept; wall-clock stamps
    ending now), so a page joins a full history (4000 rows a trail at 80 s) instead of the
    last run's few hundred."""
    from omnical.recording.topics import CMD_VEL, GROUND_TRUTH, HEDGE_POS_ANG, ODOM

    link = MonitorLink(MonitorTarget("127.0.0.1", port), "earlier run").start()
    period_s = 0.0201
    n, end = round(seconds / period_s), time.time()
    frames = 0
    for k in range(0, n, 50):  # a second at a time, each sent before the next is queued
        i = np.arange(k, min(k + 50, n))
        t_s = end - (n - i) * period_s
        t_ns = np.round(t_s * 1e9).astype(np.int64)
        x, y, yaw = 0.5 + 0.01 * np.cos(i / 200), 0.5 + 0.01 * np.sin(i / 200), i / 200
        z = np.zeros(len(i))
        link.rows(ODOM, t_ns, {"x_m": x, "y_m": y, "yaw_rad": yaw, "vx_mps": z + 0.1,
                               "vy_mps": z, "wz_radps": z + 0.25})  # fmt: skip
        link.rows(GROUND_TRUTH, t_ns, {"x_m": x, "y_m": y, "yaw_rad": yaw})
        link.rows(HEDGE_POS_ANG, t_ns, {"x_m": x + 0.02, "y_m": y, "flags": z.astype(int)})
        link.rows(CMD_VEL, t_ns, {"vx_mps": z + 0.1, "vy_mps": z, "wz_radps": z + 0.25})
        frames += 4
        deadline = time.monotonic() + 5
        while link.sent < frames and time.monotonic() < deadline:
            time.sleep(0.002)
    link.close()
    if link.dropped:
        msg = f"the earlier run's history was not all sent: {link.dropped}"
        raise RuntimeError(msg)


BATCH = 32
"""The monitor's default (``--batch``): up to this many waiting frames in one message."""

START_FRAMES = 50
"""The run's start: its first frames on the page (the slowest samples were there)."""


def _p99(lat: np.ndarray) -> float:
    return float(np.percentile(lat, 99)) if len(lat) else float("nan")


def page_figures(page: Any, since_ms: float, joined: int) -> dict[str, float]:
    """Latency median / p99 (ms) and redraws with a new pose per second, from a page's figures;
    the p99 of the frames it got on joining (``joined``: before the run), of the run's first
    :data:`START_FRAMES` and of the rest (steady state)."""
    f = page.evaluate(
        "() => ({lat: window.__monitor.latency.slice(), draws: window.__monitor.odomDrawTimes.slice(),"
        " map: window.__monitor.drawMapMs.slice(), plots: window.__monitor.drawPlotsMs.slice()})"
    )
    lat = np.array(f["lat"], dtype=np.float64)
    start, steady = lat[joined : joined + START_FRAMES], lat[joined + START_FRAMES :]
    draws = np.array([t for t in f["draws"] if t >= since_ms], dtype=np.float64)
    span_s = (draws[-1] - draws[0]) / 1e3 if len(draws) > 1 else float("nan")
    return {
        "latency_median_ms": float(np.median(lat)) if len(lat) else float("nan"),
        "latency_p99_ms": _p99(lat),
        "join_p99_ms": _p99(lat[:joined]),
        "joined": float(joined),
        "start_p99_ms": _p99(start),
        "start_max_ms": float(start.max()) if len(start) else float("nan"),
        "steady_p99_ms": _p99(steady),
        "odom_draw_hz": (len(draws) - 1) / span_s if len(draws) > 1 else 0.0,
        "frames": float(len(lat)),
        "map_ms": float(np.median(f["map"])) if f["map"] else float("nan"),
        "map_p99_ms": float(np.percentile(f["map"], 99)) if f["map"] else float("nan"),
        "plots_ms": float(np.median(f["plots"])) if f["plots"] else float("nan"),
        "plots_p99_ms": float(np.percentile(f["plots"], 99)) if f["plots"] else float("nan"),
    }


def why_figures(page: Any, joined: int) -> str:
    """Where a page's slow frames' latency went (``--why``): on the server (its ``attach``
    and the longest call holding its loop) and in the page (per message: the wait before its
    task ran, the parse, the handlers before each frame; draws and long tasks in that wait)."""
    w = page.evaluate(
        "() => { const m = window.__monitor; return {lat: m.latency.slice(), "
        "msgs: m.messages ? m.messages.slice() : null, before: m.handledMs ? m.handledMs.slice() : null,"
        " draws: m.drawSpans ? m.drawSpans.slice() : [], longs: m.longTasks ? m.longTasks.slice() : [],"
        " attach: m.attach || null, busy: m.busyMs ? m.busyMs.slice() : [], origin: performance.timeOrigin,"
        " renders: m.renderSpans ? m.renderSpans.slice() : [], handlers: m.handlerMs || {},"
        " opened: m.openedAt === undefined ? null : m.openedAt}; }"
    )
    if w["msgs"] is None or w["before"] is None:
        return "(no per-message figures: an older page)"
    lat = np.array(w["lat"], dtype=np.float64)
    # each frame's message: its task start, wait (of the first frame), parse, bytes
    rows = []
    for start, nbytes, n, parse, _handled, wait in w["msgs"]:
        rows += [(start, nbytes, parse, wait if wait is not None else float("nan"))] * int(n)
    rows = rows[-len(lat) :]
    before = np.array(w["before"][-len(lat) :], dtype=np.float64)
    if len(rows) != len(lat) or len(before) != len(lat):
        return f"(figures out of step: {len(rows)} frames in messages, {len(lat)} latencies)"
    start = np.array([r[0] for r in rows])
    nbytes = np.array([r[1] for r in rows])
    parse = np.array([r[2] for r in rows])
    wait = lat - parse - before  # from the send stamp to the message's task
    draws = np.array(w["draws"], dtype=np.float64).reshape(-1, 2)
    longs = np.array(w["longs"], dtype=np.float64).reshape(-1, 2)
    renders = np.array(w["renders"], dtype=np.float64).reshape(-1, 2)

    def busy_in(spans: np.ndarray, a: float, b: float) -> float:
        if not len(spans):
            return 0.0
        lo, hi = np.maximum(spans[:, 0], a), np.minimum(spans[:, 0] + spans[:, 1], b)
        return float(np.clip(hi - lo, 0, None).sum())

    def part(idx: np.ndarray, name: str) -> str:
        if not len(idx):
            return f"{name}: none"
        k = idx[np.argmax(lat[idx])]
        drawn = busy_in(draws, start[k] - wait[k], start[k])
        long_ms = busy_in(longs, start[k] - wait[k], start[k])
        rendered = busy_in(renders, start[k] - wait[k], start[k])
        return (
            f"{name} ({len(idx)} frames, {len(np.unique(start[idx]))} messages, "
            f"{nbytes[idx].max() / 1e3:.0f} kB largest): worst {lat[k]:.1f} ms = wait "
            f"{wait[k]:.1f} (draws in it {drawn:.1f}, animation frames with their rendering "
            f"{rendered:.1f}, long tasks {long_ms:.1f}) + parse "
            f"{parse[k]:.1f} + handlers before it {before[k]:.1f}; mean over them: wait "
            f"{wait[idx].mean():.1f}, parse {parse[idx].mean():.1f}, before {before[idx].mean():.1f}"
        )

    out = []
    attach = w["attach"]
    if attach is not None and joined:
        # a message's send stamp (server clock): the page's receipt less its first frame's wait
        sent = w["origin"] + start[:joined] - np.array([r[3] for r in rows[:joined]])
        out.append(f"server: attach {attach['ms']:.1f} ms, its frames written "
                   f"{np.nanmin(sent) - attach['at']:.1f}–{np.nanmax(sent) - attach['at']:.1f} ms "
                   f"after it began; the loop's longest hold in a second "
                   f"{max(w['busy'], default=float('nan')):.1f} ms")  # fmt: skip
    out.append(part(np.arange(min(joined, len(lat))), "joining"))
    if w["opened"] is not None and joined:
        last = start[joined - 1] + parse[joined - 1] + before[joined - 1]
        out.append(f"the first message was sent {start[0] - wait[0] - w['opened']:.1f} ms after "
                   f"the socket opened, the last joining frame handled "
                   f"{last - w['opened']:.1f} ms after; the longest handler of each stream (ms): " + ", ".join(
                   f"{s} {v:.1f}" for s, v in sorted(w["handlers"].items(), key=lambda i: -i[1])[:5]))  # fmt: skip
    out.append(part(np.arange(joined, min(joined + START_FRAMES, len(lat))), "the run's start"))
    top = np.flatnonzero(lat >= np.percentile(lat, 99)) if len(lat) else np.array([], int)
    out.append(part(top, "the slowest 1 %"))
    return "\n    ".join(out)


def measure(
    browser: Any,
    batch: int,
    seconds: float,
    repeats: int,
    src: str | None = None,
    why: bool = False,
    history_s: float = 0.0,
) -> dict[str, Any]:
    """The loop with 0 and 3 pages, and the pages' figures, on a monitor sending ``batch``
    (from the source tree ``src`` if given)."""
    proc, port = start_monitor(batch, src)
    try:
        results: dict[str, list[dict[str, Any]]] = {"0 pages": [], "3 pages (1 stalled)": []}
        figures: list[dict[str, float]] = []
        rates = ""
        for _ in range(repeats):
            results["0 pages"].append(live_twin_run(port, seconds))
            if history_s > 0:
                feed_history(port, history_s)
            pages = [browser.new_page(viewport={"width": 1280, "height": 800}) for _ in range(2)]
            for page in pages:
                page.goto(f"http://127.0.0.1:{port}/")
                page.wait_for_function("() => window.__monitor && window.__monitor.connected")
            stalled = stalled_client(port)
            # what a page gets on joining, before the run (a full history, paced by the
            # page's acks, takes up to ~0.6 s on a quiet machine)
            pages[0].wait_for_timeout(800)
            since = pages[0].evaluate("() => performance.now()")
            joined = [page.evaluate("() => window.__monitor.latency.length") for page in pages]
            results["3 pages (1 stalled)"].append(live_twin_run(port, seconds))
            rates = pages[0].inner_text("#rates")
            figures += [page_figures(page, since, n) for page, n in zip(pages, joined, strict=True)]
            if why:
                for k, (page, n) in enumerate(zip(pages, joined, strict=True), 1):
                    print(f"  why, page {k}: " + why_figures(page, n), flush=True)
            stalled.sock.close()
            for page in pages:
                page.close()
        return {"results": results, "figures": figures, "rates": rates}
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(10)


def compare_sources(
    baseline: str, seconds: float, repeats: int, why: bool = False, history_s: float = 0.0
) -> None:
    """The batched monitor of ``baseline`` and of this tree, alternately (the order swapped
    every round: a load trend's bias), ``repeats`` rounds; the pages' figures of each."""
    import os

    from playwright.sync_api import sync_playwright

    keys = ("join_p99_ms", "start_p99_ms", "steady_p99_ms", "latency_p99_ms", "latency_median_ms")
    figures: dict[str, list[dict[str, float]]] = {"baseline": [], "this tree": []}
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        for k in range(repeats):
            for which in ("baseline", "this tree") if k % 2 == 0 else ("this tree", "baseline"):
                load = os.getloadavg()[0]
                src = baseline if which == "baseline" else None
                got = measure(browser, BATCH, seconds, 1, src, why, history_s)["figures"]
                figures[which] += got
                print(f"{which} (load {load:.1f}): " + "; ".join(
                    " ".join(f"{key.removesuffix('_ms')} {f[key]:.1f}" for key in keys) for f in got
                ), flush=True)  # fmt: skip
        browser.close()
    for key in keys:
        b = [f[key] for f in figures["baseline"]]
        a = [f[key] for f in figures["this tree"]]
        bound = 5 if key == "latency_median_ms" else 50  # the targets
        print(
            f"{key}: baseline median {np.median(b):.1f} ({min(b):.1f}–{max(b):.1f}; <= {bound} ms "
            f"on {sum(x <= bound for x in b)} of {len(b)}), this tree {np.median(a):.1f} "
            f"({min(a):.1f}–{max(a):.1f}; {sum(x <= bound for x in a)} of {len(a)}), ratio "
            f"{np.median(a) / np.median(b):.2f}"
        )
    print(f"load average after: {os.getloadavg()[0]:.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=12.0, help="length of each live run")
    parser.add_argument("--repeats", type=int, default=1, help="runs per configuration")
    parser.add_argument(
        "--batched-first", action="store_true", help="measure batched, then the baseline"
    )
    parser.add_argument(
        "--baseline-src",
        metavar="DIR",
        help="instead: the batched monitor from DIR (another commit's src/, e.g. by git archive) "
        "against this one, alternately --repeats times; the pages' p99 on joining, at the "
        "run's start and in steady state, and their ratios",
    )
    parser.add_argument(
        "--why",
        action="store_true",
        help="print where each page's slowest frames' latency went: the server's attach and "
        "loop, the page's wait for its task (draws, long tasks in it), parse and handlers",
    )
    parser.add_argument(
        "--history-s",
        type=float,
        default=0.0,
        metavar="S",
        help="before the pages join, an earlier run of S seconds sent whole (50 Hz rows: at "
        "80, the 4000 rows a trail the monitor keeps); 0: the last live run's history only",
    )
    args = parser.parse_args()
    import os

    from playwright.sync_api import sync_playwright

    if args.baseline_src is not None:
        compare_sources(args.baseline_src, args.seconds, args.repeats, args.why, args.history_s)
        return

    print(f"live twin runs of {args.seconds:g} s over serial; load average before "
          f"{os.getloadavg()[0]:.1f}")  # fmt: skip
    measured: dict[int, dict[str, Any]] = {}
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        for batch in (32, 1) if args.batched_first else (1, 32):  # order: a load trend's bias
            measured[batch] = measure(
                browser, batch, args.seconds, args.repeats, why=args.why, history_s=args.history_s
            )
        browser.close()
    measured = {b: measured[b] for b in (1, 32)}
    for batch, m in measured.items():
        what = "one frame a message (baseline)" if batch == 1 else f"up to {batch} frames a message"
        print(f"--- {what}")
        results = m["results"]
        for name, runs in results.items():
            mean = statistics.fmean(r["mean_ms"] for r in runs)
            print(
                f"control loop, {name}: period mean {mean:.3f} ms, median "
                f"{statistics.fmean(r['median_ms'] for r in runs):.3f} ms, p99 "
                f"{statistics.fmean(r['p99_ms'] for r in runs):.2f} ms, max "
                f"{max(r['max_ms'] for r in runs):.1f} ms ({runs[0]['rate_hz']:g} Hz script; "
                f"frames sent {runs[-1]['sent']}, dropped at the run {runs[-1]['dropped']}, "
                f"connections {runs[-1]['connects']})"
            )
        base = statistics.fmean(r["mean_ms"] for r in results["0 pages"])
        loaded = statistics.fmean(r["mean_ms"] for r in results["3 pages (1 stalled)"])
        print(
            f"ratio of the loop's mean period, 3 pages / 0 pages: {loaded / base:.4f} (target within 1 %)"
        )
        for k, f in enumerate(m["figures"], 1):
            print(
                f"page {k}: server → page latency median {f['latency_median_ms']:.2f} ms, p99 "
                f"{f['latency_p99_ms']:.2f} ms (targets 5 / 50 ms) [p99 on joining "
                f"{f['join_p99_ms']:.1f} ms ({f['joined']:.0f} frames), the run's first "
                f"{START_FRAMES} frames {f['start_p99_ms']:.1f} ms (max {f['start_max_ms']:.1f}), "
                f"steady {f['steady_p99_ms']:.1f} ms]; new poses (odometry, truth) drawn at "
                f"{f['odom_draw_hz']:.1f} Hz (target >= 40); {f['frames']:.0f} frames; a map "
                f"redraw {f['map_ms']:.1f} ms (p99 {f['map_p99_ms']:.1f}), the plots "
                f"{f['plots_ms']:.1f} ms (p99 {f['plots_p99_ms']:.1f})"
            )
        print(f"the page's stream rates (rows/s): {m['rates']}")
    before, after = measured[1]["figures"], measured[32]["figures"]
    for key in ("latency_median_ms", "latency_p99_ms", "start_p99_ms", "steady_p99_ms"):
        b = statistics.fmean(f[key] for f in before)
        a = statistics.fmean(f[key] for f in after)
        print(f"{key}: one frame a message {b:.2f}, batched {a:.2f} (ratio {a / b:.2f})")
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
