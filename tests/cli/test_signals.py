"""Signals sent to a real omnical process: SIGINT → 130, SIGTERM → 143, one line, no traceback."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

_OMNICAL = [sys.executable, "-c", "from omnical.cli.main import main; main()"]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("sig", "status", "word"),
    [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")],
)
def test_a_signal_stops_the_demo_cleanly(
    tmp_path: Path, sig: signal.Signals, status: int, word: str
) -> None:
    proc = subprocess.Popen(
        [*_OMNICAL, "demo", "--out", str(tmp_path / "out")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(3.0)  # well inside the demo's first minute of work
    proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:  # not stopped: do not leave a demo running beside the suite
            proc.kill()
            proc.communicate()
    assert proc.returncode == status, err
    assert err.strip().splitlines()[-1] == f"omnical: {word}"
    assert "Traceback" not in err
