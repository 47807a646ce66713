"""``omnical calibrate campaign --robot serial:… --hedge serial:…`` against ``omnical twin serve``.

A real campaign is ~20 min of robot time (2–3 iterations, the validation, the homing moves).
Here the device server and the host run on a clock ``k`` times faster than the wall clock
(``twin serve --time-scale`` and the campaign's hidden ``--time-scale``: the twin, the firmware
rates and watchdog, the byte timing, the host's runner, stamps and watchdogs). A scheduling
stall of either process is then ``k`` times longer in robot time; on a loaded machine that
drives the robot off its path (a stall at the end of a move lengthens it, one during the turns
adds rotation) and the campaign's estimates with it. Measured on the shared 2-core machine
(load average 4–8), tolerance as below:

* ``k = 20``, whole campaign: 114–133 s of wall time; passed once at load ~3, failed three times
  at load 6–8 (the last, with device-timed hedgehog rows: cross-talks 1.7 and 2.1 mrad/m off).
* ``k = 10``, whole campaign (the opt-in test): 159 s of wall time, scalings within 0.17 %,
  cross-talks within 0.55 mrad/m of the truth.
* ``k = 10``, the campaign's two iterations without the validation: 83 s of wall time (11.5
  min of robot time), scalings within 0.11 %, cross-talks within 0.9 mrad/m.
* ``k = 10``, the first iteration alone without the validation (the CI test): ≈ 40 s of wall
  time. Until the analysis dead-banded the odometry's yaw jitter on straight moves
  (``calibration.analysis_tracks.resolved_odometry``) one iteration over serial scattered to
  1.6–4.6 mrad/m in 5 of 7 runs: the status frame sends one control tick in five of the
  firmware's 0.73 mrad/s-step yaw rate, rounded to 1 mrad/s, and the host's integral of it
  drifted up to 0.6 mrad/s per move, which the analysis took for rotation that is not
  cross-talk. With it: 0.72 mrad/m at most over four runs at x2 and x10 (in process: 0.5).

Tolerance: the in-process campaign's (``tests/calibration/test_campaign.py``): each scaling
within 0.5 %, each cross-talk within 1.5 mrad/m of the twin's truth.

Under load (two busy loops in the same session, issue 24) the x10 iteration did not hold: its
stand-stills are 1 s of robot time, 0.1 s of wall time, and a stall of the hedgehog's stream
that long left fewer than three positions there (the campaign then refuses to move, as it
must), or a rest window without one ("hedgehog at rest at ?"). In a session of its own (as
``make test`` runs these) it passed twice beside the busy loops (40 and 42 s; scalings within
0.11 %, cross-talks within 0.55 mrad/m), but a 0.1-s stall is all its margin, and its 40 s do
not fit the suite's three minutes. The precision runs are therefore opt-in
(``OMNICAL_HIL_CAMPAIGN=1`` for the one iteration, ``OMNICAL_HIL_FULL_CAMPAIGN=1`` for the whole
campaign), and the campaign's procedures recovering the truth
are tested in process (``tests/calibration/test_campaign.py``, where the same campaign runs on
the twin's rig; the analysis of the host's status-frame odometry,
``tests/calibration/test_analysis_odometry.py``). ``make test`` runs what load cannot change
over serial: the campaign plans, drives its first procedure, records it and keeps it when a
SIGTERM stops the robot (below, x4: its rest windows 0.18 s of wall time, the stop sent once the
robot moves again), and a hedgehog that fails stops it (``tests/drivers/test_watchdog_cli.py``).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from omnical.bags.bag import read_bag
from omnical.calibration.factors_io import read_factors
from omnical.cli.robot_target import parse_hedge, parse_robot_target
from omnical.errors import ConfigError
from omnical.robot.loader import load_robot
from omnical.twin.params import default_twin

# Scaled-clock runs (`alone`: see pyproject.toml). The option parsing and the refusals below keep
# no time: they run with the rest of the suite.

ROBOT = load_robot("rosy-mecanum")
TRUTH = default_twin(ROBOT).true_factors
SCALE_TOL = 0.005  # the in-process campaign's acceptance: each scaling within 0.5 %
CROSS_TOL = 1.5e-3  # and each cross-talk within 1.5 mrad/m
CI_TIME_SCALE = float(os.environ.get("OMNICAL_HIL_TIME_SCALE", "10"))
ONE_ITERATION = os.environ.get("OMNICAL_HIL_CAMPAIGN") == "1"
FULL = os.environ.get("OMNICAL_HIL_FULL_CAMPAIGN") == "1"
WATCHDOG = os.environ.get("OMNICAL_HIL_WATCHDOG", "off")
FULL_TIME_SCALE = float(os.environ.get("OMNICAL_HIL_FULL_TIME_SCALE", "10"))


def _omnical(*args: str) -> list[str]:
    return [sys.executable, "-c", "from omnical.cli.main import main; main()", *args]


class _Server:
    """``omnical twin serve`` in a subprocess; its two device paths."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen(
            _omnical("twin", "serve", *args),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        lines = [self.proc.stdout.readline() for _ in range(2)]
        found = [re.search(r": (/dev/\S+)", line) for line in lines]
        assert all(found), lines
        self.vehicle, self.hedge = (m.group(1) for m in found if m is not None)

    def stop(self) -> str:
        self.proc.send_signal(signal.SIGINT)
        _, err = self.proc.communicate(timeout=20)
        return err


