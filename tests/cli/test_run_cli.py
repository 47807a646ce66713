"""``omnical run`` against ``TwinDeviceServer`` on pseudo-terminals, vs the in-process twin."""

from __future__ import annotations

import math
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from serial_odometry import (
    arrival_drift,
    costliest_stall,
    end_in_start_frame,
    frames_at_their_period,
    frames_tolerance,
)

from omnical.bags.bag import read_bag
from omnical.experiment.script import load_script
from omnical.recording.recording import Recording
from omnical.robot.loader import load_robot
from omnical.services.hil import SCALED_STALL_S
from omnical.twin.device import DeviceConfig, TwinDeviceServer
from omnical.twin.params import load_twin
from omnical.twin.session import simulate_run
from omnical.twin.simulator import DigitalTwin

ROBOT = load_robot("rosy-mecanum")
SCRIPT = """\
name: short
steps:
  - hold: {duration_s: 0.5}
  - move: {vx_mps: 0.25, distance_m: 0.5, marker: forward}
  - hold: {duration_s: 0.5}
  - move: {vy_mps: 0.2, distance_m: 0.3, marker: left}
  - move: {wz_radps: 0.8, angle_deg: 90, marker: turn}
  - hold: {duration_s: 0.5}
"""


def _omnical(*args: str) -> list[str]:
    return [sys.executable, "-c", "from omnical.cli.main import main; main()", *args]


def _moves(rec: Recording) -> dict[str, tuple[np.ndarray, float]]:
    """:func:`_cruise` of the recording's ``/ground_truth``."""
    g = rec.topic("/ground_truth")
    t = np.asarray(g.t_ns, dtype=np.int64) / 1e9
    return _cruise(t, np.column_stack([g["vx_mps"], g["vy_mps"], g["wz_radps"]]))


def _replayed(commands: np.ndarray, start_s: float) -> dict[str, tuple[np.ndarray, float]]:
    """:func:`_cruise` of the in-process twin (seed 0) given ``commands``, (device time, vx,
    vy, wz) rows, at their times since ``start_s`` (the served twin's time 0): the served
    twin's own truth, bit for bit (measured: 0 difference in 5 runs)."""
    twin = DigitalTwin(ROBOT, load_twin("default", ROBOT), seed=0, engine="python")  # the server's
    for t, vx, vy, wz in commands:
        twin.advance_to(t - start_s)
        twin.send_twist(vx, vy, wz)
    twin.advance_to(commands[-1, 0] - start_s + 1.0)
    log = twin.log()
    return _cruise(np.asarray(log.ground_truth_t_s), np.asarray(log.ground_truth_twist))


def _commanded_angle_rad(t_s: np.ndarray, wz_radps: np.ndarray) -> float:
    """The integral of piecewise-constant yaw-rate commands, each held until the next."""
    return float(np.sum(wz_radps[:-1] * np.diff(t_s)))


def _cruise(t: np.ndarray, twist: np.ndarray) -> dict[str, tuple[np.ndarray, float]]:
    """Per move of SCRIPT (by the axis it drives): the body twist while cruising (the median
    over the middle half of the samples above 90 % of the axis' peak) and the time the axis
    spent above half of it (the move's duration as the device executed it), s."""
    dt = float(np.median(np.diff(t)))
    out = {}
    for axis, name in enumerate(("forward", "left", "turn")):
        v = twist[:, axis]
        cruising = np.flatnonzero(v > 0.9 * v.max())
        quarter = len(cruising) // 4
        plateau = np.median(twist[cruising[quarter : len(cruising) - quarter]], axis=0)
        out[name] = (plateau, float(np.count_nonzero(v > 0.5 * plateau[axis])) * dt)
    return out


