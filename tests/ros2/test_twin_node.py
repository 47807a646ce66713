"""``omnical ros2 twin`` against an independent rclpy probe, two processes on a private domain.

One twin and one probe run for the module (≈ 8 s): the probe waits for /odom, counts every topic
at rest, drives /cmd_vel at 0.3 m/s for 1.5 s and stops commanding; the tests read its report.
Margins come from the scenario: the preset's 0.5 m/s² limit, the 0.5 s timeout, 50 Hz odometry.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import os
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from ros2_env import (
    PROBE,
    RosProcess,
    needs_ros2,
    omnical_command,
    private_domain_id,
    process_cpu_s,
    ros_env,
)

from omnical.calibration.factors_io import write_factors
from omnical.kinematics.correction import CorrectionFactors
from omnical.recording.recording import RecordingBuilder
from omnical.recording.topics import ODOM
from omnical.robot.loader import load_robot
from omnical.ros2.messages import WHEELTEC_MOVING_COVARIANCE_DIAG, WHEELTEC_STOPPED_COVARIANCE_DIAG
from omnical.twin.params import load_twin
from omnical.twin.simulator import DigitalTwin

pytestmark = [needs_ros2, pytest.mark.alone]  # wall clock, two processes: see pyproject.toml

VX_MPS = 0.3
MOVING_MPS = 0.01
TIMEOUT_S = 0.5
ODOM_PERIOD_S = 1.0 / 50.0
ROBOT = "rosy-mecanum"
LIDAR_LINE = "lidar: {position_m: [0.0, 0.0, 0.25], yaw_deg: 0}"
OFFSET_LIDAR_LINE = "lidar: {position_m: [0.12, -0.05, 0.25], yaw_deg: 10}"
FACTORS = CorrectionFactors.seed000_table2()
FACTORS_SIGMA = CorrectionFactors(0.002, 0.003, 0.004, 0.001, 0.001, 0.002, 0.002)


@dataclass
class Run:
    report: dict[str, Any]
    twin_started_wall_s: float
    twin_publishing_wall_s: float
    twin_publishing_cpu_s: float
    hedge_path: str
    hedge_bytes: bytes
    twin_status: int
    twin_stderr: str
    helper_stops: list[tuple[int, str, str]]
    robot_file: Path


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Run]:
    env = ros_env(private_domain_id(__name__))
    folder = tmp_path_factory.mktemp("ros2")
    factors = folder / "factors.yaml"
    write_factors(factors, FACTORS, FACTORS_SIGMA)
    # the preset with its LiDAR off the base's centre and turned (the preset's sits at 0, 0):
    # /tf_static must carry the mount as the robot file gives it
    preset = (files("omnical") / "data" / "robots" / f"{ROBOT}.yaml").read_text(encoding="utf-8")
    robot_file = folder / "robot.yaml"
    robot_file.write_text(preset.replace(LIDAR_LINE, OFFSET_LIDAR_LINE), encoding="utf-8")
    assert load_robot(robot_file).lidar_mount.x_m == 0.12
    probe = RosProcess(
        [
            sys.executable,
            str(PROBE),
            "--vx",
            str(VX_MPS),
            "--moving-mps",
            str(MOVING_MPS),
            "--wait",
            "/odom",
            "/odom_calibrated",
            "/ips/fix",
            "/scan",
        ],
        env,
    )
    twin: RosProcess | None = None
    helpers: list[RosProcess] = []
    try:
        assert probe.readline(30.0).strip() == "ready", probe.stop()
        # at a robot's priority, as the rig's tests run it (ros2_env.with_priority)
        twin = RosProcess(
            omnical_command("ros2", "twin", "--robot", str(robot_file), "--world", "lab-8x6"),
            env,
            priority=True,
        )
        line = twin.readline(30.0)
        publishing = time.time()
        publishing_cpu_s = process_cpu_s(twin.pid)
        assert line.startswith("hedgehog: "), (line, twin.stop())
        hedge_path = line.split(": ", 1)[1].strip()
        fd = os.open(hedge_path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
        try:
            data = b""
            deadline = time.monotonic() + 3.0
            while len(data) < 64 and time.monotonic() < deadline:
                time.sleep(0.05)
                with contextlib.suppress(BlockingIOError):
                    data += os.read(fd, 4096)
        finally:
            os.close(fd)
        helpers.append(
            RosProcess(omnical_command("ros2", "correct", "--factors", str(factors)), env)
        )
        helpers.append(
            RosProcess(omnical_command("ros2", "locate", "--hedge", f"serial:{hedge_path}"), env)
        )
        out = probe.readline(90.0)
        stops = [h.stop() for h in helpers]
        helpers = []
        started = twin.started_wall_s
        status, _, err = twin.stop()
        twin = None
        assert out.strip(), probe.stop()
        report = json.loads(out)
        yield Run(
            report, started, publishing, publishing_cpu_s, hedge_path, data, status, err, stops,
            robot_file,
        )  # fmt: skip
    finally:
        for process in [*helpers, *([twin] if twin is not None else [])]:
            process.stop()
        probe.stop()


def test_first_odom_within_two_seconds_of_the_twin_start(run: Run) -> None:
    # The twin prints the hedgehog's path once its node publishes (the odometry flows from
    # then on, a sample each 20 ms): from Popen to that line, the re-execution for the library
    # path, the imports, the node and the twin's start included.
    # Issue 25's 2 s on a machine with a core for it: measured 1.1 s here (1.3 s of CPU, the
    # twin's threads beside the start), at nice 0 and at the robot's priority alike. A start-up
    # is CPU work, which a machine loaded beyond its cores shares out: the bound grows with the
    # load per core (at load 20 on 2 cores the start took 2.9 s); the 1-minute load lags a load
    # that just rose (CI, load 5.4 on 2 cores, at nice 0 and with services.navigation imported
    # for a world's path: 6.5 s), hence the priority.
    published = run.twin_publishing_wall_s - run.twin_started_wall_s
    limit_s = 2.0 * max(1.0, os.getloadavg()[0] / (os.cpu_count() or 1))
    assert 0.0 < published <= limit_s, (published, run.twin_publishing_cpu_s, limit_s)
    # The probe's first receipt adds Fast DDS's discovery of the new participant: measured
    # bimodal on localhost, ≈ 1 ms or ≈ 2 s (the next announcement), with either order of
    # start and with or without shared memory; bounded here by one more 3 s announcement period.
    received = run.report["first_wall_s"]["/odom"] - run.twin_started_wall_s
    assert published < received + 0.1
    assert received <= limit_s + 3.0, received


def plant_response_s(phases: int = 20) -> float:
    """The twin's own worst time, in process, from a command to the first odometry sample at
    ``MOVING_MPS``: the acceleration ramp, the motor lag, the backlash (≈ 0.12 s for the
    preset's default twin), the 100 Hz control and 50 Hz odometry ticks, over command phases."""
    description = load_robot(ROBOT)
    params = load_twin("default", description)
    worst = 0.0
    for k in range(phases):
        start = 1.0 + k * ODOM_PERIOD_S / phases
        twin = DigitalTwin(description, params, seed=0, engine="python")
        twin.advance_to(start)
        twin.send_twist(VX_MPS, 0.0, 0.0)
        twin.advance_to(start + 1.0)
        odom = twin.log().odom
        after = odom[odom[:, 0] > start]
        first = after[np.argmax(after[:, 4] >= MOVING_MPS), 0]
        worst = max(worst, float(first - start))
    return worst


def stall_s(report: dict[str, Any], start_s: float, end_s: float) -> float:
    """What a stall of this loaded machine (the twin, the probe, or the delivery between them)
    added between ``start_s`` and ``end_s`` (probe times): the longest gap between the probe's
    /odom receipts there beyond one odometry period (three real-time processes on 2 cores)."""
    rx = [t for t in report["odom_rx_s"] if start_s - 0.1 <= t <= end_s + 0.1]
    gaps = [b - a for a, b in itertools.pairwise(rx)]
    return max(0.0, max(gaps, default=0.0) - ODOM_PERIOD_S)


def test_commanded_motion_shows_in_odom_within_100_ms_plus_the_robots_response(run: Run) -> None:
    first_cmd, moving = run.report["first_cmd_s"], run.report["first_moving_s"]
    latency = moving - first_cmd
    stall = stall_s(run.report, first_cmd, moving)
    print(f"latency {latency * 1e3:.0f} ms; stall allowance {stall * 1e3:.0f} ms")
    assert 0.0 < latency <= 0.100 + plant_response_s() + stall, (latency, stall)
    assert run.report["max_vx_mps"] == pytest.approx(VX_MPS, abs=0.02)


def test_stops_within_the_timeout_plus_the_ramp_down_after_the_last_command(run: Run) -> None:
    limits = load_robot(ROBOT).limits
    ramp_s = VX_MPS / limits.max_ax_mps2  # 0.6 s
    last_cmd, stopped_at = run.report["last_cmd_s"], run.report["stopped_s"]
    stopped = stopped_at - last_cmd
    stall = stall_s(run.report, last_cmd, stopped_at)
    bound = TIMEOUT_S + ramp_s + ODOM_PERIOD_S + 0.15  # + the wheels' lag behind the ramp
    print(f"stopped {stopped:.3f} s after the last command; stall allowance {stall:.3f} s")
    assert TIMEOUT_S < stopped <= bound + stall, (stopped, stall)


def test_rates(run: Run) -> None:
    rest = run.report["rest_s"]
    expected = {"/odom": 50.0, "/ground_truth": 50.0, "/joint_states": 50.0, "/imu": 100.0}
    expected["/scan"] = 10.0
    for topic, hz in expected.items():
        # by the messages' stamps: a stall of this shared machine bunches receipts (62 Hz of
        # /odom counted in a window once), while the stamps say what was published
        stamped = run.report["rest_stamp_rates_hz"][topic]
        assert stamped == pytest.approx(hz, rel=0.12), (topic, stamped)
        # and received about as often in real time (generous: receipts bunch)
        received = run.report["rest_counts"][topic] / rest
        assert received == pytest.approx(hz, rel=0.5), (topic, received)


def test_frame_ids(run: Run) -> None:
    frames = run.report["frames"]
    assert frames["/odom"] == [["odom"], ["base_link"]]
    assert frames["/ground_truth"] == [["map"], ["base_link"]]
    assert frames["/imu"] == [["imu_link"]]
    assert frames["/scan"] == [["laser"]]
    # the corrected odometry's child frame is the one its TF moves (not the driver's base_link)
    assert frames["/odom_calibrated"] == [["odom"], ["base_link_calibrated"]]
    wheels = [w.name for w in load_robot(ROBOT).wheels]
    assert run.report["joint_names"] == wheels


def test_covariances_round_trip(run: Run) -> None:
    """/odom's pose and twist covariances, moving and stopped, as the probe received them:
    the Wheeltec driver's diagonals the twin publishes, nothing off the diagonal."""
    for part in ("pose", "twist"):
        moving = run.report[f"moving_{part}_covariance"]
        stopped = run.report[f"stopped_{part}_covariance"]
        assert [moving[7 * i] for i in range(6)] == list(WHEELTEC_MOVING_COVARIANCE_DIAG), part
        assert [stopped[7 * i] for i in range(6)] == list(WHEELTEC_STOPPED_COVARIANCE_DIAG), part
        assert sum(abs(v) for i, v in enumerate(moving) if i % 7) == 0.0, part
        assert sum(abs(v) for i, v in enumerate(stopped) if i % 7) == 0.0, part


def test_scan_sees_the_lab_walls(run: Run) -> None:
    assert run.report["scan_beams"] == 360
    assert run.report["scan_finite"] > 300  # an 8 × 6 m room: nearly every beam returns


def test_stamps_increase_at_the_odometry_period(run: Run) -> None:
    stamps = run.report["odom_stamps_s"]
    steps = [b - a for a, b in itertools.pairwise(stamps)]
    assert min(steps) > 0
    assert sum(steps) / len(steps) == pytest.approx(ODOM_PERIOD_S, rel=0.05)


def test_the_hedgehog_is_served_on_a_pty(run: Run) -> None:
    assert run.hedge_path.startswith("/dev/pts/")
    assert b"\xff" in run.hedge_bytes  # Marvelmind frames start with 0xFF


def test_the_twin_exits_130_on_sigint(run: Run) -> None:
    assert run.twin_status == 130, run.twin_stderr
    assert "Traceback" not in run.twin_stderr


def test_correct_publishes_the_offline_correction_of_the_odometry_it_received(run: Run) -> None:
    from omnical.estimation.odometry_sources import corrected_odometry

    raw = np.array(run.report["poses"]["/odom"])
    live = np.array(run.report["poses"]["/odom_calibrated"])
    assert len(live) > 100
    # the raw samples from the first one both the corrector and the probe saw: either may have
    # discovered the twin first (discovery took ≈ 1 ms or ≈ 2 s); the robot stands still until
    # the probe commands it, so there the corrected pose is still the raw one
    t0 = max(raw[0, 0], live[0, 0])
    first = int(np.argmin(np.abs(raw[:, 0] - t0)))
    k0 = int(np.argmin(np.abs(live[:, 0] - t0)))
    assert raw[first, 0] == live[k0, 0] == t0
    np.testing.assert_allclose(live[k0, 1:4], raw[first, 1:4], atol=1e-9)
    live = live[k0:]
    last = int(np.argmin(np.abs(raw[:, 0] - live[-1, 0])))
    assert raw[last, 0] == live[-1, 0]
    block = raw[first : last + 1]
    builder = RecordingBuilder()
    builder.add_many(
        ODOM,
        np.round(block[:, 0] * 1e9).astype(np.int64),
        x_m=block[:, 1],
        y_m=block[:, 2],
        yaw_rad=block[:, 3],
        vx_mps=np.zeros(len(block)),
        vy_mps=np.zeros(len(block)),
        wz_radps=np.zeros(len(block)),
    )
    offline = corrected_odometry(builder.build(), FACTORS).topic(ODOM)
    assert offline["x_m"][-1] == pytest.approx(live[-1, 1], abs=1e-6)
    assert offline["y_m"][-1] == pytest.approx(live[-1, 2], abs=1e-6)
    assert offline["yaw_rad"][-1] == pytest.approx(live[-1, 3], abs=1e-6)
    # 0.45 m forward: the longitudinal scale's 1σ (0.2 %) makes ≥ 0.9 mm of σ in x, added to
    # the driver's 1e-3 m² (Wheeltec's moving covariance) or 1e-9 (stopped)
    moved_m = abs(live[-1, 1] - live[0, 1])
    assert moved_m > 0.3
    sigma_x = np.sqrt(live[-1, 4] - min(live[-1, 4], 1e-3) if live[-1, 4] > 1e-3 else live[-1, 4])
    assert sigma_x == pytest.approx(moved_m * 0.002 / FACTORS.scale_longitudinal, rel=0.2)
    assert all(status == 130 for status, _, _ in run.helper_stops), run.helper_stops


def test_locate_publishes_the_hedgehogs_fixes_near_the_truth(run: Run) -> None:
    fixes = np.array(run.report["poses"]["/ips/fix"])
    truth = np.array(run.report["poses"]["/ground_truth"])
    span = fixes[-1, 0] - fixes[0, 0]
    assert len(fixes) / span > 4.0  # the twin's hedgehog: ≈ 8–16 Hz
    description = load_robot(ROBOT)
    hx, hy, _ = description.hedge_offset_m
    at = np.searchsorted(truth[:, 0], fixes[:, 0]).clip(0, len(truth) - 1)
    x, y, yaw = truth[at, 1], truth[at, 2], truth[at, 3]
    hedge_x = x + np.cos(yaw) * hx - np.sin(yaw) * hy
    hedge_y = y + np.sin(yaw) * hx + np.cos(yaw) * hy
    error = np.hypot(fixes[:, 1] - hedge_x, fixes[:, 2] - hedge_y)
    assert np.median(error) < 0.1  # the fix latency at 0.3 m/s and the vendor's noise
    assert fixes[0, 4] == pytest.approx(0.02**2)


def test_tf_moves_base_link_as_odom_does_and_base_link_calibrated_as_odom_calibrated(
    run: Run,
) -> None:
    """TF, on the tf2_msgs `omnical ros2 build-tf2-msgs` built (make does): odom → base_link from
    the twin and odom → base_link_calibrated from `ros2 correct`, each transform the pose of the
    odometry message of the same stamp, received by an independent node."""
    from omnical.ros2.interfaces import tf2_msgs_installed

    if not tf2_msgs_installed():
        if os.environ.get("CI"):
            pytest.fail("no tf2_msgs on CI: make runs `omnical ros2 build-tf2-msgs`")
        pytest.skip("no tf2_msgs: omnical ros2 build-tf2-msgs")
    transforms = run.report["tf"]
    assert {(t[1], t[2]) for t in transforms} == {
        ("odom", "base_link"),
        ("odom", "base_link_calibrated"),
    }
    for topic, child in (("/odom", "base_link"), ("/odom_calibrated", "base_link_calibrated")):
        poses = {p[0]: p[1:4] for p in run.report["poses"][topic]}
        mine = {t[0]: t[3:6] for t in transforms if t[2] == child}
        both = sorted(set(poses) & set(mine))
        # every message has its transform (both reliable, depth 50), but for the first and
        # last few the probe's two subscriptions may have caught one and not the other
        assert len(both) >= 100 and len(both) >= min(len(poses), len(mine)) - 10, child
        np.testing.assert_allclose([mine[t] for t in both], [poses[t] for t in both], atol=1e-9)
        assert max(abs(mine[t][0]) for t in both) > 0.3, child  # the drive, 0.45 m forward


def test_tf_static_places_the_laser_at_the_lidar_mount_and_the_imu_at_the_base(run: Run) -> None:
    """/tf_static (transient local, depth 1: what a late subscriber gets is the last message):
    that message holds base_link → laser at the robot file's LiDAR mount (height too) and
    base_link → imu_link at the origin."""
    from omnical.ros2.interfaces import tf2_msgs_installed

    if not tf2_msgs_installed():
        pytest.skip("no tf2_msgs: omnical ros2 build-tf2-msgs")  # the test above fails on CI
    last = {(t[1], t[2]): t[3:7] for t in run.report["tf_static_last"]}
    assert set(last) == {("base_link", "imu_link"), ("base_link", "laser")}
    mount = load_robot(run.robot_file).lidar_mount
    expected = [mount.x_m, mount.y_m, mount.yaw_rad, mount.z_m]
    assert expected == pytest.approx([0.12, -0.05, math.radians(10.0), 0.25])
    assert last[("base_link", "laser")] == pytest.approx(expected)
    assert last[("base_link", "imu_link")] == [0.0, 0.0, 0.0, 0.0]
