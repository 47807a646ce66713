"""The compiled twin (numba) against the Python reference: the same logs, bit for bit."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from omnical.errors import ConfigError
from omnical.kinematics.correction import CorrectionFactors
from omnical.robot.description import RobotDescription
from omnical.robot.loader import load_robot
from omnical.twin.noise import NoiseChannel, NoiseStream
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.session import simulate_run
from omnical.twin.simulator import DigitalTwin, TwinLog

ROBOTS = {name: load_robot(name) for name in ("rosy-mecanum", "omni-x")}
INSTALLED = CorrectionFactors(1.012, 1.07, 0.985, 0.004, -0.003, 0.02, -0.015)
# (twist, seconds): reversals (backlash, Coulomb friction at rest), saturation, a stop
COMMANDS = (
    ((0.25, 0.1, 0.4), 9.0),
    ((-0.3, 0.25, -0.8), 7.0),
    ((0.0, 0.0, 0.0), 3.0),
    ((5.0, -5.0, 9.0), 8.0),  # beyond the limits: clamped at the port
    ((0.05, -0.02, 0.0), 6.0),
    ((-0.2, -0.3, 1.2), 12.0),
)  # 45 s: past a noise block (4096 steps) and a log's first allocation (4096 rows)
FIELDS = ("odom", "ground_truth", "imu", "dead_wheel_counts", "magnetometer")


def _params(robot: RobotDescription, kind: str) -> TwinParams:
    base = default_twin(robot) if kind == "default" else TwinParams.ideal_twin()
    return base.with_installed(INSTALLED)


def _drive(twin: DigitalTwin, rate_hz: float = 50.0) -> list[object]:
    """Commands changing mid-run, read back at every tick like a controller would."""
    states: list[object] = []
    for twist, seconds in COMMANDS:
        twin.send_twist(*twist)
        for _ in range(round(seconds * rate_hz)):
            twin.advance_to(twin.t_s + 1.0 / rate_hz)
            states.append(twin.read_state())
            states.append(twin.ground_truth_pose)
    return states


def _assert_same_log(a: TwinLog, b: TwinLog) -> None:
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape, name
        np.testing.assert_array_equal(x, y, err_msg=name)


@pytest.mark.parametrize("kind", ["default", "ideal"])
@pytest.mark.parametrize("robot_name", sorted(ROBOTS))
def test_compiled_twin_is_bit_identical_to_the_python_reference(robot_name: str, kind: str) -> None:
    robot = ROBOTS[robot_name]
    params = _params(robot, kind)
    runs = {}
    for engine in ("python", "compiled"):
        twin = DigitalTwin(robot, params, seed=9, engine=engine)  # type: ignore[arg-type]
        assert twin.engine == engine
        states = _drive(twin)
        runs[engine] = (twin.log(), states)
    (log_py, states_py), (log_c, states_c) = runs["python"], runs["compiled"]
    _assert_same_log(log_py, log_c)
    assert states_py == states_c
    assert log_c.imu.shape[0] > 4096
    if robot.dead_wheels:
        assert log_c.magnetometer.shape[0] == log_c.imu.shape[0]
        assert np.abs(log_c.dead_wheel_cumulative_counts).max() > 0


def test_play_runs_a_command_block_like_send_and_advance() -> None:
    robot = ROBOTS["omni-x"]
    params = replace(_params(robot, "default"), step_hz=400.0, odom_rate_hz=40.0)
    t = np.arange(1, 1501) * 0.02
    twists = np.column_stack([0.3 * np.sin(t), 0.2 * np.cos(0.7 * t), 0.5 * np.sin(0.3 * t)])
    reference = DigitalTwin(robot, params, seed=4, engine="python")
    for twist, wake in zip(twists, t, strict=True):
        reference.send_twist(*twist)
        reference.advance_to(wake)
    for engine in ("python", "compiled"):
        twin = DigitalTwin(robot, params, seed=4, engine=engine)  # type: ignore[arg-type]
        for a in range(0, len(t), 333):  # blocks of odd sizes
            twin.play(twists[a : a + 333], t[a : a + 333])
        assert twin.t_s == reference.t_s
        assert twin.read_state() == reference.read_state()
        _assert_same_log(twin.log(), reference.log())


def test_simulate_run_is_the_same_on_both_engines() -> None:
    from omnical.experiment.script import load_script

    robot = ROBOTS["rosy-mecanum"]
    script = load_script("straight-10m", robot.limits)
    recordings = [
        simulate_run(script, robot, replace(default_twin(robot), engine=engine), seed=3)
        for engine in ("python", "compiled")
    ]
    a, b = recordings
    assert a.tables.keys() == b.tables.keys()
    for topic, table in a.tables.items():
        other = b.tables[topic]
        np.testing.assert_array_equal(table.t_ns, other.t_ns, err_msg=topic)
        for name in table.names:
            assert np.array_equal(table[name], other[name]), f"{topic}.{name}"


def test_engine_choice() -> None:
    robot = ROBOTS["rosy-mecanum"]
    assert DigitalTwin(robot, TwinParams.ideal_twin()).engine == "compiled"
    python = replace(TwinParams.ideal_twin(), engine="python")
    assert DigitalTwin(robot, python).engine == "python"
    assert DigitalTwin(robot, python, engine="compiled").engine == "compiled"
    with pytest.raises(ConfigError, match="unknown twin engine"):
        DigitalTwin(robot, TwinParams.ideal_twin(), engine="fast")  # type: ignore[arg-type]


@pytest.mark.parametrize(("seconds", "engine"), [(7.9, "python"), (8.1, "compiled")])
def test_a_short_run_takes_the_python_reference(
    seconds: float, engine: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Under "auto", a run under SHORT_RUN_S (lead-in and tail included) is not worth loading
    numba's kernels for; both engines give the same logs."""
    from omnical.experiment.script import TwistSequence
    from omnical.twin import rig, session

    engines: list[str] = []
    twin = rig.DigitalTwin

    def made(*args: object, **kw: object) -> DigitalTwin:
        made_twin = twin(*args, **kw)  # type: ignore[arg-type]
        engines.append(made_twin.engine)
        return made_twin

    monkeypatch.setattr(rig, "DigitalTwin", made)
    robot = ROBOTS["rosy-mecanum"]
    # a script of ``seconds``: 10 s with the 1 s lead-in and tail is the threshold
    script = TwistSequence.from_arrays("short", [0.0, seconds - 0.02], [[0.1, 0, 0], [0, 0, 0]])
    assert script.duration_s == pytest.approx(seconds) and session.SHORT_RUN_S == 10.0
    simulate_run(script, robot, default_twin(robot), seed=1)
    assert engines == [engine]