@pytest.mark.alone  # wall clock: a stall of the served device is a silence the watchdog stops
def test_serial_run_matches_the_in_process_twin(tmp_path: Path) -> None:
    """``omnical run SCRIPT`` over serial does on the device what the in-process twin does.

    Compared where load cannot reach: the topics recorded; the commands on the wire (their
    axes, signs and units: each axis' peak is the script's); the twin's response to them (each
    move's true body twist while cruising, as the in-process twin's given the same commands at
    the times the served one took them: the lateral move is too short to settle, and its
    cruise follows the command ramp's 20-Hz steps and their timing, 1.3 mm/s below the
    in-process run of the script); the status frames the host received, at the firmware's period,
    against the device's odometry (tests/cli/serial_odometry.py). A stall of either process
    only moves a command's edge in time, and so lengthens or shortens a move (by at most the
    clock's silence limit, else the run stops): the end pose is compared with the tolerance
    those measured durations give (1 cm and 1° besides, as sampled at the truth's 50 Hz; and
    the angle the costliest stall could take from the turn, which 50 Hz sampling misses). On a
    x2 clock: its limits are SCALED_STALL_S of wall time.
    """
    k = 2.0
    script = tmp_path / "short.yaml"
    script.write_text(SCRIPT)
    params = load_twin("default", ROBOT)
    config = DeviceConfig(time_scale=k)
    with TwinDeviceServer(ROBOT, params, seed=0, config=config) as server:
        done = subprocess.run(
            _omnical(
                "run", str(script), "--robot", f"serial:{server.vehicle_path}",
                "--hedge", f"serial:{server.hedge_path}", "--beacons", "default", "--yes",
                "--time-scale", f"{k:g}", "--out", str(tmp_path / "run.mcap"),
            ),
            capture_output=True, text=True, timeout=60, check=False,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        truth = server.recording()
        commands = np.array(server.command_history())
        history = np.array(server.truth_history())
        start_s = server.t0_mono  # the twin's time 0 on the device's clock
        stall_s, stall_m, stall_rad = costliest_stall(commands)
    run = read_bag(tmp_path / "run.mcap")
    twin = simulate_run(load_script(str(script), ROBOT.limits), ROBOT, params, seed=0)
    # the same topics, except the truth, which only a twin has (the server records it)
    assert set(twin.tables) - set(run.tables) == {"/ground_truth"}
    assert set(run.tables) <= set(twin.tables)

    np.testing.assert_allclose(commands[:, 1:].max(axis=0), (0.25, 0.2, 0.8), atol=1e-3)
    assert commands[:, 1:].min() >= -1e-3  # no axis driven backwards
    serial, inproc, replayed = _moves(truth), _moves(twin), _replayed(commands, start_s)
    slack = {}
    for name, (plateau, duration) in inproc.items():
        got, got_duration = serial[name]
        np.testing.assert_allclose(got, replayed[name][0], atol=1e-6, err_msg=name)
        # and near the script's run: the moves that settle within 1 mm/s, the lateral one
        # within 3 mm/s (its 20-Hz ramp: 1.3 mm/s below)
        np.testing.assert_allclose(
            got[:2], plateau[:2], atol=3e-3 if name == "left" else 1e-3, err_msg=name
        )
        assert abs(got[2] - plateau[2]) < 0.01, (name, got, plateau)
        # a move's edges moved by a stall: never by more than the silence limit on this clock
        assert abs(got_duration - duration) <= k * (SCALED_STALL_S + 0.05), (name, got_duration)
        slack[name] = abs(got_duration - duration)
    # the status frames the host received, at the firmware's period, are the device's odometry
    # (what their arrival times added to the host's own is printed: the run is open loop)
    frames, device = frames_at_their_period(run)[-1], end_in_start_frame(truth, "/odom")
    frames_off = float(np.hypot(*(frames[:2] - device[:2])))
    tol_m, tol_rad = frames_tolerance(history)
    assert frames_off < tol_m and abs(frames[2] - device[2]) < tol_rad, (frames, device)
    # the end, within what the measured durations explain (forward along x, left along y of the
    # start frame; the turn in place only turns)
    end = end_in_start_frame(truth, "/ground_truth")
    ref = end_in_start_frame(twin, "/ground_truth")
    tol_m = 0.01 + 0.25 * slack["forward"] + 0.2 * slack["left"]
    # the turn: the host sends its ramps in 20-Hz steps, at times a loaded machine moves, and
    # the angle turned follows the integral of the commanded rate (the plant's gain is the
    # twin's rotational scaling, ≈ 1): the difference of the two integrals, besides the
    # durations (1.10° against 1.01° seen, with every move's duration the script's)
    cmd = twin.topic("/cmd_vel")
    script_turn_rad = _commanded_angle_rad(np.asarray(cmd.t_ns) / 1e9, np.asarray(cmd["wz_radps"]))
    served_turn_rad = _commanded_angle_rad(commands[:, 0], commands[:, 3])
    ramp_rad = 1.1 * abs(served_turn_rad - script_turn_rad)
    tol_rad = math.radians(1.0) + 0.8 * slack["turn"] + stall_rad + ramp_rad  # a turn started late
    off = float(np.hypot(*(end[:2] - ref[:2])))
    print(
        f"serial vs in-process: end {off * 1e3:.1f} mm (tolerance {tol_m * 1e3:.1f}), heading "
        f"{math.degrees(end[2] - ref[2]):+.2f}° (tolerance {math.degrees(tol_rad):.2f}); moves "
        + ", ".join(f"{n} {serial[n][1] - inproc[n][1]:+.3f} s" for n in inproc)
        + f"; the frames vs the device's odometry {frames_off * 1e3:.1f} mm, arrival drift "
        + f"{arrival_drift(run)[1] * 1e3:.1f} mm; the costliest stall {stall_m * 1e3:.1f} mm "
        + f"({stall_s * 1e3:.0f} ms beyond the usual gap between the commands the twin took; "
        + f"{math.degrees(stall_rad):.2f}° of turn); commanded turn "
        + f"{math.degrees(served_turn_rad - script_turn_rad):+.2f}° vs the script's"
    )
    assert off <= tol_m and abs(end[2] - ref[2]) <= tol_rad
    assert np.hypot(*ref[:2]) > 0.5  # it did move


@pytest.mark.alone
def test_sigint_sends_zero_and_keeps_the_bag(tmp_path: Path) -> None:
    """On a x2 clock (its limits SCALED_STALL_S, 1 s, of wall time: a loaded machine's stall does not end the
    run before the signal does)."""
    k = 2.0
    script = tmp_path / "long.yaml"
    script.write_text("name: long\nsteps:\n  - move: {vx_mps: 0.2, duration_s: 20.0}\n")
    config = DeviceConfig(time_scale=k)
    with TwinDeviceServer(ROBOT, load_twin("ideal", ROBOT), config=config) as server:
        proc = subprocess.Popen(
            _omnical(
                "run", str(script), "--robot", f"serial:{server.vehicle_path}",
                "--hedge", f"serial:{server.hedge_path}", "--beacons", "default", "--yes",
                "--margin", "-100", "--time-scale", f"{k:g}", "--out", str(tmp_path / "run.mcap"),
            ),
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        deadline = time.monotonic() + 20
        while server.last_command != (0.2, 0.0, 0.0) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert server.last_command == (0.2, 0.0, 0.0), "the run never started"
        time.sleep(0.25)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
        assert proc.returncode == 130, err
        assert server.last_command == (0.0, 0.0, 0.0)
    assert "kept the partial run" in err and "Traceback" not in err
    partial = read_bag(tmp_path / "run.partial")
    assert partial.has("/cmd_vel") and partial.has("/odom")
    cmd = partial.topic("/cmd_vel")
    assert np.asarray(cmd["vx_mps"])[-1] == 0.0 and np.any(np.asarray(cmd["vx_mps"]) == 0.2)
    assert not (tmp_path / "run").exists()


def test_refuses_a_path_outside_the_beacons(tmp_path: Path) -> None:
    script = tmp_path / "far.yaml"
    script.write_text("name: far\nsteps:\n  - move: {vx_mps: 0.5, distance_m: 8.0}\n")
    with TwinDeviceServer(ROBOT, load_twin("ideal", ROBOT)) as server:
        done = subprocess.run(
            _omnical(
                "run", str(script), "--robot", f"serial:{server.vehicle_path}",
                "--hedge", f"serial:{server.hedge_path}", "--beacons", "default", "--yes",
                "--out", str(tmp_path / "run.mcap"),
            ),
            capture_output=True, text=True, timeout=60, check=False,
        )  # fmt: skip
        assert server.last_command in (None, (0.0, 0.0, 0.0))
    assert done.returncode == 2
    assert "refused" in done.stderr and "beacon coverage" in done.stderr


def test_seed003_task_on_rosy_closes_on_its_odometry(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from omnical.cli.main import app

    out = tmp_path / "square.mcap"
    result = CliRunner().invoke(
        app, ["run", "seed003-square", "--model", "rosy-mecanum", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert "closed on its wheel odometry" in result.output
    rows = {}
    for line in result.output.splitlines():
        m = re.match(
            r"max \|(\w) error\|, cm: odometry ([\d.]+), ground truth ([\d.]+), paper (\S+)", line
        )
        if m:
            rows[m[1]] = (float(m[2]), float(m[3]), m[4])
    assert set(rows) == {"x", "y"}, result.output
    assert rows["x"][2] == "10.4" and rows["y"][2] == "12.24"
    # the loop holds its odometry on the path (1 cm goal tolerance at the corners); the
    # uncalibrated Mecanum twin's lateral scale error (Table 2) shows only in the truth
    assert rows["x"][0] < 1.5 and rows["y"][0] < 1.5
    assert rows["y"][1] > 5.0
    bag = read_bag(out)
    assert bag.has("/cmd_vel") and bag.has("/odom") and bag.has("/ground_truth")
    gt = bag.topic("/ground_truth")
    x, y = np.asarray(gt["x_m"]), np.asarray(gt["y_m"])
    assert np.ptp(x) > 1.0 and np.ptp(y) > 1.0  # it drove the square


def test_unknown_names_listed(tmp_path: Path) -> None:
    # (controller tasks over serial: tests/cli/test_run_serial_tasks.py)
    from typer.testing import CliRunner

    from omnical.cli.main import app

    runner = CliRunner()
    out = tmp_path / "run.mcap"
    result = runner.invoke(app, ["run", "seed003-circle", "--out", str(out)])
    assert result.exit_code == 2
    assert "seed003-square" in result.output and "tour" in result.output


@pytest.mark.parametrize(("signal_name", "status"), [("SIGINT", 130), ("SIGTERM", 143)])
def test_seed003_task_interrupted_keeps_the_partial_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, signal_name: str, status: int
) -> None:
    from typer.testing import CliRunner

    import omnical.control.centred as centred
    from omnical.cli.errors import Terminated
    from omnical.cli.main import app

    stop = KeyboardInterrupt if signal_name == "SIGINT" else Terminated  # what each handler raises

    real_step = centred.centred_step
    calls = []

    def step_then_ctrl_c(*args: object, **kwargs: object) -> object:
        calls.append(1)
        if len(calls) > 100:  # 5 s into the loop at 20 Hz
            raise stop
        return real_step(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(centred, "centred_step", step_then_ctrl_c)
    out = tmp_path / "square.mcap"
    result = CliRunner().invoke(
        app, ["run", "seed003-square", "--model", "omni-x", "--out", str(out)]
    )
    assert result.exit_code == status, result.output
    assert "kept the partial run" in result.output
    assert not out.with_suffix("").exists()
    partial = read_bag(tmp_path / "square.partial")
    cmd = partial.topic("/cmd_vel")
    assert 4.9 < (int(cmd.t_ns[-1]) - int(cmd.t_ns[0])) / 1e9 < 5.2
    assert np.all(np.asarray(cmd["vx_mps"])[-1:] == 0.0)  # the loop stopped the robot


def test_robot_names_the_twin_as_in_the_other_commands(tmp_path: Path) -> None:
    """``--robot PRESET`` is that robot's in-process twin (as in simulate and calibrate);
    ``--model`` then contradicts it."""
    from typer.testing import CliRunner

    from omnical.cli.main import app

    out = tmp_path / "x.mcap"
    both = ["run", "tour", "--robot", "omni-x", "--model", "rosy-mecanum", "--out", str(out)]
    result = CliRunner().invoke(app, both)
    assert result.exit_code == 2
    assert "--robot omni-x already names the robot description" in result.output
    result = CliRunner().invoke(app, ["run", "tour", "--robot", "omni-y", "--out", str(out)])
    assert result.exit_code == 2 and "omni-y" in result.output
    assert not out.with_suffix("").exists()
