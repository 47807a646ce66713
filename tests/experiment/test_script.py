"""Motion scripts: validation, profiles that integrate to the asked distance, limits refused."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from omnical.errors import ConfigError, LimitError
from omnical.experiment.runner import run_script
from omnical.experiment.script import load_script, parse_script
from omnical.robot.loader import load_robot
from omnical.twin.clock import TwinClock
from omnical.twin.params import TwinParams
from omnical.twin.simulator import DigitalTwin

LIMITS = load_robot("rosy-mecanum").limits


def _integral(script_data: dict[str, object], axis: int) -> float:
    script = parse_script(script_data, LIMITS)
    t = np.linspace(0.0, script.duration_s, 200_001)
    v = np.array([script.twist_at(x)[axis] for x in t])
    return float(np.trapezoid(v, t))


@pytest.mark.parametrize("distance", [0.05, 1.0, 10.0])
def test_move_integrates_to_distance(distance: float) -> None:
    got = _integral({"steps": [{"move": {"vx_mps": 0.3, "distance_m": distance}}]}, 0)
    assert got == pytest.approx(distance, rel=1e-3)


def test_move_integrates_to_angle_and_duration() -> None:
    assert _integral(
        {"steps": [{"move": {"wz_radps": 0.8, "angle_deg": 1080}}]}, 2
    ) == pytest.approx(6 * math.pi, rel=1e-3)
    script = parse_script({"steps": [{"move": {"vy_mps": 0.2, "duration_s": 5.0}}]}, LIMITS)
    assert script.duration_s == pytest.approx(5.0)


def test_ramps_respect_acceleration_limits() -> None:
    script = parse_script(
        {"steps": [{"move": {"vx_mps": 0.5, "vy_mps": 0.2, "distance_m": 3}}]}, LIMITS
    )
    t = np.arange(0.0, script.duration_s, 0.001)
    v = np.array([script.twist_at(x) for x in t])
    acc = np.abs(np.diff(v, axis=0)) / 0.001
    assert acc[:, 0].max() <= LIMITS.max_ax_mps2 * 1.001
    assert acc[:, 1].max() <= LIMITS.max_ay_mps2 * 1.001


def test_step_beyond_limits_is_refused() -> None:
    with pytest.raises(
        LimitError, match=r"step 2 \(move\): vx_mps = 3.0 exceeds the robot's limit 0.8"
    ):
        parse_script(
            {"steps": [{"hold": {"duration_s": 1}}, {"move": {"vx_mps": 3.0, "duration_s": 5}}]},
            LIMITS,
        )


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"steps": []}, "steps"),
        ({"steps": [{"move": {"vx_mps": 0.1}}]}, "exactly one of duration_s"),
        ({"steps": [{"move": {"vx_mps": 0.1, "duration_s": 1, "distance_m": 1}}]}, "exactly one"),
        (
            {"steps": [{"hold": {"duration_s": 1}, "move": {"vx_mps": 0.1, "duration_s": 1}}]},
            "exactly one of 'hold'",
        ),
        ({"steps": [{"jump": {}}]}, "jump"),
        (
            {"steps": [{"move": {"wz_radps": 0.5, "distance_m": 1}}]},
            "distance_m needs a translation",
        ),
        ([1, 2], "must be a mapping"),
    ],
)
def test_invalid_scripts(data: object, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_script(data, LIMITS, "s.yaml")


@pytest.mark.parametrize(
    ("data", "where"),
    [
        ({"rate_hz": True, "steps": [{"hold": {"duration_s": 1}}]}, "rate_hz"),
        ({"steps": [{"move": {"wz_radps": True, "duration_s": 2}}]}, "steps.0.move.wz_radps"),
        ({"steps": [{"move": {"wz_radps": 0.5, "duration_s": True}}]}, "steps.0.move.duration_s"),
        ({"steps": [{"move": {"vx_mps": True, "distance_m": 1}}]}, "steps.0.move.vx_mps"),
        (
            {"steps": [{"move": {"vx_mps": 0.1, "distance_m": 1, "accel_scale": True}}]},
            "steps.0.move.accel_scale",
        ),
        ({"steps": [{"hold": {"duration_s": False}}]}, "steps.0.hold.duration_s"),
    ],
)
def test_a_boolean_is_not_a_number(data: object, where: str) -> None:
    """``rate_hz: true`` ran at 1 Hz and ``wz_radps: true`` read 1 rad/s: refused as in robot files."""
    with pytest.raises(ConfigError) as err:
        parse_script(data, LIMITS, "s.yaml")
    assert str(err.value) == f"s.yaml: field '{where}': expected a number, got a boolean"


def test_file_errors(tmp_path: Path) -> None:
    p = tmp_path / "s.yaml"
    p.write_text("steps: [\n")
    with pytest.raises(ConfigError, match=r"s\.yaml: invalid YAML at line"):
        load_script(p, LIMITS)


def test_runner_logs_commands_and_markers() -> None:
    robot = load_robot("rosy-mecanum")
    twin = DigitalTwin(robot, TwinParams.ideal_twin(), seed=0)
    script = load_script("straight-10m", robot.limits)
    log = run_script(script, twin, TwinClock(twin))
    assert not log.interrupted
    dt = np.diff(log.cmd_vel[:-1, 0])
    assert dt.mean() == pytest.approx(1 / script.rate_hz)
    assert float(np.trapezoid(log.cmd_vel[:, 1], log.cmd_vel[:, 0])) == pytest.approx(
        10.0, rel=2e-3
    )
    events = [json.loads(text) for _, text in log.events]
    assert [(e["step"], e["edge"]) for e in events] == [
        (1, "start"),
        (1, "end"),
        (2, "start"),
        (2, "end"),
        (3, "start"),
        (3, "end"),
    ]
    assert events[2]["marker"] == "forward"
    assert twin.read_state().odom_pose[0] == pytest.approx(10.0, abs=0.01)


def test_feedforward_lissajous_plays_through_the_runner() -> None:
    from omnical.experiment.script import TwistSequence
    from omnical.trajectory.references import lissajous
    from omnical.trajectory.scripts import feedforward_commands

    robot = load_robot("rosy-mecanum")
    ref = lissajous()
    t, twists = feedforward_commands(ref, 50.0, limits=robot.limits)
    seq = TwistSequence.from_arrays("lissajous", t, twists, rate_hz=50.0)
    twin = DigitalTwin(robot, TwinParams.ideal_twin(start_pose_map=(0.0, 0.0, 0.0)), seed=0)
    log = run_script(seq, twin, TwinClock(twin))
    assert log.cmd_vel.shape[0] >= len(t)
    twin.advance_to(twin.t_s + 2.0)
    # the ideal twin follows the feed-forward path back to where the reference ends
    end = ref.poses[-1] - ref.poses[0]
    odom = twin.read_state().odom_pose
    assert math.hypot(odom[0] - end[0], odom[1] - end[1]) < 0.02