@pytest.mark.parametrize("engine", ["python", "compiled"])
def test_numpy_scalars_stop_at_the_port(engine: str) -> None:
    twin = DigitalTwin(ROBOTS["omni-x"], TwinParams.ideal_twin(), engine=engine)  # type: ignore[arg-type]
    twin.send_twist(np.float64(0.2), np.float32(0.1), np.int64(0))
    twin.advance_to(np.float64(1.0))
    state = twin.read_state()
    values = [state.t_s, state.gyro_z_radps, *state.odom_pose, *state.odom_twist]
    values += [*state.wheel_speeds_radps, *twin.ground_truth_pose]
    assert all(type(v) is float for v in values)
    assert state.odom_pose[0] > 0.0


def test_noise_blocks_hand_out_the_same_numbers_as_next3() -> None:
    rows = NoiseStream(2, NoiseChannel.SLIP, block=5)
    triples = NoiseStream(2, NoiseChannel.SLIP, block=5)
    expected = [triples.next3() for _ in range(15)]  # three blocks
    first = rows.take_rows()  # a whole block
    got = [*first.tolist(), rows.next3(), rows.next3()]
    rest = rows.take_rows()  # the rest of the second block
    assert (len(first), len(rest)) == (5, 3)
    got += [*rest.tolist(), *rows.take_rows().tolist()]
    assert got == expected
