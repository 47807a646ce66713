"""The ROS 2 rig against ``omnical ros2 twin`` (issue 25): a script through ``--robot ros2``
against the same script on the in-process twin (final odometry apart, target 2 cm; wall times).

``python bench/bench_ros2_rig.py [--script tour]``; ``--campaign N`` adds a calibration campaign
of N iterations over ROS 2 (real time: ≈ 6 min an iteration) and its factors against the truth.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from omnical.bags.bag import read_bag
from omnical.calibration.factors_io import read_factors
from omnical.recording.topics import ODOM
from omnical.robot.loader import load_robot
from omnical.twin.params import default_twin

ROBOT = "rosy-mecanum"


def _omnical(*args: str) -> list[str]:
    return [sys.executable, "-c", "from omnical.cli.main import main; main()", *args]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(1 + os.getpid() % 100)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_LOG_DIR"] = str(Path(tempfile.gettempdir()) / "omnical-ros2-bench-logs")
    return env


class _Twin:
    """``omnical ros2 twin`` in a process of its own, stopped by its PID."""

    def __init__(self, env: dict[str, str]) -> None:
        self.proc = subprocess.Popen(
            _omnical("ros2", "twin", "--robot", ROBOT),
            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line.startswith("hedgehog: "):
            self.stop()
            raise SystemExit(f"ros2 twin did not start: {line!r}")
        self.hedge = line.split(": ", 1)[1].strip()

    def stop(self) -> None:
        self.proc.terminate()  # SIGTERM: SIGINT may be ignored in a background job
        try:
            self.proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.communicate()


def _final(bag: Path) -> np.ndarray:
    odom = read_bag(bag).topic(ODOM)
    return np.array([odom["x_m"][-1], odom["y_m"][-1], odom["yaw_rad"][-1]])


def script_run(script: str, out: Path) -> None:
    env = _env()
    twin = _Twin(env)
    try:
        t0 = time.perf_counter()
        done = subprocess.run(
            _omnical("run", script, "--robot", "ros2", "--hedge", "none", "--yes",
                     "-o", str(out / "ros2.mcap"), "--overwrite"),
            env=env, capture_output=True, text=True, check=False,
        )  # fmt: skip
        wall_ros2 = time.perf_counter() - t0
    finally:
        twin.stop()
    if done.returncode != 0:
        raise SystemExit(done.stderr)
    t0 = time.perf_counter()
    subprocess.run(
        _omnical("run", script, "-o", str(out / "local.mcap"), "--overwrite"),
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    wall_local = time.perf_counter() - t0
    a, b = _final(out / "ros2.mcap"), _final(out / "local.mcap")
    apart_m = float(np.hypot(*(a[:2] - b[:2])))
    print(
        f"{script}: final odometry over ROS 2 ({a[0]:.3f}, {a[1]:.3f}) m, in process "
        f"({b[0]:.3f}, {b[1]:.3f}) m: {apart_m * 100:.2f} cm apart (target ≤ 2 cm), "
        f"yaw {np.degrees(a[2] - b[2]):+.2f}°"
    )
    print(
        f"wall time: {wall_ros2:.1f} s over ROS 2 (real time), {wall_local:.1f} s in process "
        f"(×{wall_ros2 / wall_local:.1f})"
    )


def campaign_run(iterations: int, out: Path) -> None:
    env = _env()
    twin = _Twin(env)
    try:
        t0 = time.perf_counter()
        done = subprocess.run(
            _omnical("calibrate", "campaign", "--robot", "ros2", "--hedge", f"serial:{twin.hedge}",
                     "--yes", "--max-iterations", str(iterations), "--no-validate",
                     "--no-figures", "--out", str(out / "campaign"), "--overwrite"),
            env=env, capture_output=True, text=True, check=False,
        )  # fmt: skip
        wall = time.perf_counter() - t0
    finally:
        twin.stop()
    if done.returncode != 0:
        raise SystemExit(done.stderr + done.stdout)
    got = read_factors(out / "campaign" / "factors.yaml").factors.as_dict()
    truth = default_twin(load_robot(ROBOT)).true_factors.as_dict()
    print(f"campaign over ROS 2, {iterations} iteration(s): {wall / 60:.1f} min of wall time")
    worst_scale, worst_cross = 0.0, 0.0
    for key, value in got.items():
        err = float(value) - float(truth[key])
        is_scale = key.startswith("scale_")
        if is_scale:
            err /= float(truth[key])  # relative
            worst_scale = max(worst_scale, abs(err))
        else:
            worst_cross = max(worst_cross, abs(err))
        unit = f"{err * 100:+.3f} %" if is_scale else f"{err * 1e3:+.3f} mrad/m"
        print(f"  {key}: {float(value):.5f} (truth {float(truth[key]):.5f}, {unit})")
    print(
        f"worst: scaling {worst_scale * 100:.3f} % (target 0.5 %), cross-talk "
        f"{worst_cross * 1e3:.3f} mrad/m (target 1.5)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--script", default="tour")
    parser.add_argument("--campaign", type=int, default=0, metavar="N")
    parser.add_argument("--keep", type=Path, default=None, help="keep the bags in this folder")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = args.keep or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        script_run(args.script, out)
        if args.campaign:
            campaign_run(args.campaign, out)


if __name__ == "__main__":
    main()
