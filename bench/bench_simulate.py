"""Simulate benchmark (issue "Scale"): ``omnical simulate`` of 1, 10 and 60 minutes of robot time.

For each length (the built-in ``tour`` repeated until it lasts that long), measured in this
run, each figure in a fresh process:

* the whole command as a user runs it, ``omnical simulate SCRIPT --out RUN.mcap`` (interpreter
  start, imports, script, twin, bag): wall time, CPU time (user + system: what the wall time
  would be on an idle core) and peak memory (VmHWM), with omnical's bulk MCAP writer (the
  default) and, as the baseline, with rosbags' writer message by message;
* the twin with recording alone (``simulate_run`` + ``write_bag``, in the process, after the
  imports): robot time / time taken (wall, and CPU), and the bag write alone, for both
  writers (the bulk write: best of :data:`BULK_REPEATS`); and the size of the bag against an
  uncompressed one.

Targets: the 60-minute command <= 5 s wall on one core; twin with recording >= 3000x; the bag
at least 5x smaller than uncompressed.
Timings on a shared machine drift: compare the figures of one run, and read CPU time where
the machine is busy.

Run: ``.venv/bin/python bench/bench_simulate.py`` (``--minutes 1 10`` for fewer lengths).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

MINUTES = (1, 10, 60)
WRITERS = ("bulk", "rosbags")
BULK_REPEATS = 3
"""The bulk writer's bag write is timed this many times in the process; the best counts."""


def write_script(path: Path, minutes: float) -> float:
    """A motion script of ``minutes`` of robot time (the tour, repeated); returns its length."""
    from omnical.experiment.library import builtin_script_data
    from omnical.experiment.script import parse_script
    from omnical.robot.loader import load_robot

    limits = load_robot("rosy-mecanum").limits
    steps = builtin_script_data("tour")["steps"]
    once = parse_script({"name": "tour-x", "steps": steps}, limits).duration_s
    repeats = max(1, round(60.0 * minutes / once))
    # a copy of each step: repeated objects would be written as YAML aliases, which scripts refuse
    data = {"name": f"tour-{minutes}min", "steps": [copy.deepcopy(s) for s in steps * repeats]}
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return parse_script(data, limits).duration_s


def _peak_mb() -> float:
    # VmHWM, not ru_maxrss: the latter keeps the parent's peak across fork + exec.
    status = Path("/proc/self/status").read_text().splitlines()
    return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:")) / 1024


def _child_command(writer: str, script: str, out: str) -> None:
    """``omnical simulate`` as the CLI runs it, with ``writer``; prints the peak memory."""
    import functools

    from omnical.bags import bag
    from omnical.cli.main import main as cli_main

    bag.write_bag = functools.partial(bag.write_bag, writer=writer)  # type: ignore[assignment]
    sys.argv = ["omnical", "simulate", script, "--out", out, "--overwrite"]
    try:
        cli_main()
    except SystemExit as stop:
        if stop.code:
            raise
    print(json.dumps({"peak_mb": _peak_mb()}))


def _child_phases(script: str, out: str) -> None:
    """simulate_run, then write_bag with each writer (after the imports); prints seconds."""
    from omnical.bags.bag import write_bag
    from omnical.experiment.script import load_script
    from omnical.robot.loader import load_robot
    from omnical.twin.params import load_twin
    from omnical.twin.session import simulate_run

    robot = load_robot("rosy-mecanum")
    params = load_twin("default", robot)
    compiled = load_script(script, robot.limits)
    simulate_run(load_script("straight-10m", robot.limits), robot, params, seed=0)  # warm up
    start, cpu = time.perf_counter(), time.process_time()
    recording = simulate_run(compiled, robot, params, seed=0)
    figures = {
        "simulate_s": time.perf_counter() - start,
        "simulate_cpu_s": time.process_time() - cpu,
        "messages": recording.message_count,
    }
    for writer in WRITERS:
        walls, cpus = [], []
        for _ in range(BULK_REPEATS if writer == "bulk" else 1):
            start, cpu = time.perf_counter(), time.process_time()
            written = write_bag(recording, out, overwrite=True, writer=writer)  # type: ignore[arg-type]
            walls.append(time.perf_counter() - start)
            cpus.append(time.process_time() - cpu)
        figures[f"write_{writer}_s"] = min(walls)
        figures[f"write_{writer}_cpu_s"] = min(cpus)
        figures[f"size_{writer}_mb"] = sum(f.stat().st_size for f in written.iterdir()) / 1e6
    written = write_bag(recording, out, overwrite=True, compression=None)
    figures["size_plain_mb"] = sum(f.stat().st_size for f in written.iterdir()) / 1e6
    print(json.dumps(figures))


