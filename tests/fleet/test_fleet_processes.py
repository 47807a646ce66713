"""A sweep on a Dask scheduler and worker started as processes on 127.0.0.1 (``dask://``), a
sweep killed by SIGTERM mid-way then resumed (issue 27), a fleet stopped by Ctrl-C. Real
processes in wall-clock time: ``alone`` (see pyproject.toml)."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from omnical.cli.main import app
from omnical.fleet.table import read_rows

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


_HOLD_HOOK = '''"""Loaded as ``sitecustomize`` by every interpreter tests/fleet/test_fleet_processes.py
starts: a fleet job on an empty bag file runs until the file is filled or removed (a long job,
stopped or let go). A FIFO stood for one until a bag that is no regular file was refused.
Nothing is imported here: omnical's locate is patched when it is first imported (a worker
started as the test sends Ctrl-C must not be in a long import of its site module then)."""

import sys
import time
from importlib.machinery import PathFinder

_NAME = "omnical.reports.locate"


def _hold(module):
    from pathlib import Path

    locate_bag = module.locate_bag

    def held(bag, *args, **kwargs):
        path = Path(bag)
        while path.is_file() and path.stat().st_size == 0:
            time.sleep(0.05)
        return locate_bag(bag, *args, **kwargs)

    module.locate_bag = held


class _Finder:
    @staticmethod
    def find_spec(name, path, target=None):
        if name != _NAME:
            return None
        spec = PathFinder.find_spec(name, path)
        if spec is None or spec.loader is None:
            return spec
        run = spec.loader.exec_module

        def exec_module(module):
            run(module)
            _hold(module)

        spec.loader.exec_module = exec_module
        return spec


sys.meta_path.insert(0, _Finder())
'''


@pytest.fixture(scope="module")
def held(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The environment of the processes whose fleet jobs on an empty bag wait (``_HOLD_HOOK``)."""
    hook = tmp_path_factory.mktemp("hook")
    (hook / "sitecustomize.py").write_text(_HOLD_HOOK, encoding="utf-8")
    path = os.pathsep.join(p for p in (str(hook), os.environ.get("PYTHONPATH", "")) if p)
    return {**os.environ, "PYTHONPATH": path}


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


@contextmanager
def _cluster(env: dict[str, str]) -> Iterator[str]:
    """A Dask scheduler and one single-threaded worker as processes on 127.0.0.1 (``env``
    theirs): its address."""
    port = _free_port()
    address = f"127.0.0.1:{port}"
    quiet: dict[str, Any] = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "env": env}
    scheduler = subprocess.Popen(
        [_DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], **quiet
    )
    worker = None
    try:
        _wait_for_port(port, scheduler)  # a loaded machine: the scheduler may take seconds
        worker = subprocess.Popen(
            # no nanny: the worker is the process (a nanny is a third interpreter to start and
            # stop, and restarts nothing here)
            [
                _DASK,
                "worker",
                f"tcp://{address}",
                "--nthreads",
                "1",
                "--no-dashboard",
                "--no-nanny",
            ],
            **quiet,
        )
        yield address
    finally:
        if worker is not None:
            _stop(worker)
        _stop(scheduler)


@pytest.fixture(scope="module")
def cluster(held: dict[str, str]) -> Iterator[str]:
    """One scheduler and worker for the module's two Dask tests (each start and stop is seconds
    of process start-up and shutdown in wall-clock time)."""
    with _cluster(held) as address:
        yield address


RUNS, SEED = 6, 9


