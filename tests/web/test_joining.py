"""A page joining a long run: its history in blocks, in messages of at most 64 KiB, each long
one followed by the next only once the page says it handled it (``/ws?ack=1``)."""

from __future__ import annotations

import json
import time

import numpy as np
from monitor_procs import start_monitor

from omnical.recording.topics import GROUND_TRUTH, ODOM
from omnical.web.protocol import HISTORY_POINTS, MonitorTarget
from omnical.web.server import ACK_BYTES, ACK_WAIT_S, BATCH_BYTES
from omnical.web.tee import MonitorLink
from omnical.web.wsclient import WebSocketClient

ROWS = HISTORY_POINTS["odom"]


def _long_run(port: int) -> MonitorLink:
    """80 s of odometry and truth at 49.75 Hz (under the link's 50 Hz thinning: every row is kept), sent
    whole (a frame a second, each sent before the next)."""
    link = MonitorLink(MonitorTarget("127.0.0.1", port), "long run").start()
    end = time.time()
    for k in range(0, ROWS, 50):
        i = np.arange(k, k + 50)
        one = np.ones(50)
        t_ns = np.round((end - (ROWS - i) * 0.0201) * 1e9).astype(np.int64)
        link.rows(ODOM, t_ns, {"x_m": 0.001 * i, "y_m": one, "yaw_rad": 0 * one,
                               "vx_mps": 0.05 * one, "vy_mps": 0 * one, "wz_radps": 0 * one})  # fmt: skip
        link.rows(GROUND_TRUTH, t_ns, {"x_m": 0.001 * i, "y_m": one, "yaw_rad": 0 * one})
        deadline = time.monotonic() + 10
        while link.sent < 3 + k // 25 and time.monotonic() < deadline:  # hello, the frames
            time.sleep(0.005)
    assert not link.dropped
    return link


def _odom_rows(text: str) -> int:
    message = json.loads(text)
    frames = message if isinstance(message, list) else [message]
    return sum(len(f["d"]["t"]) for f in frames if f["s"] == "odom")


def test_a_joiners_history_is_paced_by_its_acks() -> None:
    mon = start_monitor()
    link = _long_run(mon.port)
    try:
        page = WebSocketClient.connect("127.0.0.1", mon.port, "/ws?ack=1")
        page.sock.settimeout(10)
        opened = time.monotonic()
        texts = [page.recv_text()]  # not said open: the server waited for it, then gave up
        assert time.monotonic() - opened >= 0.8 * ACK_WAIT_S
        assert len(texts[0]) >= ACK_BYTES  # a long message: the next waits for its ack
        waited = time.monotonic()
        texts.append(page.recv_text())
        assert time.monotonic() - waited >= 0.8 * ACK_WAIT_S  # none came: it gave up
        for _ in range(3):
            page.send_text("ack")  # open, and both handled: the rest comes as it is acked
        rows = sum(_odom_rows(t) for t in texts)
        while rows < ROWS:
            texts.append(page.recv_text())
            rows += _odom_rows(texts[-1])
            if len(texts[-1]) >= ACK_BYTES:  # only long ones are acknowledged
                page.send_text("ack")
        page.close()
        assert max(len(t) for t in texts) <= BATCH_BYTES + 2  # blocks, <= 64 KiB a message
        assert len(texts) >= 6  # 4000 rows of each (~500 kB) in several
    finally:
        link.close()
        mon.proc.stop()


def test_a_client_that_does_not_ack_is_not_waited_for() -> None:
    """Another client (``/ws``, no ``ack=1``): its long messages go back to back."""
    mon = start_monitor()
    link = _long_run(mon.port)
    try:
        page = WebSocketClient.connect("127.0.0.1", mon.port, "/ws")
        page.sock.settimeout(10)
        opened = time.monotonic()
        texts = [page.recv_text()]
        rows = _odom_rows(texts[0])
        while rows < ROWS:
            texts.append(page.recv_text())
            rows += _odom_rows(texts[-1])
        spent = time.monotonic() - opened
        page.close()
        long_ones = sum(len(t) >= ACK_BYTES for t in texts)
        assert long_ones >= 6 and spent < (long_ones - 1) * ACK_WAIT_S  # no wait after each
    finally:
        link.close()
        mon.proc.stop()


def test_the_page_acknowledges_what_the_server_waits_for() -> None:
    """The page's bound for a long message is the server's (else one waits for the other)."""
    import re

    from omnical.web.server import STATIC_DIR

    script = (STATIC_DIR / "monitor.js").read_text()
    match = re.search(r"const ACK_CHARS = (\d+);", script)
    assert match is not None and int(match.group(1)) == ACK_BYTES
    assert "/ws?ack=1" in script
