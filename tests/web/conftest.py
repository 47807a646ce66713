"""Fixtures of the monitor's tests: a live ``omnical monitor``, and Debian's chromium driven by
Playwright (``/usr/bin/chromium``, a fresh profile each launch)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import Any

import pytest
from monitor_procs import CHROMIUM, CHROMIUM_ARGS, Monitor, start_monitor


@pytest.fixture
def monitor() -> Iterator[Monitor]:
    """A live monitor with the default beacons, stopped after the test."""
    mon = start_monitor("--beacons", "default")
    try:
        yield mon
    finally:
        mon.proc.stop()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """Chromium under Playwright (skipped where Debian's chromium is not installed)."""
    if not CHROMIUM.exists():
        if os.environ.get("CI"):  # .ci/run installs it: a CI without it is broken
            pytest.fail("no /usr/bin/chromium on CI (.ci/run installs it with apt-get)")
        pytest.skip("no /usr/bin/chromium (make installs it: apt-get install chromium)")
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()
