"""``omnical ros2 twin`` on localhost (issue 25): /cmd_vel → moving /odom latency, and messages lost
at 50 Hz.

Latency: ``--trials`` commands of 0.3 m/s from rest to the ideal twin, each timed from the publish
to the first /odom at ≥ 1 cm/s received here; baseline (same process): the twin's own response in
simulated time to a command at the same instant of its clock (ramp, motor lag, 100 Hz control,
50 Hz odometry); ROS 2 adds the difference (target ≤ 30 ms). Loss: /cmd_vel at 50 Hz for
``--seconds`` (issue: 600) against the twin's count at exit; /odom stamps checked for gaps.
``python bench/bench_ros2.py [--trials 30] [--seconds 60] [--domain N]``.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from omnical.ros2.runtime import ensure_ros_environment, import_rclpy

ROBOT = "rosy-mecanum"
VX_MPS = 0.3
MOVING_MPS = 0.01
ODOM_PERIOD_S = 0.02


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(1 + (os.getpid() * 7) % 100)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_LOG_DIR"] = str(Path(tempfile.gettempdir()) / "omnical-ros2-bench-logs")
    return env


def plant_response_s(starts_s: list[float]) -> list[float]:
    """The ideal twin's own command → first moving odometry sample times, in simulated time, for
    commands at these instants of its clock (only their phase in its 20 ms cycle matters)."""
    from omnical.robot.loader import load_robot
    from omnical.twin.params import load_twin
    from omnical.twin.simulator import DigitalTwin

    description = load_robot(ROBOT)
    params = load_twin("ideal", description)
    out = []
    for at in starts_s:
        start = 1.0 + at % ODOM_PERIOD_S
        twin = DigitalTwin(description, params, seed=0, engine="python")
        twin.advance_to(start)
        twin.send_twist(VX_MPS, 0.0, 0.0)
        twin.advance_to(start + 0.5)
        odom = twin.log().odom
        after = odom[odom[:, 0] > start]
        out.append(float(after[np.argmax(after[:, 4] >= MOVING_MPS), 0] - start))
    return out


class Probe:
    """The bench's node: /odom in (receipt times), /cmd_vel out."""

    def __init__(self) -> None:
        rclpy = import_rclpy()
        from geometry_msgs.msg import Twist
        from nav_msgs.msg import Odometry
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        self.Twist = Twist
        self.sent = 0
        rclpy.init()
        self.node = rclpy.create_node("omnical_bench_probe")
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.lock = threading.Lock()
        self.odom: list[tuple[float, float, float]] = []  # receipt wall s, stamp s, vx
        self.node.create_subscription(Odometry, "/odom", self._on_odom, qos)
        self.cmd = self.node.create_publisher(Twist, "/cmd_vel", qos)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        threading.Thread(target=self.executor.spin, daemon=True).start()

    def _on_odom(self, msg: Any) -> None:
        now = time.time()
        stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        with self.lock:
            self.odom.append((now, stamp, float(msg.twist.twist.linear.x)))

    def send(self, vx: float) -> float:
        twist = self.Twist()
        twist.linear.x = vx
        t = time.time()
        self.cmd.publish(twist)
        self.sent += 1
        return t

    def last_vx(self) -> float:
        with self.lock:
            return self.odom[-1][2] if self.odom else float("nan")

    def wait(self, condition: Any, timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if condition():
                return True
            time.sleep(0.0005)
        return False


def latency_trials(probe: Probe, trials: int) -> tuple[list[float], list[float]]:
    """Publish → first received /odom at ≥ MOVING_MPS, from rest, ``trials`` times; and each
    publish time less an /odom stamp (the twin's stamps are its start + k · 20 ms)."""
    out = []
    sent_at = []
    with probe.lock:
        a_stamp = probe.odom[0][1]
    for _ in range(trials):
        probe.wait(lambda: probe.last_vx() == 0.0, 10.0)
        time.sleep(0.3 + float(np.random.default_rng().uniform(0.0, 0.05)))
        with probe.lock:
            seen = len(probe.odom)
        sent = probe.send(VX_MPS)
        last_sent = sent

        def moving(seen: int = seen) -> bool:
            with probe.lock:
                return any(vx >= MOVING_MPS for _, _, vx in probe.odom[seen:])

        while not moving():
            if time.time() - last_sent > 0.05:  # keep commanding as a teleop would (20 Hz)
                last_sent = probe.send(VX_MPS)
            time.sleep(0.0005)
        with probe.lock:
            first = next(t for t, _, vx in probe.odom[seen:] if vx >= MOVING_MPS)
        out.append(first - sent)
        sent_at.append(sent - a_stamp)
        probe.send(0.0)
    return out, sent_at


def loss_run(probe: Probe, seconds: float) -> tuple[int, int, int]:
    """/cmd_vel at 50 Hz for ``seconds`` (a slow weave); (sent, /odom received, /odom gaps)."""
    with probe.lock:
        first = len(probe.odom)
    sent = 0
    start = time.monotonic()
    next_t = start
    while (now := time.monotonic()) - start < seconds:
        phase = now - start
        probe.send(0.2 * np.sin(0.5 * phase))
        sent += 1
        next_t += 0.02
        time.sleep(max(0.0, next_t - time.monotonic()))
    time.sleep(0.5)
    with probe.lock:
        stamps = np.array([s for _, s, _ in probe.odom[first:]])
    gaps = int(np.sum(np.diff(stamps) > 1.5 * ODOM_PERIOD_S))
    return sent, len(stamps), gaps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=30)
    parser.add_argument("--seconds", type=float, default=60.0, help="the 50 Hz run (issue: 600)")
    parser.add_argument("--domain", type=int, default=None, help="ROS_DOMAIN_ID (default: by PID)")
    args = parser.parse_args()
    ensure_ros_environment()
    env = _env()
    if args.domain is not None:
        env["ROS_DOMAIN_ID"] = str(args.domain)
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
    load = os.getloadavg()[0]
    probe = Probe()
    twin = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "from omnical.cli.entry import main; main()",
            "ros2",
            "twin",
            "--robot",
            ROBOT,
            "--twin",
            "ideal",
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        assert twin.stdout is not None
        twin.stdout.readline()
        if not probe.wait(lambda: probe.cmd.get_subscription_count() > 0 and probe.odom, 30.0):
            sys.exit("the twin did not come up")
        time.sleep(0.5)
        lat, sent_at = latency_trials(probe, args.trials)
        with probe.lock:
            transport = [r - s for r, s, _ in probe.odom[-200:]]
        sent, odom_n, gaps = loss_run(probe, args.seconds)
    finally:
        twin.send_signal(2)
        _, err = twin.communicate(timeout=10)
    received = re.search(r"received (\d+) /cmd_vel", err)
    got = int(received.group(1)) if received else -1
    plant = plant_response_s(sent_at)
    added = [a - b for a, b in zip(lat, plant, strict=True)]
    e2e_ms = 1000 * statistics.median(lat)
    plant_ms = 1000 * statistics.median(plant)
    print(
        f"omnical ros2 twin (ideal twin) on localhost, ROS_DOMAIN_ID {env['ROS_DOMAIN_ID']}; "
        f"load average {load:.2f} at start"
    )
    print(f"{'':40s} {'median':>8s} {'p90':>8s}")
    print(f"{'/cmd_vel → moving /odom (ms)':40s} {e2e_ms:8.1f} {1000 * np.quantile(lat, 0.9):8.1f}")
    print(
        f"{'baseline: the twin itself (ms)':40s} {plant_ms:8.1f} "
        f"{1000 * np.quantile(plant, 0.9):8.1f}"
    )
    print(
        f"{'ROS 2 adds (ms, target ≤ 30)':40s} {1000 * statistics.median(added):8.1f} "
        f"{1000 * np.quantile(added, 0.9):8.1f}   ratio of the medians {e2e_ms / plant_ms:.2f}x"
    )
    print(f"{'/odom sample → received (ms)':40s} {1000 * statistics.median(transport):8.1f}")
    print(
        f"50 Hz for {args.seconds:g} s: /cmd_vel sent {sent} ({probe.sent} in all), the twin "
        f"received {got} in all: lost {probe.sent - got}; /odom received {odom_n} "
        f"(expected {(args.seconds + 0.5) / ODOM_PERIOD_S:.0f}), gaps in the stamps {gaps}"
    )


if __name__ == "__main__":
    main()
