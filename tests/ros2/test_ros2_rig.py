"""``--robot ros2``: the ROS 2 rig against ``omnical ros2 twin`` and a minimal rclpy robot.

The option parsing, the refusals and the scan conversion run with the suite; the runs (``alone``)
start the robots as processes on a private ROS_DOMAIN_ID on localhost and kill them by PID.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml
from ros2_env import (
    RosProcess,
    needs_ros2,
    omnical_command,
    private_domain_id,
    ros_env,
    with_priority,
)

import omnical
from omnical.bags.bag import read_bag
from omnical.cli.robot_target import parse_hedge, parse_robot_target
from omnical.errors import ConfigError, ProtocolError, SafetyStopError
from omnical.recording.topics import (
    CMD_VEL,
    EVENTS,
    GROUND_TRUTH,
    HEDGE_POS_ANG,
    IMU,
    JOINT_STATES,
    ODOM,
    SCAN,
)
from omnical.robot.loader import load_robot
from omnical.ros2.messages import yaw_from_quaternion
from omnical.ros2.rig import (
    SecondOdomPublisherError,
    full_circle_ranges,
    stream_limit_s,
    two_robots,
)
from omnical.services.hil import SCALED_STALL_S

ROBOT_SCRIPT = Path(__file__).with_name("ros2_robot.py")
CHECKS_SCRIPT = Path(__file__).with_name("ros2_rig_checks.py")
SCRIPT = """name: rig-short
steps:
  - hold: {duration_s: 0.5}
  - move: {vx_mps: 0.2, distance_m: 0.3}
  - move: {wz_radps: 0.5, angle_deg: 30}
  - move: {vy_mps: 0.15, distance_m: 0.2}
  - hold: {duration_s: 0.5}
