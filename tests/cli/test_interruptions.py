"""Interruptions lose nothing: SIGINT / SIGTERM during ``omnical simulate`` keep the run so far
under a partial name (never over the previous complete run) and exit 130 / 143; SIGKILL at
any moment leaves the previous bag untouched and nothing half-written under the final name."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from omnical.bags.bag import read_bag
from omnical.bags.staging import find_staging
from omnical.cli.main import app

runner = CliRunner()

_SLOW_OMNICAL = """
import sys, time
from pathlib import Path
import omnical.experiment.rig as session  # where run_script_on calls the runner
_run = session.run_script
flag = Path(sys.argv.pop(1))
def run_script(*args, on_tick=None, **kwargs):
    def tick(done, total):
        flag.touch()  # the runner is running: the test may signal now
        time.sleep(0.004)  # ~250x real time, so that signals land inside the run
        if on_tick is not None:
            on_tick(done, total)
    return _run(*args, on_tick=tick, **kwargs)
session.run_script = run_script
from omnical.cli.main import main
main()
"""

_SCRIPT = """name: long
steps:
  - move: {vx_mps: 0.2, duration_s: 600}
  - hold: {duration_s: 1200}
"""


def _fake_run(sig: signal.Signals) -> Any:
    """A simulate_run that receives ``sig`` half-way and stops like the runner does."""

    def simulate_run(script: Any, *args: Any, on_tick: Any = None, **kwargs: Any) -> Any:
        from omnical.recording.recording import RecordingBuilder

        builder = RecordingBuilder()
        try:
            for k in range(100):
                builder.add("/cmd_vel", 10**9 * (k + 1), vx_mps=0.1, vy_mps=0.0, wz_radps=0.0)
                if k == 50:
                    os.kill(os.getpid(), sig)
                    time.sleep(1.0)  # the handler raises here
        except KeyboardInterrupt:
            pass
        return builder.build()

    return simulate_run


@pytest.mark.parametrize(("sig", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_keeps_the_partial_run_beside_the_previous_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, sig: signal.Signals, status: int
) -> None:
    import omnical.twin.session as session

    out = tmp_path / "run.mcap"
    assert runner.invoke(app, ["simulate", "straight-10m", "--out", str(out)]).exit_code == 0
    before = {p.name: p.read_bytes() for p in (tmp_path / "run").iterdir()}
    monkeypatch.setattr(session, "simulate_run", _fake_run(sig))
    for partial in ("run.partial", "run.partial-2"):
        result = runner.invoke(app, ["simulate", "straight-10m", "--out", str(out), "--overwrite"])
        assert result.exit_code == status, result.output
        assert (
            f"kept the partial run in {tmp_path / partial} (50.0 s of the script's" in result.output
        )
        assert "the earlier" in result.output and "was not touched" in result.output
        assert result.output.strip().splitlines()[-1] in (
            "omnical: interrupted",
            "omnical: terminated",
        )
        assert read_bag(tmp_path / partial).topic("/cmd_vel").t_ns.size == 51
    assert {p.name: p.read_bytes() for p in (tmp_path / "run").iterdir()} == before


@pytest.mark.slow
def test_real_signals_at_random_moments(tmp_path: Path) -> None:
    rng = random.Random(10)
    script = tmp_path / "long.yaml"
    script.write_text(_SCRIPT)
    out = tmp_path / "run.mcap"
    assert runner.invoke(app, ["simulate", "straight-10m", "--out", str(out)]).exit_code == 0
    before = {p.name: p.read_bytes() for p in (tmp_path / "run").iterdir()}
    kept = 0
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        flag = tmp_path / f"running-{sig.name}"
        proc = subprocess.Popen(
            [sys.executable, "-c", _SLOW_OMNICAL, str(flag), "simulate", str(script), "--out", str(out), "--overwrite"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        deadline = time.monotonic() + 30
        while not flag.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        time.sleep(rng.uniform(0.0, 1.5))  # seeded: somewhere in the run
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
        assert "Traceback" not in err
        if sig == signal.SIGKILL:
            assert proc.returncode == -signal.SIGKILL
        else:
            assert proc.returncode == (130 if sig == signal.SIGINT else 143), err
            kept += 1
            partial = tmp_path / ("run.partial" if kept == 1 else f"run.partial-{kept}")
            assert f"kept the partial run in {partial}" in err
            assert read_bag(partial).has("/odom")
        # the previous complete run is untouched whatever happened
        assert {p.name: p.read_bytes() for p in (tmp_path / "run").iterdir()} == before
    # a write killed mid-way leaves a staging: the next run keeps it for omnical recover
    leftovers = [s for s in find_staging(tmp_path / "run") if s.kind == "write"]
    result = runner.invoke(app, ["simulate", "straight-10m", "--out", str(out), "--overwrite"])
    assert result.exit_code == 0, result.output
    assert all(s in find_staging(tmp_path / "run") for s in leftovers)


_PAUSING_SIMULATE = """
import sys, time
from pathlib import Path
flag, point = Path(sys.argv.pop(1)), sys.argv.pop(1)
if point == "assembled":  # the script has run to its end; its recording is being assembled
    import omnical.twin.record as record
    patched, name = record, "twin_recording"
else:  # "written": the complete run is being written as a bag
    import omnical.bags.bag as bag
    patched, name = bag, "write_ros2_bag"
