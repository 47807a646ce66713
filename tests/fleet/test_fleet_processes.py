"""A sweep on a Dask scheduler and worker started as processes on 127.0.0.1 (``dask://``), and a
sweep killed by SIGTERM mid-way then resumed (issue 27). Real processes in wall-clock time:
``alone`` (see pyproject.toml)."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from omnical.cli.main import app

runner = CliRunner()
_OMNICAL = [sys.executable, "-c", "from omnical.cli.main import main; main()"]
_DASK = str(Path(sys.executable).with_name("dask"))

SPEC = """\
twin: default
iterations: 1
parameters:
  true_factors.scale.lateral: {uniform: [1.05, 1.2]}
  ips.nlos_probability: {choice: [0.0, 0.1]}
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _wait_for_port(port: int, proc: subprocess.Popen[bytes], limit_s: float = 60.0) -> None:
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        assert proc.poll() is None, "the scheduler exited"
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
        except OSError:
            time.sleep(0.1)
            continue
        return
    pytest.fail(f"no scheduler listening on 127.0.0.1:{port} after {limit_s:g} s")


def _stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _serial_table(spec: Path, out: Path, runs: int, seed: int) -> str:
    args = ["sweep", str(spec), "--runs", str(runs), "--seed", str(seed)]
    result = runner.invoke(app, [*args, "--executor", "serial", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return (out / "sweep.csv").read_text(encoding="utf-8")


@pytest.mark.alone
def test_a_scheduler_and_a_worker_as_processes_give_the_same_table(tmp_path: Path) -> None:
    spec = tmp_path / "spec.yaml"
    spec.write_text(SPEC, encoding="utf-8")
    port = _free_port()
    address = f"127.0.0.1:{port}"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    scheduler = subprocess.Popen(
        [_DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], **quiet
    )
    worker = None
    try:
        _wait_for_port(port, scheduler)  # a loaded machine: the scheduler may take seconds
        worker = subprocess.Popen(
            [_DASK, "worker", f"tcp://{address}", "--nthreads", "1", "--no-dashboard"], **quiet
        )
        args = ["sweep", str(spec), "--runs", "4", "--seed", "5", "--chunk", "1"]
        result = runner.invoke(
            app, [*args, "--executor", f"dask://{address}", "--out", str(tmp_path / "dask")]
        )
        assert result.exit_code == 0, result.output
    finally:
        if worker is not None:
            _stop(worker)
        _stop(scheduler)
    dask = (tmp_path / "dask" / "sweep.csv").read_text(encoding="utf-8")
    assert dask == _serial_table(spec, tmp_path / "serial", 4, 5)


@pytest.mark.alone
def test_resume_after_sigterm_finishes_without_redoing_rows(tmp_path: Path) -> None:
    spec = tmp_path / "spec.yaml"
    spec.write_text(SPEC, encoding="utf-8")
    out = tmp_path / "sweep"
    runs = 6
    args = [*_OMNICAL, "sweep", str(spec), "--runs", str(runs), "--seed", "9", "--out", str(out)]
    proc = subprocess.Popen(
        [*args, "--executor", "local:1", "--chunk", "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    table = out / "sweep.csv"
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if table.exists() and len(table.read_text(encoding="utf-8").splitlines()) >= 3:
                break
            time.sleep(0.05)
        assert proc.poll() is None, "the sweep ended before it could be stopped"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143, err.decode()
    assert err.decode().strip().endswith("omnical: terminated")
    kept = table.read_text(encoding="utf-8").splitlines()
    done = len(kept) - 1
    assert 2 <= done < runs

    resumed = subprocess.run(
        [*args, "--executor", "serial", "--resume"], capture_output=True, timeout=300, check=False
    )
    assert resumed.returncode == 0, resumed.stderr.decode()
    assert f"({done} done before the resume)" in resumed.stdout.decode()
    final = table.read_text(encoding="utf-8")
    assert set(kept) <= set(final.splitlines())  # the rows written before the kill, kept
    assert final == _serial_table(spec, tmp_path / "serial", runs, 9)