"""


# ----------------------------------------------------------------------------- with the suite


def test_robot_ros2_is_parsed_once_with_its_model() -> None:
    target = parse_robot_target("ros2")
    assert (target.kind, target.model, target.port, target.is_live) == (
        "ros2", "rosy-mecanum", None, True,
    )  # fmt: skip
    assert parse_robot_target("ros2", "omni-x").model == "omni-x"
    assert not parse_robot_target("twin").is_live and parse_robot_target("serial:/x").is_live
    with pytest.raises(ConfigError, match="give 'ros2'"):
        parse_robot_target("ros2:/ns")


def test_hedge_from_a_topic() -> None:
    assert parse_hedge("topic:/hedge_pos").topic == "/hedge_pos"
    assert parse_hedge("topic:ips/fix") == parse_hedge("topic:/ips/fix")
    assert parse_hedge("topic:/ips/fix").kind == "topic"
    for bad in ("topic:", "topic:/9x", "topic:/a//b", "topic:/a b"):
        with pytest.raises(ConfigError, match="ROS 2 topic"):
            parse_hedge(bad)
    with pytest.raises(ConfigError, match="topic:/NAME"):
        parse_hedge("udp:1234")


def test_a_partial_scan_goes_on_a_full_circle_within_its_range_limits() -> None:
    ranges = np.array([1.0, 0.05, 2.0, 9.0, np.inf, 3.0])
    out, beams = full_circle_ranges(ranges, -math.pi / 2, math.pi / 180, 0.1, 8.0)
    assert beams == 360 and out.shape == (360,)
    assert out[0] == 1.0 and out[2] == 2.0 and out[5] == 3.0
    assert np.isnan(out[[1, 3, 4]]).all()  # too close, too far, no return
    assert np.isnan(out[6:]).all()  # beams the scan does not cover
    clockwise, _ = full_circle_ranges(np.array([1.0, 2.0]), 0.0, -math.pi / 2, 0.0, 8.0)
    assert clockwise[0] == 1.0 and clockwise[3] == 2.0  # −90° is beam 3 of 4
    with pytest.raises(ProtocolError, match="angle_increment"):
        full_circle_ranges(ranges, 0.0, 0.0, 0.1, 8.0)


def test_quaternion_yaw_and_stream_limits() -> None:
    yaw = 2.5
    assert yaw_from_quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)) == pytest.approx(yaw)
    assert stream_limit_s([], 0.25) == pytest.approx(0.3)  # 3 × 0.1 s before a rate is known
    assert stream_limit_s([0.0, 0.02, 0.04, 0.06, 0.08], 0.25) == 0.25  # 50 Hz: the floor
    assert stream_limit_s([0.0, 0.2, 0.4, 0.6], 0.25) == pytest.approx(0.6)
    assert stream_limit_s([0.0, 2.0, 4.0, 6.0], 0.25) == 1.0  # a slow stream: capped


def test_a_second_odom_publisher_is_one_line_naming_them(monkeypatch: pytest.MonkeyPatch) -> None:
    import pickle

    monkeypatch.setenv("ROS_DOMAIN_ID", "7")
    err = SecondOdomPublisherError("ROS 2 robot (/odom)", ["/robot_b", "/ns/robot_a"])
    assert str(err) == (
        "2 nodes publish /odom on ROS_DOMAIN_ID 7 (/ns/robot_a, /robot_b): one robot per domain: "
        "stop the other one, or give each robot a ROS_DOMAIN_ID of its own "
        "(discovered after the start: robot stopped)"
    )
    assert isinstance(err, SafetyStopError)  # exit 4, the run kept
    again = pickle.loads(pickle.dumps(SecondOdomPublisherError("r", ["/a", "/b"], moving=False)))
    assert str(again).endswith("(discovered after the start: motion not started)")
    assert again.publishers == ("/a", "/b") and not again.moving
    assert "(2 nodes named /robot, /x)" in two_robots(["/robot", "/x", "/robot"])
    unknown = "_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_"  # rmw's, before the node's graph info
    assert "(/robot, a node not named yet)" in two_robots(["/robot", unknown])


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["run", "tour", "-o", "x.mcap", "--hedge", "topic:/h"], "needs --robot ros2"),
        (["run", "tour", "-o", "x.mcap", "--robot", "serial:/dev/null", "--hedge", "none",
          "--twist-stamped"],
         "--twist-stamped applies to --robot ros2"),
        (["run", "tour", "-o", "x.mcap", "--robot", "twin", "--time-scale", "2"],
         "--time-scale applies to a live robot"),
        (["calibrate", "campaign", "--robot", "ros2", "--hedge", "topic:/h", "--yes"],
         "raw distances"),
        (["run", "tour", "-o", "x.mcap", "--robot", "ros2", "--hedge", "topic:/h"],
         "give the beacon map with --beacons"),
        (["calibrate", "campaign", "--robot", "ros2", "--hedge", "none", "--yes"],
         "needs the hedgehog"),
        (["navigate", "--map", "lab-8x6", "--start", "1,1,0", "--goal", "2,1", "-o", "n.mcap",
          "--robot", "ros2", "--world", "lab-8x6"], "drives in the real one"),
        (["ros2", "correct", "--factors", "f.yaml", "--monitor", "a:b:c"], "--monitor 'a:b:c'"),
        (["ros2", "locate", "--hedge", "serial:/x", "--monitor", "99999"], "--monitor '99999'"),
        (["ros2", "map", "lab-8x6", "--monitor", "x:0"], "--monitor 'x:0'"),
    ],
)  # fmt: skip
def test_refusals_before_ros_is_touched(
    args: list[str], says: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from typer.testing import CliRunner

    from omnical.cli.main import app

    def no_ros(**_: object) -> None:
        raise AssertionError("ROS 2 loaded before the options were checked")

    monkeypatch.setattr("omnical.ros2.runtime.ensure_ros_environment", no_ros)
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2, result.output
    assert says in result.output
    assert "Traceback" not in result.output


# ----------------------------------------------------------------------------- ROS 2 runs


def _robot(env: dict[str, str], *args: str) -> RosProcess:
    proc = RosProcess([sys.executable, str(ROBOT_SCRIPT), *args], env, priority=True)
    assert proc.readline(30.0).strip() == "robot up", proc.stop()
    return proc


def _report(proc: RosProcess) -> dict[str, object]:
    status, out, err = proc.stop()
    assert status == 0, err
    result: dict[str, object] = json.loads(out.strip().splitlines()[-1])
    return result


@pytest.fixture
def env(request: pytest.FixtureRequest) -> Iterator[dict[str, str]]:
    yield ros_env(private_domain_id(request.node.name))


@needs_ros2
@pytest.mark.alone
def test_run_over_ros2_ends_where_the_in_process_twin_does(
    env: dict[str, str], tmp_path: Path
) -> None:
    """The same script through ``--robot ros2`` against ``omnical ros2 twin`` and on the
    in-process twin: final odometry within 2 cm (issue 25's target), the bag's topics."""
    script = tmp_path / "short.yaml"
    script.write_text(SCRIPT)
    twin = RosProcess(
        omnical_command("ros2", "twin", "--robot", "rosy-mecanum"), env, priority=True
    )
    try:
        line = twin.readline(30.0)
        assert line.startswith("hedgehog: "), (line, twin.stop())
        done = subprocess.run(
            with_priority(omnical_command(
                "run", str(script), "--robot", "ros2", "--hedge", "none", "--yes",
                "-o", str(tmp_path / "ros2.mcap"),
            )),
            env=env, capture_output=True, text=True, timeout=120, check=False,
        )  # fmt: skip
    finally:
        twin.stop()
    assert done.returncode == 0, done.stderr + done.stdout
    assert "ROS 2 robot: /odom, /imu, /joint_states" in done.stdout
    local = subprocess.run(
        omnical_command("run", str(script), "-o", str(tmp_path / "local.mcap")),
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert local.returncode == 0, local.stderr
    over, here = read_bag(tmp_path / "ros2.mcap"), read_bag(tmp_path / "local.mcap")
    for topic in (ODOM, IMU, JOINT_STATES, CMD_VEL, EVENTS):
        assert over.has(topic), topic
    odom = over.topic(ODOM)
    span_s = (odom.t_ns[-1] - odom.t_ns[0]) / 1e9
    assert len(odom.t_ns) / span_s == pytest.approx(50.0, rel=0.1)  # the twin's /odom rate
    a, b = over.topic(ODOM), here.topic(ODOM)
    end_over = np.array([a["x_m"][-1], a["y_m"][-1]])
    end_here = np.array([b["x_m"][-1], b["y_m"][-1]])
    assert np.hypot(*end_here) > 0.2  # it moved
    # issue 25's 2 cm, plus what a stall of this machine (seen as the longest gap in /odom, one
    # period expected) may add to a move at the script's 0.2 m/s, 0.5 rad/s: load can lengthen
    # a move over ROS 2 (measured on `tour` beside busy loops: 0.1, 2.0 and 14.5 cm)
    stall_s = max(0.0, float(np.diff(odom.t_ns).max()) / 1e9 - 0.02)
    apart_m = float(np.hypot(*(end_over - end_here)))
    print(f"final odometry {apart_m * 100:.2f} cm apart; longest /odom gap {stall_s:.3f} s")
    assert apart_m < 0.02 + 0.2 * stall_s, (end_over, end_here, stall_s)
    assert abs(a["yaw_rad"][-1] - b["yaw_rad"][-1]) < math.radians(2.0) + 0.5 * stall_s


@needs_ros2
@pytest.mark.alone
def test_stamped_commands_a_topic_hedgehog_and_the_scan_are_recorded(
    env: dict[str, str], tmp_path: Path
) -> None:
    script = tmp_path / "short.yaml"
    script.write_text(SCRIPT)
    robot = _robot(env, "--stamped")
    try:
        done = subprocess.run(
            with_priority(omnical_command(
                "run", str(script), "--robot", "ros2", "--twist-stamped", "--yes",
                "--hedge", "topic:/hedge_pos", "--beacons", "default",
                "-o", str(tmp_path / "run.mcap"),
            )),
            env=env, capture_output=True, text=True, timeout=120, check=False,
        )  # fmt: skip
    finally:
        report = _report(robot)
    assert done.returncode == 0, done.stderr + done.stdout
    hx, hy = (2.9, 2.4) - np.asarray(load_robot("rosy-mecanum").hedge_offset_m)[:2]
    assert f"path checked from ({hx:.2f}, {hy:.2f}) m" in done.stdout
    assert "/scan (360 beams)" in done.stdout and "(TwistStamped)" in done.stdout
    rec = read_bag(tmp_path / "run.mcap")
    assert len(rec.topic(HEDGE_POS_ANG).t_ns) > 40  # 10 Hz over ≈ 7 s
    scans = rec.topic(SCAN)
    assert np.asarray(scans["ranges_m"]).shape[1] == 180
    assert np.asarray(rec.topic(JOINT_STATES)["name"])[0].tolist() == ["w1", "w2", "w3", "w4"]
    assert report["last"] == [0.0, 0.0, 0.0]
    assert isinstance(report["pose"], list) and report["pose"][0] > 0.05  # stopped while moving
    pose = report["pose"]
    assert isinstance(pose, list) and pose[0] > 0.15  # it moved, on the stamped commands
    odom = rec.topic(ODOM)
    assert float(odom["x_m"][-1]) == pytest.approx(pose[0], abs=0.02)


@needs_ros2
@pytest.mark.alone
def test_a_silent_odom_stops_the_robot_and_keeps_the_run(
    env: dict[str, str], tmp_path: Path
) -> None:
    script = tmp_path / "short.yaml"
    script.write_text(SCRIPT)
    robot = _robot(env, "--silent-after", "0.6")
    try:
        done = subprocess.run(
            omnical_command(
                "run", str(script), "--robot", "ros2", "--hedge", "none", "--yes",
                "-o", str(tmp_path / "run.mcap"),
            ),
            env=env, capture_output=True, text=True, timeout=120, check=False,
        )  # fmt: skip
    finally:
        report = _report(robot)
    assert done.returncode == 4, done.stderr + done.stdout
    assert "ROS 2 robot (/odom): no valid data" in done.stderr
    assert "robot stopped" in done.stderr and "Traceback" not in done.stderr
    assert (tmp_path / "run.partial").exists()
    assert report["last"] == [0.0, 0.0, 0.0]
    assert isinstance(report["pose"], list) and report["pose"][0] > 0.05  # stopped while moving


@needs_ros2
@pytest.mark.alone
def test_sigterm_sends_zero_and_exits_143(env: dict[str, str], tmp_path: Path) -> None:
    robot = _robot(env)
    try:
        proc = subprocess.Popen(
            omnical_command(
                "run", "straight-10m", "--robot", "ros2", "--hedge", "none", "--yes",
                "-o", str(tmp_path / "run.mcap"),
            ),
            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        assert robot.readline(30.0).strip() == "moving", proc.kill()
        time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    finally:
        report = _report(robot)
    assert proc.returncode == 143, err
    assert "kept the partial run" in err
    assert report["last"] == [0.0, 0.0, 0.0]
    assert isinstance(report["pose"], list) and report["pose"][0] > 0.05  # stopped while moving


@needs_ros2
@pytest.mark.alone
def test_navigate_over_ros2_localises_on_the_twins_scan(
    env: dict[str, str], tmp_path: Path
) -> None:
    """One leg in the lab against ``omnical ros2 twin --world lab-8x6``: localised by matching
    the twin's /scan to the map, it ends at the goal by the twin's /ground_truth."""
    twin = RosProcess(
        omnical_command("ros2", "twin", "--robot", "rosy-mecanum", "--world", "lab-8x6"),
        env,
        priority=True,
    )
    try:
        line = twin.readline(30.0)
        assert line.startswith("hedgehog: "), (line, twin.stop())
        done = subprocess.run(
            with_priority(omnical_command(
                "navigate", "--robot", "ros2", "--map", "lab-8x6", "--start", "1.5,1.2,0",
                "--goal", "2.3,1.5", "--yes", "-o", str(tmp_path / "nav.mcap"),
            )),
            env=env, capture_output=True, text=True, timeout=120, check=False,
        )  # fmt: skip
    finally:
        twin.stop()
    assert done.returncode == 0, done.stderr + done.stdout
    assert "scan-to-map matching" in done.stdout
    matched = re.search(r"scans matched: (\d+) used, (\d+) rejected", done.stdout)
    assert matched is not None and int(matched[1]) >= 20 and int(matched[2]) <= 2, done.stdout
    rec = read_bag(tmp_path / "nav.mcap")
    assert rec.has(SCAN) and rec.has(GROUND_TRUTH)
    truth = rec.topic(GROUND_TRUTH)
    end = np.array([truth["x_m"][-1], truth["y_m"][-1]])
    assert np.hypot(*(end - (2.3, 1.5))) < 0.05, end


CAMPAIGN_TIME_SCALE = 10.0
"""The CI campaign's clock: ``ros2 twin --time-scale`` and the campaign's ``--time-scale``."""
SCALED_RATE_HZ = {"odom": 20.0, "ground_truth": 10.0, "imu": 20.0}
"""The twin's streams on that clock (robot time; the preset's 50, 50 and 100 Hz make 2500
messages per wall second at x10, more than a loaded 2-core machine moves: the hedgehog's
stream, generated in the same process, stalled); 20 Hz is the vehicle controller's status rate,
on which the campaign over serial recovers the factors."""
ROBOT_PRESET = Path(omnical.__file__).parent / "data" / "robots" / "rosy-mecanum.yaml"


def _scaled_twin(env: dict[str, str], tmp_path: Path, k: float) -> tuple[RosProcess, str]:
    """``omnical ros2 twin`` of the default twin on a ``k``-times clock, its streams at
    :data:`SCALED_RATE_HZ` when k ≠ 1, and the path of its hedgehog's pty."""
    robot, twin_spec = "rosy-mecanum", "default"
    if k != 1.0:  # k times the messages per wall second: the streams at a robot's lower rates
        robot, twin_spec = str(tmp_path / "robot.yaml"), str(tmp_path / "twin.yaml")
        preset = yaml.safe_load(ROBOT_PRESET.read_text())
        preset["imu"]["rate_hz"] = SCALED_RATE_HZ["imu"]
        Path(robot).write_text(yaml.safe_dump(preset))
        Path(twin_spec).write_text(
            f"odom_rate_hz: {SCALED_RATE_HZ['odom']}\n"
            f"ground_truth_rate_hz: {SCALED_RATE_HZ['ground_truth']}\n"
        )
    twin = RosProcess(
        omnical_command(
            "ros2",
            "twin",
            "--robot",
            robot,
            "--twin",
            twin_spec,
            "--time-scale",
            f"{k:g}",
            "--cmd-timeout",
            f"{SCALED_STALL_S * k:g}",
        ),
        env,
        priority=k != 1.0,
    )  # fmt: skip  (the /cmd_vel timeout in robot time: SCALED_STALL_S of wall time, as the rig's)
    line = twin.readline(30.0)
    assert line.startswith("hedgehog: "), (line, twin.stop())
    return twin, line.split(": ", 1)[1].strip()