@pytest.fixture(scope="module")
def spec_and_table(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """SPEC's file and its serial table of RUNS runs from SEED, computed once: the reference of
    the Dask and the resumed sweeps (run i is the same whatever the number of runs:
    tests/fleet/test_sweep.py, so a sweep of fewer runs is the table's first rows)."""
    base = tmp_path_factory.mktemp("sweep-reference")
    spec = base / "spec.yaml"
    spec.write_text(SPEC, encoding="utf-8")
    return spec, _serial_table(spec, base / "serial", RUNS, SEED)


@pytest.mark.alone
def test_a_scheduler_and_a_worker_as_processes_give_the_same_table(
    tmp_path: Path, cluster: str, spec_and_table: tuple[Path, str]
) -> None:
    spec, serial = spec_and_table
    args = ["sweep", str(spec), "--runs", "4", "--seed", str(SEED), "--chunk", "1"]
    result = runner.invoke(
        app, [*args, "--executor", f"dask://{cluster}", "--out", str(tmp_path / "dask")]
    )
    assert result.exit_code == 0, result.output
    dask = (tmp_path / "dask" / "sweep.csv").read_text(encoding="utf-8")
    assert dask.splitlines() == serial.splitlines()[:5]  # the header and runs 0-3


def _tour_bag(path: Path) -> Path:
    from omnical.bags.bag import write_bag
    from omnical.experiment.library import builtin_script_data
    from omnical.experiment.script import parse_script
    from omnical.robot.loader import load_robot
    from omnical.twin.params import default_twin
    from omnical.twin.session import simulate_run

    robot = load_robot("rosy-mecanum")
    script = parse_script(builtin_script_data("tour"), robot.limits)
    return write_bag(simulate_run(script, robot, default_twin(robot), seed=1), path)


def _scheduler_tasks(address: str, limit_s: float = 10.0) -> int:
    """The tasks the scheduler holds, once it holds none or after ``limit_s``."""
    from distributed import Client

    def count() -> int:
        # a lambda: pickled by value (the scheduler cannot import this test module)
        return int(client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)))

    with Client(address, timeout=30, set_as_default=False) as client:  # type: ignore[no-untyped-call]
        deadline = time.monotonic() + limit_s
        while (left := count()) and time.monotonic() < deadline:
            time.sleep(0.1)
        return left


def _ctrl_c_when(
    proc: subprocess.Popen[bytes],
    ready: Callable[[], bool],
    *,
    timeout_s: float,
    settle_s: float = 0.0,
) -> str:
    """Ctrl-C as a terminal gives it (SIGINT to the process group) once ``ready()`` (and
    ``settle_s`` more), within 120 s; its stderr once it ended with status 130."""
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None and not ready():
            time.sleep(0.05)
        time.sleep(settle_s)
        assert proc.poll() is None, "the fleet ended before it could be stopped"
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err.decode()
    return str(err.decode())


