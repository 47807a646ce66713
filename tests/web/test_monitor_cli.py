"""``omnical monitor`` and ``--monitor`` on bad input: one line, exit status 2, no traceback."""

from __future__ import annotations

import importlib.util
import socket
import subprocess
import time
from pathlib import Path
from urllib.parse import urlsplit, urlunsplit

import pytest
from monitor_procs import omnical, start_monitor
from typer.testing import CliRunner

from omnical.cli.main import app
from omnical.web.protocol import parse_monitor_target
from omnical.web.tee import MonitorLink


def _invoke(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, list(args))
    return result.exit_code, result.output


@pytest.mark.parametrize("spec", ["nope", "70000", "ftp://x:1/"])
def test_a_bad_monitor_option_is_one_line(spec: str, tmp_path: Path) -> None:
    code, out = _invoke("run", "straight-10m", "--out", str(tmp_path / "r.mcap"), "--monitor", spec)
    assert code == 2
    assert out.strip().splitlines()[-1].startswith("omnical: error: --monitor")
    assert "Traceback" not in out and not (tmp_path / "r").exists()


def test_a_port_in_use_is_one_line() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        code, out = _invoke("monitor", "--port", str(port))
    assert code == 2
    assert f"--port {port}: address 127.0.0.1:{port} already in use" in out
    assert "Traceback" not in out


def test_a_missing_extra_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "uvicorn" else real(name, *a)
    )
    code, out = _invoke("monitor")
    assert code == 2
    assert out.strip() == (
        "omnical: error: omnical monitor needs the web extra (uvicorn missing): "
        "pip install 'omnical[web]'"
    )


def test_a_bad_recording_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "x.mcap").write_bytes(b"not a bag")
    code, out = _invoke("monitor", str(tmp_path / "x.mcap"))
    assert code == 2 and out.startswith("omnical: error:") and len(out.strip().splitlines()) == 1
    code, out = _invoke("monitor", "--port", "70000")
    assert code == 2 and "--port 70000" in out


def test_monitor_and_the_option_in_the_help() -> None:
    for args in (["run", "--help"], ["calibrate", "campaign", "--help"], ["navigate", "--help"],
                 ["twin", "serve", "--help"], ["ros2", "twin", "--help"]):  # fmt: skip
        code, out = _invoke(*args)
        assert code == 0 and "--monitor" in out, args
    code, out = _invoke("--help")
    assert "monitor" in out


@pytest.mark.parametrize("args", [("--token", "sekrit"), ("--host", "0.0.0.0")])
def test_the_hint_carries_the_token_and_works(args: tuple[str, ...]) -> None:
    mon = start_monitor(*args)
    try:
        assert "?token=" in mon.url
        spec = mon.proc.wait_for(r"--monitor '(\S+)'").group(1)
        if "--host" in args:  # the page's URL names this machine; the run's, this machine
            page = urlsplit(mon.url)
            assert page.hostname == socket.gethostname().lower()
            # (only the host: the token may hold the host's name, "vm" once)
            assert spec == urlunsplit(page._replace(netloc=f"127.0.0.1:{page.port}"))
        else:
            assert spec == mon.url  # the whole URL, its token with it
        heard: list[str] = []
        link = MonitorLink(parse_monitor_target(spec), "run", on_warning=heard.append).start()
        deadline = time.monotonic() + 10
        while not link.connected and time.monotonic() < deadline:
            time.sleep(0.02)
        link.close()
        assert link.connects == 1 and heard == []
    finally:
        mon.proc.stop()


def test_twin_serve_checks_monitor_before_the_ptys_are_up() -> None:
    code, out = _invoke("twin", "serve", "--monitor", "nope")
    assert code == 2 and out.strip().startswith("omnical: error: --monitor 'nope'")
    assert "vehicle controller" not in out and "hedgehog" not in out


def test_ros2_twin_checks_monitor_before_ros2_starts() -> None:
    done = subprocess.run(
        omnical("ros2", "twin", "--monitor", "nope"),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.strip() == (
        "omnical: error: --monitor 'nope': the port must be a number within 1–65535 ([HOST:]PORT)"
    )


def test_a_run_refused_by_a_replaying_monitor_logs_no_error(tmp_path: Path) -> None:
    # uvicorn's websockets-sansio logged "ERROR: ASGI callable returned without completing
    # handshake." after the 409 it did send (a new user read it as the monitor failing)
    import numpy as np

    from omnical.bags.bag import write_bag
    from omnical.recording.recording import RecordingBuilder
    from omnical.recording.topics import ODOM

    b = RecordingBuilder()
    t = np.arange(0.0, 2.0, 0.05)
    b.add_many(ODOM, 10**18 + (t * 1e9).astype(np.int64), x_m=t, y_m=0 * t, yaw_rad=0 * t,
               vx_mps=0 * t + 1, vy_mps=0 * t, wz_radps=0 * t)  # fmt: skip
    mon = start_monitor(str(write_bag(b.build(), tmp_path / "r.mcap")))
    try:
        link = MonitorLink(parse_monitor_target(str(mon.port)), "run").start()
        deadline = time.monotonic() + 10
        while link.refused is None and time.monotonic() < deadline:
            time.sleep(0.02)
        link.close()
        assert link.refused is not None and "409" in link.refused
    finally:
        mon.proc.stop()
    assert mon.proc.popen.stderr is not None
    err = mon.proc.popen.stderr.read()
    assert "ERROR" not in err, err