def _campaign_command(pty: str, k: float, out: Path, *more: str) -> list[str]:
    campaign = omnical_command(
        "calibrate", "campaign", "--robot", "ros2", "--hedge", f"serial:{pty}", "--yes",
        "--no-figures", "--time-scale", f"{k:g}", "--out", str(out), *more,
    )  # fmt: skip
    return with_priority(campaign) if k != 1.0 else campaign


def _streams_in_order(run_bag: Path) -> None:
    run = read_bag(run_bag)
    for topic in (CMD_VEL, ODOM, IMU, JOINT_STATES, HEDGE_POS_ANG):
        t = np.asarray(run.topic(topic).t_ns)
        assert len(t) > 10 and np.all(np.diff(t) >= 0), topic


def _campaign_over_ros2(env: dict[str, str], tmp_path: Path, k: float) -> None:
    """One iteration of seed 000's procedures over ROS 2 against ``omnical ros2 twin`` on a
    ``k``-times clock, the hedgehog on its pty: every scaling within 0.5 %, every cross-talk
    within 1.5 mrad/m of the twin's truth (issue 25)."""
    from omnical.calibration.factors_io import read_factors
    from omnical.twin.params import default_twin

    t0 = time.monotonic()
    twin, pty = _scaled_twin(env, tmp_path, k)
    try:
        campaign = _campaign_command(
            pty, k, tmp_path / "cal", "--max-iterations", "1", "--no-validate"
        )
        done = subprocess.run(
            campaign, env=env, capture_output=True, text=True, timeout=1200, check=False
        )
    finally:
        twin.stop()
    wall_s = time.monotonic() - t0
    assert done.returncode == 0, done.stderr + done.stdout
    got = read_factors(tmp_path / "cal" / "factors.yaml").factors.as_dict()
    truth = default_twin(load_robot("rosy-mecanum")).true_factors.as_dict()
    off = {
        key: round((value / truth[key] - 1.0) * 100, 3) if key.startswith("scale_") else
        round((value - truth[key]) * 1e3, 2)
        for key, value in got.items()
    }  # fmt: skip
    print(f"campaign over ROS 2 at x{k:g}: {wall_s:.0f} s wall; % / mrad/m off: {off}")
    for key, value in off.items():
        assert abs(value) < (0.5 if key.startswith("scale_") else 1.5), (key, got, truth)
    _streams_in_order(next((tmp_path / "cal" / "recordings").glob("iter1-rotation*")))


