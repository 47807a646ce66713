"""Twin benchmark: real-time factors of the compiled twin and the Python reference at 200 Hz.

Prints simulated seconds per wall second, measured in the same process, for

* the bare twin step loop (one command, no runner, no IPS, no recording), compiled and Python;
* the twin with recording: ``simulate_run`` of 10 minutes of robot time (runner, twin logs,
  simulated IPS, Recording; bag writing excluded), compiled and Python;
* a 60-minute ``simulate_run`` on the compiled twin, wall time;
* and, for reference, writing the 10-minute recording as a ROS 2 MCAP bag.

Targets: with recording >= 3000x, bare loop >= 20000x, 60-minute simulate_run <= 5 s.
The compiled kernels are compiled (or loaded from numba's cache) before timing; the cold
compile time is printed first.

Run: ``make bench`` or ``.venv/bin/python bench/bench_twin.py``.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import replace
from pathlib import Path

from omnical.bags.bag import write_bag
from omnical.experiment.library import builtin_script_data
from omnical.experiment.script import MotionScript, parse_script
from omnical.robot.description import RobotDescription
from omnical.robot.loader import load_robot
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.session import simulate_run
from omnical.twin.simulator import DigitalTwin

ROBOT_TIME_S = 600.0
LONG_RUN_S = 3600.0
PYTHON_BARE_S = 120.0  # the Python reference is timed on less robot time


def _tour(robot: RobotDescription, seconds: float) -> MotionScript:
    tour = builtin_script_data("tour")
    once = parse_script({"name": "tour-x", "steps": tour["steps"]}, robot.limits)
    repeats = int(seconds // once.duration_s) + 1
    return parse_script({"name": "tour-x", "steps": tour["steps"] * repeats}, robot.limits)


def _bare_rtf(robot: RobotDescription, params: TwinParams, seconds: float) -> float:
    twin = DigitalTwin(robot, params, seed=1)
    t0 = time.perf_counter()
    twin.send_twist(0.2, 0.1, 0.3)
    twin.advance_to(seconds)
    return seconds / (time.perf_counter() - t0)


def main() -> None:
    robot = load_robot("rosy-mecanum")
    compiled = replace(default_twin(robot), engine="compiled")
    python = replace(compiled, engine="python")
    script = _tour(robot, ROBOT_TIME_S)

    t0 = time.perf_counter()
    DigitalTwin(robot, compiled, seed=0).advance_to(0.1)
    warm_s = time.perf_counter() - t0
    simulate_run(_tour(robot, 1.0), robot, compiled, seed=0)  # every kernel loaded

    bare_c = max(_bare_rtf(robot, compiled, ROBOT_TIME_S) for _ in range(3))
    bare_py = _bare_rtf(robot, python, PYTHON_BARE_S)

    t0 = time.perf_counter()
    recording = simulate_run(script, robot, compiled, seed=1)
    sim_c_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    simulate_run(script, robot, python, seed=1)
    sim_py_s = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        write_bag(recording, Path(tmp) / "bench.mcap")
        bag_s = time.perf_counter() - t0

    long_script = _tour(robot, LONG_RUN_S)
    t0 = time.perf_counter()
    long_recording = simulate_run(long_script, robot, compiled, seed=1)
    long_s = time.perf_counter() - t0

    n_msgs = sum(len(t) for t in recording.tables.values())
    rtf_c = recording.duration_s / sim_c_s
    rtf_py = recording.duration_s / sim_py_s
    print(
        f"robot time: {recording.duration_s:.0f} s at {compiled.step_hz:.0f} Hz, "
        f"{n_msgs} messages recorded"
    )
    print(f"first compiled twin (JIT compile, or load from numba's cache): {warm_s:.2f} s")
    print(f"simulate + record: compiled {sim_c_s:.2f} s, Python {sim_py_s:.2f} s")
    print(f"real-time factor with recording (compiled): {rtf_c:.0f}x (target >= 3000x)")
    print(f"real-time factor with recording (Python reference): {rtf_py:.0f}x")
    print(
        f"bare twin loop (no runner, IPS or recording), compiled: {bare_c:.0f}x (target >= 20000x)"
    )
    print(f"bare twin loop, Python reference: {bare_py:.0f}x")
    print(
        f"ratio compiled / Python: bare {bare_c / bare_py:.0f}, with recording {rtf_c / rtf_py:.0f}"
    )
    print(f"ratio with recording / bare loop (compiled): {rtf_c / bare_c:.2f}")
    print(
        f"{long_recording.duration_s / 60:.0f}-minute simulate_run (compiled): {long_s:.2f} s "
        f"(target <= 5 s)"
    )
    print(f"write MCAP bag of the {recording.duration_s:.0f} s recording: {bag_s:.2f} s")


if __name__ == "__main__":
    main()