def _run(*args: str) -> tuple[dict[str, float], float, float]:
    """A child of this script: its JSON line, wall seconds and CPU seconds (user + system)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    out = subprocess.run(
        [sys.executable, __file__, *args], check=True, capture_output=True, text=True
    ).stdout
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return json.loads(out.strip().splitlines()[-1]), wall, cpu


def main(minutes: tuple[float, ...]) -> None:
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for m in minutes:
            script = root / f"tour{m:g}.yaml"
            robot_s = write_script(script, m)
            out = str(root / f"run{m:g}.mcap")
            print(f"--- {m:g} min ({robot_s:.0f} s of robot time)")
            cmd: dict[str, tuple[float, float, float]] = {}
            for writer in WRITERS:
                figures, wall, cpu = _run("--child-command", writer, str(script), out)
                cmd[writer] = (wall, cpu, figures["peak_mb"])
                print(
                    f"omnical simulate, {writer:<7} writer  {wall:6.2f} s wall  {cpu:6.2f} s CPU"
                    f"  {figures['peak_mb']:6.0f} MB peak"
                )
            (wall_b, cpu_b, mb_b), (wall_r, cpu_r, mb_r) = cmd["bulk"], cmd["rosbags"]
            print(
                f"ratio rosbags / bulk: wall {wall_r / wall_b:.1f}x  CPU {cpu_r / cpu_b:.1f}x  "
                f"memory {mb_r / mb_b:.1f}x"
            )
            phases, _, _ = _run("--child-phases", str(script), out)
            n = phases["messages"]
            for clock in ("", "_cpu"):
                sim_s = phases[f"simulate{clock}_s"]
                for writer in WRITERS:
                    write_s = phases[f"write_{writer}{clock}_s"]
                    print(
                        f"twin + recording, {writer:<7} writer, {'CPU' if clock else 'wall'}:"
                        f" simulate {sim_s:5.2f} s + write {write_s:5.2f} s "
                        f"({n / write_s:>9,.0f} msg/s, {phases[f'size_{writer}_mb']:5.1f} MB)"
                        f" = {robot_s / (sim_s + write_s):5.0f}x real time"
                    )
                ratio = phases[f"write_rosbags{clock}_s"] / phases[f"write_bulk{clock}_s"]
                print(f"ratio write rosbags / bulk ({'CPU' if clock else 'wall'}): {ratio:.1f}x")
            plain = phases["size_plain_mb"]
            print(
                f"bag size: bulk {phases['size_bulk_mb']:.1f} MB, uncompressed {plain:.1f} MB"
                f" ({plain / phases['size_bulk_mb']:.1f}x smaller)"
            )


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child-command":
        _child_command(sys.argv[2], sys.argv[3], sys.argv[4])
    elif len(sys.argv) > 1 and sys.argv[1] == "--child-phases":
        _child_phases(sys.argv[2], sys.argv[3])
    else:
        parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
        parser.add_argument("--minutes", type=float, nargs="+", default=list(MINUTES))
        main(tuple(parser.parse_args().minutes))