@needs_ros2
@pytest.mark.alone
def test_a_campaign_over_ros2_on_a_x10_clock_stops_on_sigterm_and_keeps_its_runs(
    env: dict[str, str], tmp_path: Path
) -> None:
    """``calibrate campaign --robot ros2`` against ``ros2 twin``, both on a x10 clock, the
    hedgehog on the twin's pty: SIGTERM once the first procedure (63 s of robot time) is done
    and the robot moves on (driving home, or the next procedure): exit 143, one line, the
    finished run kept aside with every stream recorded in order. The whole iteration and its
    factors: opt-in (below)."""
    import queue
    import threading

    k = CAMPAIGN_TIME_SCALE
    err_path = tmp_path / "campaign.err"
    twin, pty = _scaled_twin(env, tmp_path, k)
    with err_path.open("w") as err_file:
        proc = subprocess.Popen(
            _campaign_command(pty, k, tmp_path / "cal"),
            env=env, stdout=subprocess.PIPE, stderr=err_file, text=True,
        )  # fmt: skip
    lines: queue.Queue[str] = queue.Queue()

    def read_lines() -> None:
        for line in proc.stdout or ():
            lines.put(line)

    threading.Thread(target=read_lines, daemon=True).start()
    try:
        seen: list[str] = []
        deadline = time.monotonic() + 120
        while not seen or "driving home first" not in seen[-1]:
            left = deadline - time.monotonic()
            if left <= 0 or (proc.poll() is not None and lines.empty()):
                break
            with contextlib.suppress(queue.Empty):
                seen.append(lines.get(timeout=min(left, 1.0)))
        said = "".join(seen) + err_path.read_text()
        assert seen and "driving home first" in seen[-1], said
        time.sleep(0.2)  # moving on
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        twin.stop()
    err = err_path.read_text()
    assert proc.returncode == 143, err
    assert "robot stopped; kept" in err and "Traceback" not in err, err
    assert not (tmp_path / "cal").exists()  # the runs are kept aside: no campaign under OUT
    _streams_in_order(tmp_path / "cal.partial" / "recordings" / "iter1-rotation.mcap")


