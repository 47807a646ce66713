"""A failing link for tests: a pseudo-terminal relay between a host and a device's port.

The host opens :attr:`Relay.path`; the relay forwards its bytes to the device (a
``TwinDeviceServer`` pty) and the device's bytes back, until :meth:`Relay.fail` makes the
device's side go ``silent`` (nothing forwarded), send ``garbage`` (random bytes at the same
rate) or ``close`` (the host's end hangs up). It logs when it last forwarded device bytes and
every command frame the host sent, to measure how long a moving robot went on after the failure.
"""

from __future__ import annotations

import contextlib
import os
import re
import select
import termios
import threading
import time
import tty
from typing import Literal

import numpy as np

from omnical.drivers.wheeltec import CommandParser

Mode = Literal["pass", "silent", "garbage", "close"]


class Relay:
    """Forward between a new pty (the host's) and ``device_path`` until told to fail."""

    def __init__(self, device_path: str, *, seed: int = 0) -> None:
        self.master, self._slave = os.openpty()
        tty.setraw(self.master)
        tty.setraw(self._slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self._slave)
        self._device = os.open(device_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self._device)
        self.mode: Mode = "pass"
        self.failed_at: float | None = None
        self.last_forwarded: float | None = None
        self.quiet_before_fail_s = 0.0  # device bytes last forwarded this long before fail()
        self.garbage_from: float | None = None  # when the first garbage went to the host
        self.commands: list[tuple[float, tuple[float, float, float]]] = []
        self._parser = CommandParser()
        self._rng = np.random.default_rng(seed)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="relay", daemon=True)
        self._thread.start()

    def fail(self, mode: Mode) -> float:
        """From now on, the device's side is ``mode``; returns the monotonic time of the switch."""
        self.failed_at = time.monotonic()
        if self.last_forwarded is not None:
            self.quiet_before_fail_s = self.failed_at - self.last_forwarded
        self.mode = mode
        if mode == "close":
            with contextlib.suppress(OSError):
                termios.tcflush(self._slave, termios.TCIOFLUSH)
            os.close(self._slave)  # the host's opened end stays; its reads now fail
            self._slave = -1
            os.close(self.master)
            self.master = -1
        return self.failed_at

    def moving_after(self, t_s: float) -> float:
        """Time from ``t_s`` to the last non-zero command the host sent after it (0 if none)."""
        late = [t for t, twist in self.commands if t > t_s and twist != (0.0, 0.0, 0.0)]
        return max(late) - t_s if late else 0.0

    def garbage_before_the_stop(self, error: str) -> bool:
        """Whether garbage went to the host at least 100 ms before the stop that ``error`` (the
        driver's "no valid data for X s" line) names: the last good frame plus that silence. The
        relay sends garbage as the served device sends its frames: a loaded machine can hold
        them back past the stop, when the host has rightly received nothing."""
        silence = re.search(r"no valid data for ([\d.]+) s", error)
        if silence is None or self.last_forwarded is None or self.garbage_from is None:
            return False
        return self.garbage_from + 0.1 < self.last_forwarded + float(silence[1])

    def moved(self) -> bool:
        """The host sent a non-zero command."""
        return any(twist != (0.0, 0.0, 0.0) for _, twist in self.commands)

    def close(self) -> None:
        """Stop forwarding and close every descriptor."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        for fd in (self.master, self._slave, self._device):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)

    def __enter__(self) -> Relay:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            fds = [self._device] + ([self.master] if self.master >= 0 else [])
            try:
                ready, _, _ = select.select(fds, [], [], 0.01)
            except (OSError, ValueError):
                ready = []
                if self.master < 0:
                    time.sleep(0.01)
                    continue
            now = time.monotonic()
            if self.master >= 0 and self.master in ready:
                data = self._read(self.master)
                if data:
                    for cmd in self._parser.feed(data):
                        self.commands.append((now, cmd.twist))
                    self._write(self._device, data)
            if self._device in ready:
                data = self._read(self._device)
                if not data or self.master < 0:
                    continue
                if self.mode == "pass":
                    self._write(self.master, data)
                    self.last_forwarded = now
                elif self.mode == "garbage":
                    self._write(
                        self.master,
                        self._rng.integers(0, 256, len(data)).astype(np.uint8).tobytes(),
                    )
                    if self.garbage_from is None:
                        self.garbage_from = now

    @staticmethod
    def _read(fd: int) -> bytes:
        try:
            return os.read(fd, 4096)
        except (BlockingIOError, OSError):
            return b""

    @staticmethod
    def _write(fd: int, data: bytes) -> None:
        with contextlib.suppress(BlockingIOError, OSError):
            os.write(fd, data)
