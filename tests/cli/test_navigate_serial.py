"""``omnical navigate --robot serial:… --hedge serial:…`` against the pseudo-terminal twin.

The robot is localised by the driver's odometry fused with the live hedgehog fixes (no scan
matching over serial); the goals are checked on the device server's ground truth. The lab map's
frame is the twin's, and the default beacon map covers the legs. Measured (default rosy-mecanum
twin, uncalibrated): two tracking legs on ``lab-8x6`` end 2.0 cm from the last goal by the
truth at the wall clock (24.6 s wall), run here at ×2.
"""

from __future__ import annotations

import itertools
import math
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from omnical.bags.bag import read_bag
from omnical.robot.loader import load_robot
from omnical.twin.device import DeviceConfig, TwinDeviceServer
from omnical.twin.params import TwinParams, load_twin

ROBOT = load_robot("rosy-mecanum")
GOALS = ((2.5, 1.0), (2.5, 2.2))


def _params(twin: str = "default") -> TwinParams:
    return replace(load_twin(twin, ROBOT), start_pose_map=(1.0, 1.0, 0.0))


def _omnical(*args: str) -> list[str]:
    return [sys.executable, "-c", "from omnical.cli.main import main; main()", *args]


def _nav_args(server: TwinDeviceServer, out: Path, *extra: str, start: str = "1,1,0") -> list[str]:
    goals = [a for g in GOALS for a in ("--goal", f"{g[0]},{g[1]}")]
    return _omnical(
        "navigate", "--robot", f"serial:{server.vehicle_path}",
        "--hedge", f"serial:{server.hedge_path}", "--map", "lab-8x6", "--start", start,
        *goals, "--controller", "tracking", "--beacons", "default", "--yes",
        "--out", str(out), *extra,
    )  # fmt: skip


def _rest_positions(
    commands: list[tuple[float, float, float, float]],
    truth: list[tuple[float, float, float, float]],
    legs: int,
) -> list[tuple[float, float]]:
    """Where the twin stood (x, y) at the end of each of ``legs`` drives, on the device's clock.

    The legs are split at the ``legs - 1`` longest runs of zero commands between nonzero ones
    (the host's settling between legs, 0.5 s of them: more than a command rounded to zero on
    the way, and a stall of the host sends none); a leg's rest is the truth just before the
    next leg's first command, the last one's the truth at the end."""
    cmd = np.asarray(commands, dtype=np.float64)
    moving = np.flatnonzero(np.any(cmd[:, 1:] != 0.0, axis=1))
    gaps = sorted(((b - a - 1, cmd[b, 0]) for a, b in itertools.pairwise(moving)), reverse=True)
    t_truth = np.asarray([row[0] for row in truth])
    out = []
    for t in [*sorted(t for _, t in gaps[: legs - 1]), math.inf]:
        i = max(int(np.searchsorted(t_truth, t)) - 1, 0)
        out.append((truth[i][1], truth[i][2]))
    return out


@pytest.mark.alone
def test_two_legs_over_serial_reach_their_goals_by_the_ground_truth(tmp_path: Path) -> None:
    scale = 2.0
    out = tmp_path / "nav.mcap"
    with TwinDeviceServer(ROBOT, _params(), seed=0, config=DeviceConfig(time_scale=scale)) as srv:
        t0 = time.monotonic()
        done = subprocess.run(
            _nav_args(srv, out, "--time-scale", f"{scale:g}"),
            capture_output=True, text=True, timeout=120, check=False,
        )  # fmt: skip
        wall = time.monotonic() - t0
    assert done.returncode == 0, done.stderr + done.stdout
    assert "no scan matching" in done.stdout and "fused with the hedgehog" in done.stdout
    bag = read_bag(out)
    for topic in ("/cmd_vel", "/odom", "/imu", "/hedge_pos_ang", "/omnical/events"):
        assert bag.has(topic), topic
    ev = bag.topic("/omnical/events")
    ends = [int(t) for t, text in zip(ev.t_ns, ev["text"], strict=True) if '"end"' in str(text)]
    assert len(ends) == 2
    # where the robot stood at rest after each leg, on the device's own clock (the bag's stamps
    # start from the session, its first rows from the driver's buffer before it: no anchor)
    rests = _rest_positions(srv.command_history(), srv.truth_history(), len(GOALS))
    errors = [math.hypot(p[0] - g[0], p[1] - g[1]) for p, g in zip(rests, GOALS, strict=True)]
    print(
        f"navigate over serial (x{scale:g}, {wall:.1f} s wall): at rest after each leg, "
        f"{', '.join(f'{e * 100:.1f}' for e in errors)} cm from its goal by the truth"
    )
    assert max(errors) < 0.05


