"""Scan-to-map localisation over ROS 2: matched at the scan's own time vs at the pose now.

``python bench/bench_ros2_scan_timing.py [--runs N]``: ``omnical ros2 twin --world lab-8x6`` in
a process, this process navigating it through the ROS 2 rig; the localised pose against the
twin's ``/ground_truth`` while moving (mean along-track error = the bias), each way in turn.
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROBOT = "rosy-mecanum"
START = (1.5, 1.2, 0.0)
GOALS = [(3.4, 2.6), (1.5, 1.2)]


def _omnical(*args: str) -> list[str]:
    return [sys.executable, "-c", "from omnical.cli.main import main; main()", *args]


def one_run(at_scan_time: bool) -> tuple[float, float, float, int]:
    """(mean along-track error m, its RMS across track m, speed m/s, matches) of one run."""
    from omnical.control.limits import DEFAULT_COMMAND_LIMITS, CommandLimits
    from omnical.navigation.inflation import inflate
    from omnical.navigation.map_io import load_map
    from omnical.navigation.prm import PlanParams, build_roadmap
    from omnical.recording.recording import RecordingBuilder
    from omnical.recording.topics import GROUND_TRUTH
    from omnical.robot.loader import load_robot
    from omnical.ros2.rig import Ros2Lidar, ros2_devices
    from omnical.services.hil import HostClock, SerialRig
    from omnical.services.navigation import navigate_on, resolve_world, robot_footprint

    if not at_scan_time:  # the behaviour before: the newest scan taken as of the pose now
        Ros2Lidar.scan_age_s = lambda self: 0.0  # type: ignore[method-assign]
    robot = load_robot(ROBOT)
    grid = load_map(resolve_world(Path("lab-8x6")))
    infl = inflate(grid, footprint=robot_footprint(robot))
    params = PlanParams()
    clock = HostClock()
    sink = RecordingBuilder()
    with ros2_devices(robot, clock, say=lambda _: None) as (driver, _, lidar):
        rig = SerialRig(driver, None, clock, abort_key=False, lidar=lidar)
        nav = navigate_on(
            rig, sink, GOALS, ["tracking"] * len(GOALS), inflated=infl,
            roadmap=build_roadmap(infl, params.prm), plan_params=params,
            limits=CommandLimits.from_robot(robot.limits).tightened(DEFAULT_COMMAND_LIMITS),
            start_pose_map=START, map_grid=grid,
        )  # fmt: skip
    if not nav.reached:
        why = [
            (leg.plan.status, leg.plan.reason, leg.control and leg.control.reason)
            for leg in nav.legs
        ]
        raise SystemExit(f"the legs were not driven: {why}")
    rec = sink.build()
    truth = rec.topic(GROUND_TRUTH)
    t_truth = (np.asarray(truth.t_ns) - nav.session.origin_ns) / 1e9
    est = nav.estimates
    tx = np.interp(est[:, 0], t_truth, truth["x_m"])
    ty = np.interp(est[:, 0], t_truth, truth["y_m"])
    vx = np.gradient(tx, est[:, 0])
    vy = np.gradient(ty, est[:, 0])
    speed = np.hypot(vx, vy)
    moving = speed > 0.1
    ex, ey = est[:, 1] - tx, est[:, 2] - ty
    along = (ex * vx + ey * vy)[moving] / speed[moving]
    across = (-ex * vy + ey * vx)[moving] / speed[moving]
    return (
        float(np.mean(along)),
        float(np.sqrt(np.mean(across**2))),
        float(np.mean(speed[moving])),
        nav.accepted,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=1)
    parser.add_argument("--one", choices=["now", "stamp"], help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:  # a child: the ROS 2 side in a re-executed process of its own
        from omnical.ros2.runtime import ensure_ros_environment

        ensure_ros_environment()
        along, across, speed, n = one_run(args.one == "stamp")
        print(f"RESULT {along} {across} {speed} {n}")
        return
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(1 + os.getpid() % 100)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_LOG_DIR"] = str(Path(tempfile.gettempdir()) / "omnical-ros2-bench-logs")
    results: dict[str, list[tuple[float, ...]]] = {"now": [], "stamp": []}
    for _ in range(args.runs):
        for way in ("now", "stamp"):
            twin = subprocess.Popen(
                _omnical("ros2", "twin", "--robot", ROBOT, "--world", "lab-8x6"),
                env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
            )  # fmt: skip
            try:
                assert twin.stdout is not None and twin.stdout.readline().startswith("hedgehog")
                done = subprocess.run(
                    [sys.executable, __file__, "--one", way],
                    env=env, capture_output=True, text=True, check=False,
                )  # fmt: skip
            finally:
                twin.terminate()  # SIGTERM: SIGINT may be ignored in a background job
                twin.wait(timeout=10)
            line = [ln for ln in done.stdout.splitlines() if ln.startswith("RESULT")]
            if not line:
                raise SystemExit(done.stderr[-2000:])
            results[way].append(tuple(float(v) for v in line[0].split()[1:]))
            along, across, speed, matches = results[way][-1]
            print(
                f"matched at {'the scan stamp' if way == 'stamp' else 'the pose now':14s}: "
                f"along-track bias {along * 100:+.2f} cm, across RMS {across * 100:.2f} cm at "
                f"{speed:.2f} m/s, {matches:.0f} matches"
            )
    mean = {w: float(np.mean([r[0] for r in rs])) for w, rs in results.items()}
    ratio = abs(mean["now"]) / max(abs(mean["stamp"]), 1e-4)
    print(
        f"mean along-track bias over {args.runs} run(s): pose now {mean['now'] * 100:+.2f} cm, "
        f"scan stamp {mean['stamp'] * 100:+.2f} cm (×{ratio:.1f} smaller)"
    )
    assert math.isfinite(ratio)


if __name__ == "__main__":
    main()