real = getattr(patched, name)
def paused(*args, **kwargs):
    flag.touch()
    time.sleep(1.0)  # the test signals meanwhile: the signal is noted, the sleep goes on
    return real(*args, **kwargs)
setattr(patched, name, paused)
from omnical.cli.main import main
main()
"""


@pytest.mark.parametrize(
    ("point", "sig", "status"),
    [("assembled", signal.SIGTERM, 143), ("written", signal.SIGINT, 130)],
)
def test_a_signal_after_the_run_keeps_it_as_partial_and_the_earlier_bag(
    tmp_path: Path, point: str, sig: signal.Signals, status: int
) -> None:
    """Issue 28: SIGTERM while the finished run was assembled lost it; a signal while the bag
    was written replaced the earlier bag. Now both keep the run as RUN.partial, the earlier RUN
    byte-identical, and exit 130 / 143."""
    out = tmp_path / "run.mcap"
    assert runner.invoke(app, ["simulate", "straight-10m", "--out", str(out)]).exit_code == 0
    before = {p.name: p.read_bytes() for p in (tmp_path / "run").iterdir()}
    flag = tmp_path / "paused"
    proc = subprocess.Popen(
        [sys.executable, "-c", _PAUSING_SIMULATE, str(flag), point, "simulate", "straight-10m",
         "--out", str(out), "--overwrite"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 60
    while not flag.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == status, err
    assert "Traceback" not in err
    assert f"kept the whole run in {tmp_path / 'run.partial'}" in err  # the script had ended
    assert f"the earlier {tmp_path / 'run'} was not touched" in err
    assert {p.name: p.read_bytes() for p in (tmp_path / "run").iterdir()} == before
    kept = read_bag(tmp_path / "run.partial")
    assert (
        kept.topic("/cmd_vel").t_ns.size == read_bag(tmp_path / "run").topic("/cmd_vel").t_ns.size
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["paused", "run", "run.partial"]


_RECORDER = """
import sys, time
from pathlib import Path
from omnical.bags.recorder import BagRecorder
out, flag = sys.argv[1:3]
with BagRecorder(out, overwrite=True, flush_period_s=0.0) as recorder:
    t0 = 1_700_000_000_000_000_000
    recorder.write_rows("/cmd_vel", [t0, t0 + 10**9], vx_mps=[0.3, 0.4], vy_mps=[0.0, 0.0], wz_radps=[0.0, 0.0])
    recorder.flush()
    Path(flag).touch()
    time.sleep(60)
"""


def test_recover_finds_the_killed_run_before_the_earlier_bag(tmp_path: Path) -> None:
    """Issue 28: ``recover RUN`` after a killed recorder returned the earlier complete bag at
    RUN; the killed run (in its staging) comes first now, and is named."""
    from omnical.bags.bag import write_bag
    from omnical.recording.recording import RecordingBuilder

    out = tmp_path / "run.mcap"
    builder = RecordingBuilder()
    builder.add_many("/cmd_vel", [1, 2], vx_mps=[0.1, 0.1], vy_mps=[0.0, 0.0], wz_radps=[0.0, 0.0])
    write_bag(builder.build(), out)
    before = {p.name: p.read_bytes() for p in (tmp_path / "run").iterdir()}
    flag = tmp_path / "flushed"
    proc = subprocess.Popen([sys.executable, "-c", _RECORDER, str(out), str(flag)])
    deadline = time.monotonic() + 60
    while not flag.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    proc.kill()
    proc.wait()
    (staging,) = find_staging(tmp_path / "run")
    result = runner.invoke(app, ["recover", str(out)])
    assert result.exit_code == 0, result.output
    assert (
        f"found the unfinished recording of {tmp_path / 'run'} in {staging.path}" in result.output
    )
    assert f"(its recorder, process {proc.pid}, was killed)" in result.output
    recovered = read_bag(tmp_path / "run.recovered").topic("/cmd_vel")
    assert recovered["vx_mps"].tolist() == [0.3, 0.4]  # the killed run's, not the earlier bag's
    assert {p.name: p.read_bytes() for p in (tmp_path / "run").iterdir()} == before
    assert not find_staging(tmp_path / "run")


def test_a_stop_at_the_runs_end_still_says_where_the_partial_run_is(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a new user's Ctrl-C to `run --robot ros2` once left RUN.partial-2 with only "omnical:
    # interrupted" said: a stop outside the run's own handling (here as the run is finished)
    # went through the recorder's exit, which keeps the bag without a word
    import omnical.experiment.rig as rig_module

    real = rig_module.run_script_on

    def stopped_at_the_end(rig: Any, script: Any, sink: Any, **kwargs: Any) -> Any:
        real(rig, script, sink, **kwargs)  # recorded whole, then the stop
        raise KeyboardInterrupt

    monkeypatch.setattr(rig_module, "run_script_on", stopped_at_the_end)
    out = tmp_path / "run.mcap"
    result = runner.invoke(app, ["run", "straight-10m", "--robot", "twin", "--out", str(out)])
    assert result.exit_code == 130, result.output
    assert f"omnical: robot stopped; kept the partial run in {tmp_path / 'run.partial'}" in (
        result.output
    )
    assert read_bag(tmp_path / "run.partial").topic("/cmd_vel").t_ns.size > 100
    assert not out.exists() and not (tmp_path / "run").exists()
