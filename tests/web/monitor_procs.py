"""Helpers of the monitor's tests: ``omnical monitor``, ``twin serve`` and ``run`` as real
processes, and the page's own figures read through Playwright."""

from __future__ import annotations

import queue
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]  # fmt: skip


def omnical(*args: str) -> list[str]:
    """The command line of ``omnical ARGS`` in this interpreter."""
    return [sys.executable, "-c", "from omnical.cli.main import main; main()", *args]


@dataclass
class Proc:
    """A process whose stdout lines are read by a thread (``lines``)."""

    popen: subprocess.Popen[str]
    lines: queue.Queue[str] = field(default_factory=queue.Queue)
    seen: list[str] = field(default_factory=list)

    def wait_for(self, pattern: str, timeout_s: float = 30.0) -> re.Match[str]:
        """The first stdout line matching ``pattern`` (AssertionError on timeout or exit)."""
        rx = re.compile(pattern)
        for line in self.seen:
            if m := rx.search(line):
                return m
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=0.1)
            except queue.Empty:
                if self.popen.poll() is not None and self.lines.empty():
                    break
                continue
            self.seen.append(line)
            if m := rx.search(line):
                return m
        err = (
            self.popen.stderr.read() if self.popen.poll() is not None and self.popen.stderr else ""
        )
        raise AssertionError(f"no line matching {pattern!r}: {self.seen} {err}")

    def stop(self, sig: int = signal.SIGINT, timeout_s: float = 10.0) -> int:
        """Stop it with ``sig``; its exit status."""
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
            try:
                self.popen.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()
        return self.popen.returncode


def start(*args: str) -> Proc:
    """``omnical ARGS`` started, its stdout read line by line."""
    popen = subprocess.Popen(
        omnical(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1
    )
    proc = Proc(popen)

    def pump() -> None:
        assert popen.stdout is not None
        for line in popen.stdout:
            proc.lines.put(line.rstrip("\n"))

    threading.Thread(target=pump, daemon=True).start()
    return proc


@dataclass
class Monitor:
    """A running ``omnical monitor``."""

    proc: Proc
    port: int
    url: str


def start_monitor(*args: str, port: int = 0) -> Monitor:
    """``omnical monitor --port PORT ARGS``, once it listens (port 0: the one it picked)."""
    proc = start("monitor", "--port", str(port), *args)
    m = proc.wait_for(r"omnical monitor: (http://\S+:(\d+)/\S*)")
    return Monitor(proc, int(m.group(2)), m.group(1))


def figures(page: Any) -> dict[str, Any]:
    """The page's own figures (``window.__monitor``)."""
    return page.evaluate(
        """() => { const m = window.__monitor; return {frames: m.frames, byStream: m.byStream,
        draws: m.draws, odomDraws: m.odomDraws, errors: m.errors, connected: m.connected,
        connects: m.connects, latched: m.latched, mode: m.mode, latency: m.latency.slice(-2000),
        odomDrawTimes: m.odomDrawTimes.slice(-2000)}; }"""
    )


def wait_until(page: Any, js: str, timeout_s: float = 15.0) -> None:
    """Wait until the page's ``js`` expression (on ``m = window.__monitor``) is true."""
    page.wait_for_function(f"() => {{ const m = window.__monitor; return !!(m && ({js})); }}",
                           timeout=timeout_s * 1e3)  # fmt: skip


def new_page(browser: Any, url: str) -> tuple[Any, list[str]]:
    """A page at ``url`` and the list its page errors and console errors go to."""
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.goto(url)
    return page, errors


def page_frames(ws: Any) -> list[dict[str, Any]]:
    """The frames of a page's next WebSocket message (one, or the batch that waited)."""
    import json

    message: Any = json.loads(ws.recv_text())
    frames: list[dict[str, Any]] = message if isinstance(message, list) else [message]
    return frames
