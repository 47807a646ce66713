"""Twin benchmark: real-time factor for 10 minutes of robot time at 200 Hz, with recording.

Prints simulated seconds per wall second for the full pipeline (twin + runner + simulated IPS +
Recording + ROS 2 MCAP bag on disk), and as the baseline, measured in the same process, the bare
twin step loop with no runner, no IPS and no recording. Target: ≥ 100× with recording.

Run: ``make bench`` or ``.venv/bin/python bench/bench_twin.py``.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from omnical.experiment.library import builtin_script_data
from omnical.experiment.script import parse_script
from omnical.recording.bag import write_bag
from omnical.robot.loader import load_robot
from omnical.twin.params import default_twin
from omnical.twin.session import simulate_run
from omnical.twin.simulator import DigitalTwin

ROBOT_TIME_S = 600.0


def main() -> None:
    robot = load_robot("rosy-mecanum")
    params = default_twin(robot)
    tour = builtin_script_data("tour")
    repeats = 1
    script = parse_script({"name": "tour-x", "steps": tour["steps"] * repeats}, robot.limits)
    repeats = int(ROBOT_TIME_S // script.duration_s) + 1
    script = parse_script({"name": "tour-x", "steps": tour["steps"] * repeats}, robot.limits)

    # baseline: the bare twin loop, same robot time, no recording
    twin = DigitalTwin(robot, params, seed=1)
    t0 = time.perf_counter()
    twin.send_twist(0.2, 0.1, 0.3)
    twin.advance_to(script.duration_s)
    bare_s = time.perf_counter() - t0
    bare_rtf = script.duration_s / bare_s

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        recording = simulate_run(script, robot, params, seed=1)
        sim_s = time.perf_counter() - t0
        t1 = time.perf_counter()
        write_bag(recording, Path(tmp) / "bench.mcap")
        bag_s = time.perf_counter() - t1
    total_s = sim_s + bag_s
    n_msgs = sum(len(t) for t in recording.tables.values())
    rtf = recording.duration_s / total_s
    print(
        f"robot time: {recording.duration_s:.0f} s at {params.step_hz:.0f} Hz, {n_msgs} messages recorded"
    )
    print(f"simulate + record: {sim_s:.2f} s, write MCAP bag: {bag_s:.2f} s")
    print(f"real-time factor with recording: {rtf:.0f}x (target >= 100x)")
    print(f"baseline, bare twin loop (no runner, IPS or recording): {bare_rtf:.0f}x")
    print(f"ratio with recording / bare loop: {rtf / bare_rtf:.2f}")


if __name__ == "__main__":
    main()