_CAMPAIGN_OPT_IN = os.environ.get("OMNICAL_ROS2_CAMPAIGN", "")


@needs_ros2
@pytest.mark.alone
@pytest.mark.skipif(
    _CAMPAIGN_OPT_IN not in ("1", "x10"),
    reason="≈ 45 s: OMNICAL_ROS2_CAMPAIGN=x10 (or =1, with the real-time one)",
)
def test_a_short_campaign_over_ros2_recovers_the_twins_factors(
    env: dict[str, str], tmp_path: Path
) -> None:
    """On a x10 clock (its 6.4 robot-minutes in ≈ 45 s)."""
    _campaign_over_ros2(env, tmp_path, CAMPAIGN_TIME_SCALE)


@needs_ros2
@pytest.mark.alone
@pytest.mark.skipif(
    _CAMPAIGN_OPT_IN != "1",
    reason="≈ 6.5 min of real time: OMNICAL_ROS2_CAMPAIGN=1 (or bench/bench_ros2_rig.py)",
)
def test_a_campaign_over_ros2_in_real_time_recovers_the_twins_factors(
    env: dict[str, str], tmp_path: Path
) -> None:
    """In real time (measured 0.04 % and 0.37 mrad/m in 6.4 min)."""
    _campaign_over_ros2(env, tmp_path, 1.0)