@pytest.mark.alone
def test_ctrl_c_cancels_a_dask_fleets_remote_tasks(
    tmp_path: Path, cluster: str, held: dict[str, str]
) -> None:
    """After Ctrl-C the cluster runs no more of the fleet's jobs: when the job that was running
    ends, neither the next job of its chunk nor a queued task runs (no output appears)."""
    bag = _tour_bag(tmp_path / "bag.mcap")
    endless = tmp_path / "b.mcap"
    endless.touch()  # empty: its job runs until it is let go (_HOLD_HOOK)
    rest = [tmp_path / f"{c}.mcap" for c in "cdef"]
    for link in rest:
        link.symlink_to(bag)
    out = tmp_path / "fleet"
    table = out / "fleet.csv"
    args = [*_OMNICAL, "fleet", "locate", str(endless), *map(str, rest), "--chunk", "2"]
    proc = subprocess.Popen(  # chunks (b, c), (d, e), (f) on one single-threaded worker
        [*args, "--executor", f"dask://{cluster}", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
        env=held,
    )
    # once the endless job has started
    err = _ctrl_c_when(proc, (out / "recordings" / "b").is_dir, timeout_s=60)
    said = f"omnical: 0 rows kept in {table}; --resume continues\nomnical: interrupted"
    assert err.strip().endswith(said)
    assert _scheduler_tasks(cluster) == 0  # every task of the run cancelled there
    endless.write_bytes(b"not a bag")  # the running job let go: it fails on it
    time.sleep(3.0)  # the worker free: time enough for a job (≈ 0.5 s each)
    assert read_rows(table)[1] == []
    made = sorted(p.name for p in (out / "recordings").iterdir())
    assert made == [], made  # b's job removed its empty directory; c, d, e, f never ran


@pytest.mark.alone
def test_resume_after_sigterm_finishes_without_redoing_rows(
    tmp_path: Path, spec_and_table: tuple[Path, str]
) -> None:
    spec, serial = spec_and_table
    out = tmp_path / "sweep"
    runs = RUNS
    args = ["sweep", str(spec), "--runs", str(runs), "--seed", str(SEED), "--out", str(out)]
    proc = subprocess.Popen(
        [*_OMNICAL, *args, "--executor", "local:1", "--chunk", "1"],
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
    kept = table.read_text(encoding="utf-8").splitlines()
    done = len(kept) - 1
    said = f"omnical: {done} rows kept in {table}; --resume continues\nomnical: terminated"
    assert err.decode().strip().endswith(said)
    assert 2 <= done < runs

    # the resume in this process (the signal was the subprocess's subject; the command's code
    # is the same here, without a second interpreter's start-up)
    resumed = runner.invoke(app, [*args, "--executor", "serial", "--resume"])
    assert resumed.exit_code == 0, resumed.output
    assert f"({done} done before the resume)" in resumed.output
    final = table.read_text(encoding="utf-8")
    assert set(kept) <= set(final.splitlines())  # the rows written before the kill, kept
    assert final == serial


@pytest.mark.alone
def test_ctrl_c_stops_a_local_fleet_at_once_in_one_line(
    tmp_path: Path, held: dict[str, str]
) -> None:
    from omnical.bags.bag import write_bag
    from omnical.experiment.library import builtin_script_data
    from omnical.experiment.script import parse_script
    from omnical.robot.loader import load_robot
    from omnical.twin.params import default_twin
    from omnical.twin.session import simulate_run

    robot = load_robot("rosy-mecanum")
    script = parse_script(builtin_script_data("tour"), robot.limits)
    bag = write_bag(simulate_run(script, robot, default_twin(robot), seed=1), tmp_path / "a.mcap")
    endless = tmp_path / "b.mcap"
    endless.touch()  # empty: its job runs until it is stopped (_HOLD_HOOK)
    out = tmp_path / "fleet"
    args = [*_OMNICAL, "fleet", "locate", str(bag), str(endless), "--out", str(out)]
    # Ctrl-C at a terminal: SIGINT to the whole process group, the workers included
    proc = subprocess.Popen(
        [*args, "--executor", "local:2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
        env=held,
    )
    table = out / "fleet.csv"
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if table.exists() and len(table.read_text(encoding="utf-8").splitlines()) >= 2:
                break
            time.sleep(0.05)
        time.sleep(0.5)  # the idle worker back to waiting for work
        assert proc.poll() is None, "the fleet ended before it could be stopped"
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=30)  # the endless job is not waited for
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err.decode()
    said = f"omnical: 1 row kept in {table}; --resume continues\nomnical: interrupted"
    assert err.decode().strip() == said  # no worker's traceback
    (kept,) = read_rows(table)[1]
    assert kept["name"] == "a" and kept["status"] == "ok"

    endless.unlink()
    shutil.copyfile(next(bag.glob("*.mcap")), endless)  # a bag of one file now
    resumed = subprocess.run(
        [*args, "--executor", "local:2", "--resume"], capture_output=True, timeout=300, check=False
    )
    assert resumed.returncode == 0, resumed.stderr.decode()
    assert "2 ok, 0 error (1 done before the resume)" in resumed.stdout.decode()


@pytest.mark.alone
@pytest.mark.parametrize(
    ("sig", "after_s", "status", "said"),
    [
        (signal.SIGINT, 0.0, 130, "interrupted"),
        (signal.SIGINT, 0.4, 130, "interrupted"),
        (signal.SIGTERM, 0.1, 143, "terminated"),
    ],
)
def test_a_stop_with_jobs_waiting_in_the_pool_is_one_line(
    tmp_path: Path,
    held: dict[str, str],
    sig: signal.Signals,
    after_s: float,
    status: int,
    said: str,
) -> None:
    """Two workers on endless jobs, more jobs submitted behind them (cancelled by the stop):
    on Python < 3.14 the pool's manager thread failed those too, and printed "Exception in
    thread ... InvalidStateError: CANCELLED" after the stop's line (issue: fleet review)."""
    bags = []
    for i in range(8):
        bags.append(tmp_path / f"r{i}.mcap")
        bags[-1].touch()  # empty: a job that runs until stopped (_HOLD_HOOK)
    out = tmp_path / "fleet"
    args = [*_OMNICAL, "fleet", "locate", *map(str, bags), "--out", str(out)]
    proc = subprocess.Popen(
        [*args, "--executor", "local:2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
        env=held,
    )
    table = out / "fleet.csv"
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None and not table.exists():
            time.sleep(0.05)
        time.sleep(0.5 + after_s)  # the jobs submitted: two running, the others queued
        assert proc.poll() is None, "the fleet ended before it could be stopped"
        os.killpg(proc.pid, sig)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == status, err.decode()
    expected = f"omnical: 0 rows kept in {table}; --resume continues\nomnical: {said}"
    assert err.decode().strip() == expected
    assert read_rows(table)[1] == []


@pytest.mark.alone
def test_ctrl_c_during_overwrite_keeps_the_earlier_fleet_and_the_new_rows_beside(
    tmp_path: Path, held: dict[str, str]
) -> None:
    """Found by a new user: Ctrl-C during ``fleet ... --overwrite`` left the new rows where the
    earlier complete output had been (its table, report and recordings gone, no .partial).
    Now the earlier output is as it was, the new rows in DIR.partial, said in one line, and
    ``--resume --overwrite`` finishes them and puts them in place."""
    bag = _tour_bag(tmp_path / "a.mcap")
    out = tmp_path / "fleet"
    earlier = subprocess.run(
        [*_OMNICAL, "fleet", "locate", str(bag), "--executor", "serial", "--out", str(out)],
        capture_output=True,
        timeout=300,
        check=False,
    )
    assert earlier.returncode == 0, earlier.stderr.decode()
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    endless = tmp_path / "b.mcap"
    endless.touch()  # empty: its job runs until it is stopped (_HOLD_HOOK)
    args = [*_OMNICAL, "fleet", "locate", str(bag), str(endless), "--out", str(out), "--overwrite"]
    proc = subprocess.Popen(  # Ctrl-C at a terminal: SIGINT to the process group
        [*args, "--executor", "local:2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
        env=held,
    )

    def a_row_staged() -> bool:  # a's row in the staging directory: b's job is held
        staged = list(tmp_path.glob(".fleet.omnical-out-*/fleet.csv"))
        return bool(staged) and len(staged[0].read_text(encoding="utf-8").splitlines()) >= 2

    # the idle worker given 0.5 s to go back to waiting for work
    err = _ctrl_c_when(proc, a_row_staged, timeout_s=30, settle_s=0.5)
    partial = tmp_path / "fleet.partial"
    said = (
        f"omnical: 1 row kept in {partial / 'fleet.csv'}; the earlier {out} was not touched; "
        "--resume --overwrite continues them, then replaces it\nomnical: interrupted"
    )
    assert err.strip() == said
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert [r["name"] for r in read_rows(partial / "fleet.csv")[1]] == ["a"]

    endless.unlink()
    shutil.copyfile(next(bag.glob("*.mcap")), endless)  # a bag of one file now
    resumed = runner.invoke(app, [*args[len(_OMNICAL) :], "--executor", "serial", "--resume"])
    assert resumed.exit_code == 0, resumed.output
    assert "2 ok, 0 error (1 done before the resume)" in resumed.output
    assert [r["name"] for r in read_rows(out / "fleet.csv")[1]] == ["a", "b"]
    assert not partial.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