def test_robot_target_parsing() -> None:
    assert parse_robot_target("twin").kind == "twin"
    assert parse_robot_target("twin").model == "rosy-mecanum"
    assert parse_robot_target("omni-x").model == "omni-x"  # the older meaning: that robot's twin
    target = parse_robot_target("serial:/dev/ttyUSB0", "omni-x")
    assert (target.kind, target.port, target.model) == ("serial", "/dev/ttyUSB0", "omni-x")
    with pytest.raises(ConfigError, match="--model"):
        parse_robot_target("omni-x", "rosy-mecanum")
    with pytest.raises(ConfigError, match="after 'serial:'"):
        parse_robot_target("serial:")
    assert parse_hedge("serial:/dev/pts/4").port == "/dev/pts/4"
    assert parse_hedge("none").kind == "none"
    with pytest.raises(ConfigError, match="--hedge"):
        parse_hedge("usb")


def _wait(pred: object, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():  # type: ignore[operator]
            return True
        time.sleep(0.01)
    return False


def _campaign_over_serial(tmp_path: Path, time_scale: float, *options: str) -> float:
    """Run the campaign against ``twin serve``; assert the truth recovered; the wall time."""
    scale = f"{time_scale:g}"
    server = _Server(
        "--robot", "rosy-mecanum", "--twin", "default", "--watchdog", WATCHDOG, "--time-scale", scale
    )  # fmt: skip
    t0 = time.monotonic()
    try:
        done = subprocess.run(
            _omnical(
                "calibrate", "campaign", "--robot", f"serial:{server.vehicle}",
                "--model", "rosy-mecanum", "--hedge", f"serial:{server.hedge}",
                "--yes", "--no-figures", "--time-scale", scale, *options,
                "--out", str(tmp_path / "cal"),
            ),
            capture_output=True, text=True, timeout=600, check=False,
        )  # fmt: skip
    finally:
        server.stop()
    wall_s = time.monotonic() - t0
    assert done.returncode == 0, done.stderr + done.stdout
    factors = read_factors(tmp_path / "cal" / "factors.yaml").factors
    rel = factors.scales / TRUTH.scales - 1.0
    cross = factors.crosstalks_rad_per_m - TRUTH.crosstalks_rad_per_m
    print(
        f"campaign {' '.join(options)} over serial at x{scale}: {wall_s:.0f} s wall; scalings "
        f"vs truth {np.round(rel * 100, 3)} %, cross-talks {np.round(cross * 1e3, 2)} mrad/m"
    )
    summary = [
        ln.strip() for ln in done.stdout.splitlines() if "converged" in ln or "robot time" in ln
    ]
    print("  " + "; ".join(summary[-2:]))
    assert np.all(np.abs(rel) <= SCALE_TOL), rel
    assert np.all(np.abs(cross) <= CROSS_TOL), cross
    recordings = sorted((tmp_path / "cal" / "recordings").iterdir())
    run = read_bag(next(p for p in recordings if p.name.startswith("iter1-rotation")))
    for topic in ("/cmd_vel", "/odom", "/imu", "/beacon_raw_distance", "/hedge_pos_ang"):
        t = np.asarray(run.topic(topic).t_ns)
        assert len(t) > 10 and np.all(np.diff(t) >= 0), topic
    assert np.all(np.diff(np.asarray(run.topic("/odom").t_ns)) > 0)  # strictly, per frame
    return wall_s


@pytest.mark.alone
@pytest.mark.skipif(
    not ONE_ITERATION,
    reason="x10, 40 s, needs a quiet machine (see the module docstring): OMNICAL_HIL_CAMPAIGN=1",
)
def test_one_iteration_over_serial_recovers_the_truth(tmp_path: Path) -> None:
    _campaign_over_serial(tmp_path, CI_TIME_SCALE, "--max-iterations", "1", "--no-validate")


@pytest.mark.alone
@pytest.mark.skipif(
    not FULL, reason="~20 robot-minutes, 2+ wall minutes: OMNICAL_HIL_FULL_CAMPAIGN=1"
)
def test_full_campaign_over_serial_recovers_the_truth(tmp_path: Path) -> None:
    _campaign_over_serial(tmp_path, FULL_TIME_SCALE)
    assert any(
        p.name.startswith("validation-") for p in (tmp_path / "cal" / "recordings").iterdir()
    )


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--robot", "omni-x", "--model", "rosy-mecanum"], "already names the robot"),
        (["--robot", "twin", "--hedge", "serial:/dev/null"], "use --hedge twin"),
        (["--robot", "twin", "--area", "0,0,3,3"], "does not apply to the twin"),
        (["--robot", "serial:/dev/omnical-none", "--hedge", "twin", "--yes"], "--hedge serial"),
        (["--robot", "serial:/dev/omnical-none", "--hedge", "serial:/dev/x"], "add --yes"),
        (
            ["--robot", "serial:/dev/omnical-none", "--hedge", "serial:/dev/x", "--yes"],
            "cannot open the vehicle controller port",
        ),
    ],
)
def test_campaign_target_errors_are_one_line(tmp_path: Path, args: list[str], needle: str) -> None:
    done = subprocess.run(
        _omnical("calibrate", "campaign", *args, "--out", str(tmp_path / "cal")),
        capture_output=True, text=True, timeout=60, check=False, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert needle in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr


@pytest.mark.alone
def test_sigterm_stops_the_robot_and_keeps_the_runs(tmp_path: Path) -> None:
    """A SIGTERM once the first procedure is done (the campaign on to the next): exit 143, the
    robot stopped and standing, the finished run kept aside. On a x4 clock: the first procedure
    (63 s of robot time) in 16 s, its stand-stills 0.25 s of wall time."""
    from omnical.twin.device import DeviceConfig, TwinDeviceServer
    from omnical.twin.params import load_twin

    k = 4.0
    config = DeviceConfig(time_scale=k)
    with TwinDeviceServer(ROBOT, load_twin("default", ROBOT), config=config) as server:
        proc = subprocess.Popen(
            _omnical(
                "calibrate", "campaign", "--robot", f"serial:{server.vehicle_path}",
                "--hedge", f"serial:{server.hedge_path}", "--yes", "--no-figures",
                "--time-scale", f"{k:g}", "--out", str(tmp_path / "cal"),
            ),
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        assert proc.stdout is not None
        deadline = time.monotonic() + 90
        seen = []
        for line in proc.stdout:  # the first run done: the campaign goes on to the next
            seen.append(line)
            if "iter1-rotation: hedgehog at rest" in line or time.monotonic() > deadline:
                break
        assert "iter1-rotation: hedgehog at rest" in seen[-1], "".join(seen)
        # signalled once the robot moves again: driving home (or the second run). (Signalled
        # at once, the stop can fall between that line and the run joining the kept ones:
        # SerialBench.run says the line before it adds the run to its recordings, and the
        # campaign then ends "terminated" with nothing kept.)
        moving = _wait(lambda: server.last_command not in (None, (0.0, 0.0, 0.0)), 30.0)
        assert moving, "the robot did not move after the first run"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
        assert proc.returncode == 143, err
        assert server.last_command == (0.0, 0.0, 0.0)
        time.sleep(0.5)
        x, y, _ = server.twin.ground_truth_pose
        time.sleep(0.5)
        assert np.hypot(*np.subtract(server.twin.ground_truth_pose[:2], (x, y))) < 1e-3
    assert "robot stopped; kept" in err
    assert not (tmp_path / "cal").exists()  # the runs are kept aside: no campaign under OUT
    kept = read_bag(tmp_path / "cal.partial" / "recordings" / "iter1-rotation.mcap")
    assert kept.has("/cmd_vel") and kept.has("/beacon_raw_distance")