@pytest.mark.alone  # wall clock on pseudo-terminals: see pyproject.toml
def test_sigint_mid_leg_stops_the_robot_and_keeps_the_partial_bag(tmp_path: Path) -> None:
    """On a x2 clock (its limits SCALED_STALL_S, 1 s, of wall time: a loaded machine's stall does not end the
    leg before the signal does; on the robot's own clock, 0.15 s: exit 4, not 130)."""
    k = 2.0
    config = DeviceConfig(time_scale=k)
    with TwinDeviceServer(ROBOT, _params("ideal"), config=config) as server:
        proc = subprocess.Popen(
            _nav_args(server, tmp_path / "nav.mcap", "--time-scale", f"{k:g}"),
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        deadline = time.monotonic() + 25
        while server.last_command in (None, (0.0, 0.0, 0.0)) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert server.last_command not in (None, (0.0, 0.0, 0.0)), "the leg never moved"
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
        time.sleep(0.1)
        assert proc.returncode == 130, err
        assert server.last_command == (0.0, 0.0, 0.0)
    assert "kept the partial run" in err and "Traceback" not in err
    partial = read_bag(tmp_path / "nav.partial")
    cmd = partial.topic("/cmd_vel")
    assert np.asarray(cmd["vx_mps"])[-1] == 0.0 and np.any(np.asarray(cmd["vx_mps"]) > 0.05)
    assert partial.has("/odom") and partial.has("/hedge_pos_ang")


def test_a_wrong_start_or_a_leg_outside_the_area_is_refused(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from omnical.cli.main import app

    with TwinDeviceServer(ROBOT, _params("ideal")) as server:
        wrong = subprocess.run(
            _nav_args(server, tmp_path / "a.mcap", start="2,2,0"),
            capture_output=True, text=True, timeout=60, check=False,
        )  # fmt: skip
        # the second refusal in this process (the same command's code, without a second
        # interpreter's start-up: 2 s of CPU); the first is the console's
        outside = CliRunner().invoke(
            app, _nav_args(server, tmp_path / "b.mcap", "--area", "0.3,0.3,3.0,2.0")[3:]
        )
        assert server.last_command in (None, (0.0, 0.0, 0.0))
    assert wrong.returncode == 2, wrong.stderr
    assert "from --start (2.00, 2.00)" in wrong.stderr
    assert outside.exit_code == 2, outside.output
    assert "refused" in outside.stderr and "leg 2" in outside.stderr
    assert "allowed area" in outside.stderr
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_serial_and_twin_options_do_not_mix(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from omnical.cli.main import app

    base = ["navigate", "--map", "lab-8x6", "--start", "1,1,0", "--goal", "2,1"]
    out = ["--out", str(tmp_path / "n.mcap")]
    runner = CliRunner()
    r = runner.invoke(app, [*base, "--robot", "serial:/dev/null", "--world", "lab-8x6", *out])
    assert r.exit_code == 2 and "--world is the twin's floor plan" in r.output
    r = runner.invoke(app, [*base, "--robot", "serial:/dev/null", *out])
    assert r.exit_code == 2 and "--hedge serial:PORT" in r.output
    r = runner.invoke(app, [*base, *out])
    assert r.exit_code == 2 and "--world is required" in r.output
    # a goal off the map is a mistake on a serial robot too, found before any port is opened
    off = ["navigate", "--map", "lab-8x6", "--start", "1,1,0", "--goal", "100,100"]
    r = runner.invoke(
        app, [*off, "--robot", "serial:/dev/null", "--hedge", "serial:/dev/null", *out]
    )
    assert r.exit_code == 2 and "--goal 100,100: outside the map lab-8x6" in r.output