@needs_ros2
@pytest.mark.alone
def test_a_second_robot_on_the_domain_stops_the_motion_or_is_refused(
    env: dict[str, str], tmp_path: Path
) -> None:
    """A second node publishing /odom started while the robot moves (Fast DDS's discovery can
    take 2 s, so this is also what a second robot discovered late looks like): the motion
    stops (exit 4, the run kept) with one line naming both nodes and what to do. With both up
    before the start: refused at start (exit 2), or stopped so (exit 4) if discovered late.
    Either way the robots get zero."""
    first, second = _robot(env, "--name", "robot_a"), None
    run = omnical_command(
        "run", "straight-10m", "--robot", "ros2", "--hedge", "none", "--yes",
        "-o", str(tmp_path / "run.mcap"),
    )  # fmt: skip
    try:
        proc = subprocess.Popen(
            run, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        assert first.readline(30.0).strip() == "moving", proc.kill()
        second = _robot(env, "--name", "robot_b")
        _, err = proc.communicate(timeout=60)
        run[run.index("-o") + 1] = str(tmp_path / "again.mcap")
        again = subprocess.run(
            run, env=env, capture_output=True, text=True, timeout=60, check=False
        )
    finally:
        reports = [_report(r) for r in (first, second) if r is not None]
    assert proc.returncode == 4, err
    said = [line for line in err.splitlines() if "nodes publish /odom" in line]
    assert len(said) == 1, err
    assert said[0].startswith("omnical: error: 2 nodes publish /odom on ROS_DOMAIN_ID")
    assert "(/robot_a, /robot_b)" in said[0] and "ROS_DOMAIN_ID of its own" in said[0]
    assert said[0].endswith("(discovered after the start: robot stopped)")
    assert "no valid data" not in err and "Traceback" not in err
    assert (tmp_path / "run.partial").exists()  # what was recorded is kept
    assert again.returncode in (2, 4), again.stderr + again.stdout
    assert "(/robot_a, /robot_b): one robot per domain" in again.stderr
    assert "Traceback" not in again.stderr
    assert len(reports) == 2 and all(r["last"] == [0.0, 0.0, 0.0] for r in reports)


@needs_ros2
@pytest.mark.alone
def test_cmd_vel_check_a_failing_command_thread_close_and_a_stale_scan(
    env: dict[str, str],
) -> None:
    """In one process (ros2_rig_checks.py): nobody on /cmd_vel, or the other Twist type, is
    refused before anything moves; a tick of the command thread that raises leaves the 20-Hz
    stream alive at zero and the next motion raises; close publishes zero for 0.3 s and refuses
    a later motion; a scan older than its silence limit is refused; a scan's age."""
    done = subprocess.run(
        [sys.executable, str(CHECKS_SCRIPT)],
        env=env, capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["nobody"].startswith("ConfigError: nobody subscribes to /cmd_vel")
    assert out["twist"] == ""
    assert out["stamped"].endswith("as geometry_msgs/msg/Twist: omit --twist-stamped")
    assert out["alive"] and out["zeros_while_failing"] >= 2
    assert out["motion_after_failure"].startswith("SafetyStopError: ROS 2 robot (/odom)")
    assert "command thread failed: RuntimeError('boom')" in out["motion_after_failure"]
    assert out["close_s"] >= 0.3 and out["zeros_at_close"] >= 4
    assert (
        out["motion_after_close"].startswith("ProtocolError") and not out["published_after_close"]
    )
    assert out["fresh"] == 360 and out["limit_s"] == pytest.approx(0.5)
    assert out["stale"].startswith("SafetyStopError: LiDAR (/scan): no valid data for 0.70 s")
    assert out["stale_exceeded"]
    # the newest scan's age: its stamp on the host's clock by the smallest receipt delay
    assert out["unstamped_age_s"] == 0.0
    assert out["age_s"] == pytest.approx(0.058, abs=1e-6)
    assert out["age_swept_s"] == pytest.approx(0.058 - 0.1 * 359 / 360 / 2, abs=1e-6)


@needs_ros2
@pytest.mark.alone
def test_a_stamped_cmd_vel_without_twist_stamped_is_refused(
    env: dict[str, str], tmp_path: Path
) -> None:
    robot = _robot(env, "--stamped")
    try:
        done = subprocess.run(
            omnical_command(
                "run", "tour", "--robot", "ros2", "--hedge", "none", "--yes",
                "-o", str(tmp_path / "run.mcap"),
            ),
            env=env, capture_output=True, text=True, timeout=60, check=False,
        )  # fmt: skip
    finally:
        report = _report(robot)
    assert done.returncode == 2, done.stderr + done.stdout
    assert "subscribes to /cmd_vel as geometry_msgs/msg/TwistStamped: use --twist-stamped" in (
        done.stderr
    )
    assert "Traceback" not in done.stderr and report["count"] == 0


@needs_ros2
@pytest.mark.alone
def test_navigating_on_a_scan_that_dies_is_a_safety_stop(
    env: dict[str, str], tmp_path: Path
) -> None:
    """/scan silent 0.3 s after the first motion while the robot is localised on it: exit 4
    naming the LiDAR, the robot left at zero, the run kept."""
    robot = _robot(env, "--scan-silent-after", "0.3")
    try:
        done = subprocess.run(
            omnical_command(
                "navigate", "--robot", "ros2", "--map", "lab-8x6", "--start", "1.5,1.2,0",
                "--goal", "2.3,1.5", "--yes", "-o", str(tmp_path / "nav.mcap"),
            ),
            env=env, capture_output=True, text=True, timeout=120, check=False,
        )  # fmt: skip
    finally:
        report = _report(robot)
    assert done.returncode == 4, done.stderr + done.stdout
    assert "LiDAR (/scan): no valid data" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and (tmp_path / "nav.partial").exists()
    assert report["last"] == [0.0, 0.0, 0.0]
