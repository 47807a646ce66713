"""User files at the boundary: hostile bytes, YAML and values end in one ConfigError, or load."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from omnical.errors import ConfigError, LimitError
from omnical.ips.beacons import load_beacon_map
from omnical.robot.loader import load_robot
from omnical.userfiles import (
    MAX_NESTING,
    MAX_YAML_NODES,
    parse_yaml,
    read_file_bytes,
    read_text_file,
    read_yaml,
)

ROSY = Path(__file__).parents[1] / "src" / "omnical" / "data" / "robots" / "rosy-mecanum.yaml"

FUZZ = settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def _write(tmp_path: Path, data: bytes, name: str = "f.yaml") -> Path:
    path = tmp_path / name
    path.write_bytes(data)
    return path


def test_what_a_file_may_not_be(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nowhere.yaml: cannot read"):
        read_yaml(tmp_path / "nowhere.yaml")
    with pytest.raises(ConfigError, match="is a directory, expected a robot file"):
        read_yaml(tmp_path, "robot file")
    with pytest.raises(ConfigError, match="not a text file"):
        read_yaml(_write(tmp_path, b"name: x\x00\x01"))
    with pytest.raises(ConfigError, match=r"not UTF-8 text \(byte 6\)"):
        read_text_file(_write(tmp_path, b"name: \xff\xfe"))
    with pytest.raises(ConfigError, match="invalid YAML at line 2, column 1"):
        read_yaml(_write(tmp_path, b"a: [1,\n"))
    deep = "".join("  " * i + "k:\n" for i in range(MAX_NESTING + 5))
    with pytest.raises(ConfigError, match=f"nested deeper than {MAX_NESTING} levels"):
        read_yaml(_write(tmp_path, deep.encode()))
    flow = "[" * 5000 + "]" * 5000
    with pytest.raises(ConfigError, match="nested"):
        read_yaml(_write(tmp_path, flow.encode()))
    assert read_yaml(_write(tmp_path, b"a: {b: [1, 2]}")) == {"a": {"b": [1, 2]}}


@FUZZ
@given(data=st.binary(max_size=400))
def test_any_bytes_load_or_give_one_config_error(tmp_path: Path, data: bytes) -> None:
    path = _write(tmp_path, data)
    for loader in (read_yaml, load_robot, load_beacon_map):
        try:
            loader(path)
        except ConfigError as err:
            assert str(err).startswith(str(path)), err
            assert "\n" not in str(err)


_SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e-300, 1e308, -1e308, 0.0, -0.0]),
    st.text(max_size=12),
)


def _hostile(value: object) -> st.SearchStrategy[object]:
    return st.one_of(_SCALARS, st.just(value), st.lists(_SCALARS, max_size=3))


@FUZZ
@given(data=st.data())
def test_hostile_values_in_a_robot_file_load_or_give_one_config_error(
    tmp_path: Path, data: st.DataObject
) -> None:
    robot = yaml.safe_load(ROSY.read_text(encoding="utf-8"))
    section = data.draw(st.sampled_from(["limits", "drive_train", "imu", "wheel", "top"]))
    if section == "wheel":
        target = robot["wheels"][0]
    elif section == "top":
        target = robot
    else:
        target = robot.setdefault(section, {})
    key = data.draw(st.sampled_from(sorted(target) or ["name"]))
    target[key] = data.draw(_hostile(target.get(key)))
    path = _write(tmp_path, yaml.safe_dump(robot).encode())
    try:
        loaded = load_robot(path)
    except ConfigError as err:
        assert str(err).startswith(str(path)) and "\n" not in str(err)
        return
    for wheel in loaded.wheels:  # what loads is physical
        assert 0.0 < wheel.radius_m <= 1.0
    limits = loaded.limits
    for value in (limits.max_vx_mps, limits.max_ax_mps2, loaded.drive_train.gear_ratio):
        assert 0.0 < value < 1e5


_TWIN_KEYS = [
    "slip_sigma",
    "slip_correlation_s",
    "backlash_deg",
    "step_hz",
    "odom_rate_hz",
    "ground_truth_rate_hz",
    "start_pose_map",
    "gyro_bias_radps",
    "hedge_offset_m",
    "wheel_radius_errors",
    "motor_gain_errors",
    "motor_time_constant_error",
    "coulomb_friction_radps",
    "viscous_droop",
    "ips.nlos_probability",
    "ips.distance_noise_m",
    "ips.latency_s",
    "ips.rate_max_hz",
    "true_factors.scale.lateral",
    "installed_factors.crosstalk_rad_per_m.left",
]


@FUZZ
@given(key=st.sampled_from(_TWIN_KEYS), value=_hostile(None))
def test_hostile_values_in_a_twin_file_load_or_give_one_config_error(
    tmp_path: Path, key: str, value: object
) -> None:
    from omnical.twin.params import load_twin

    document: dict[str, object] = {"base": "default"}
    *parents, leaf = key.split(".")
    node = document
    for part in parents:
        node = node.setdefault(part, {})  # type: ignore[assignment]
    node[leaf] = value
    path = _write(tmp_path, yaml.safe_dump(document).encode(), "twin.yaml")
    try:
        load_twin(path, load_robot("rosy-mecanum"))
    except ConfigError as err:
        assert "\n" not in str(err)


@FUZZ
@given(
    field=st.sampled_from(["vx_mps", "wz_radps", "duration_s", "distance_m", "accel_scale"]),
    value=_SCALARS,
    rate=st.one_of(st.just(50.0), _SCALARS),
)
def test_hostile_values_in_a_script_load_or_give_one_config_error(
    tmp_path: Path, field: str, value: object, rate: object
) -> None:
    from omnical.experiment.script import MAX_SCRIPT_DURATION_S, load_script

    move: dict[str, object] = {"vx_mps": 0.2, "duration_s": 2.0}
    if field in ("distance_m",):
        move.pop("duration_s")
    move[field] = value
    path = _write(tmp_path, yaml.safe_dump({"rate_hz": rate, "steps": [{"move": move}]}).encode())
    try:
        script = load_script(path, load_robot("rosy-mecanum").limits)
    except (ConfigError, LimitError) as err:  # a bad value, or one beyond the robot's limits
        assert str(err).startswith(str(path)) and "\n" not in str(err)
        return
    assert 0.0 < script.duration_s <= MAX_SCRIPT_DURATION_S  # what loads stays bounded
    assert 1.0 <= script.rate_hz <= 1000.0


BOMB = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n' + "".join(
    f"{c}: &{c} [{','.join(['*' + p] * 9)}]\n" for p, c in zip("abcdefgh", "bcdefghi", strict=True)
)
"""Billion laughs: 342 bytes, nine levels of nine aliases (9⁹ "lol" once expanded)."""


def _refused(path: Path) -> str:
    return (
        f"{path}: YAML alias *a at line 2, column 8: aliases are not accepted "
        "(they can expand without bound); write the value out"
    )


def _returns_within(seconds: float, read: Callable[[], object]) -> BaseException | None:
    """What ``read`` raised (None if it returned), failing the test if it is still running
    after ``seconds`` (a generous guard against the hang; the thread is a daemon)."""
    outcome: list[BaseException | None] = []

    def run() -> None:
        try:
            read()
            outcome.append(None)
        except BaseException as err:  # handed to the test
            outcome.append(err)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(seconds)
    assert outcome, f"still reading after {seconds} s: the alias bomb hangs"
    return outcome[0]


def _readers() -> dict[str, Callable[[Path], object]]:
    from omnical.calibration.factors_io import read_factors
    from omnical.experiment.script import load_script
    from omnical.navigation.map_io import load_map
    from omnical.twin.params import load_twin
    from omnical.twin.world import load_world

    rosy = load_robot("rosy-mecanum")
    return {
        "read_yaml": read_yaml,
        "robot": load_robot,
        "script": lambda p: load_script(p, rosy.limits),
        "twin": lambda p: load_twin(p, rosy),
        "beacons": load_beacon_map,
        "factors": read_factors,
        "map": load_map,
        "world": load_world,
    }


@pytest.mark.parametrize("reader", sorted(_readers()))
def test_an_alias_bomb_is_refused_at_once_by_every_reader(tmp_path: Path, reader: str) -> None:
    path = _write(tmp_path, BOMB.encode())
    err = _returns_within(30.0, lambda: _readers()[reader](path))
    assert isinstance(err, ConfigError), err
    assert str(err) == _refused(path)


@pytest.mark.parametrize("reader", sorted(_readers()))
def test_an_empty_file_is_one_line_saying_so_except_a_twin(tmp_path: Path, reader: str) -> None:
    """Found by a new user: an empty robot file said 'got NoneType', an empty beacon map
    '<top level>: Input should be a valid dictionary'. An empty twin file is the default twin
    (its overrides are all optional)."""
    path = _write(tmp_path, b"# nothing yet\n")
    if reader == "twin":
        assert _readers()[reader](path) is not None
        return
    with pytest.raises(ConfigError, match=r"^.*f\.yaml: empty \(no YAML in it\), expected a "):
        _readers()[reader](path)


def test_an_alias_anywhere_is_refused_and_anchors_alone_are_plain_data(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"YAML alias \*base at line 2, column 13"):
        read_yaml(_write(tmp_path, b"base: &base {x: 1}\nwheel: {<<: *base, y: 2}\n"))
    assert read_yaml(_write(tmp_path, b"a: &one 1\nb: 2\n")) == {"a": 1, "b": 2}


def test_more_values_than_the_cap_are_refused(tmp_path: Path) -> None:
    at_cap = "[" + ",".join(["0"] * (MAX_YAML_NODES - 1)) + "]"  # the list is a value too
    assert len(read_yaml(_write(tmp_path, at_cap.encode()))) == MAX_YAML_NODES - 1
    over = "[" + ",".join(["0"] * MAX_YAML_NODES) + "]"
    with pytest.raises(ConfigError, match=f"more than {MAX_YAML_NODES} YAML values"):
        read_yaml(_write(tmp_path, over.encode()))


def test_a_fifo_a_device_or_a_directory_is_not_a_regular_file(tmp_path: Path) -> None:
    fifo = tmp_path / "robot.yaml"
    os.mkfifo(fifo)  # nobody writes to it: opening it must not wait
    for path, kind in ((fifo, "a FIFO"), (Path("/dev/zero"), "a character device")):
        err = _returns_within(30.0, lambda p=path: read_yaml(p, "robot file"))
        assert isinstance(err, ConfigError)
        assert str(err) == f"{path}: is not a regular file ({kind}), expected a robot file"
    with pytest.raises(ConfigError, match="is a directory, expected a robot file"):
        read_yaml(tmp_path, "robot file")


def test_more_bytes_than_the_limit_are_not_read(tmp_path: Path) -> None:
    path = _write(tmp_path, b"x" * 101)
    with pytest.raises(ConfigError, match="larger than 100 bytes, too large for a map image"):
        read_file_bytes(path, "map image", limit=100)
    assert read_file_bytes(path, "map image", limit=101) == b"x" * 101


def test_shipped_yaml_goes_through_the_same_guard() -> None:
    from omnical.experiment.library import builtin_script_data, builtin_script_names

    assert {"tour"} <= set(builtin_script_names())
    assert builtin_script_data("tour")["steps"]
    with pytest.raises(ConfigError, match=r"^preset x: YAML alias \*a"):
        parse_yaml("a: &a [1]\nb: *a\n", "preset x", "robot file")


_CLI_BOMBS = {
    "robot": ["simulate", "tour", "--robot", "{bomb}", "--out", "run.mcap"],
    "script": ["simulate", "{bomb}", "--out", "run.mcap"],
    "plan map": ["plan", "{bomb}", "--from", "1,1", "--to", "2,2", "--out", "p.csv"],
    "navigate map": [
        *("navigate", "--world", "lab-8x6", "--map", "{bomb}", "--start", "1.5,1.2,0"),
        *("--goal", "2.5,1.2", "--out", "nav.mcap"),
    ],
    "navigate world": [
        *("navigate", "--world", "{bomb}", "--map", "lab-8x6", "--start", "1.5,1.2,0"),
        *("--goal", "2.5,1.2", "--out", "nav.mcap"),
    ],
}


@pytest.mark.parametrize("case", sorted(_CLI_BOMBS))
def test_an_alias_bomb_ends_the_command_at_once_in_one_line(
    tmp_path: Path, case: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One case in a real process (stderr as a shell sees it), the others in-process (the same
    handlers, without a second start of Python and the command's imports)."""
    bomb = _write(tmp_path, BOMB.encode(), "bomb.yaml")
    args = [a.replace("{bomb}", str(bomb)) for a in _CLI_BOMBS[case]]
    if case == "robot":
        proc = subprocess.run(
            [sys.executable, "-m", "omnical.cli.main", *args],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=120,  # the guard against the hang (it burnt CPU past a minute)
            check=False,
        )
        status, stderr = proc.returncode, proc.stderr
    else:
        from typer.testing import CliRunner

        from omnical.cli.main import app

        monkeypatch.chdir(tmp_path)
        results = []
        err = _returns_within(120.0, lambda: results.append(CliRunner().invoke(app, args)))
        assert err is None, err
        status, stderr = results[0].exit_code, results[0].stderr
    assert status == 2, stderr
    assert stderr.splitlines() == [f"omnical: error: {_refused(bomb)}"]
    assert not list(tmp_path.glob("run*")) and not list(tmp_path.glob("nav*"))


def test_an_exponent_without_a_dot_is_a_float_as_in_yaml_1_2() -> None:
    """``resolution: 5e-2`` is a float to ROS's map_server (yaml-cpp, YAML 1.2); PyYAML's YAML
    1.1 read it as a string, and omnical refused a map that ROS reads."""
    from omnical.userfiles import parse_yaml

    data = parse_yaml("a: 5e-2\nb: -3E+2\nc: .5e1\nd: '2e-2'\ne: 1e\nf: 7\n", "m.yaml")
    assert data == {"a": 0.05, "b": -300.0, "c": 5.0, "d": "2e-2", "e": "1e", "f": 7}
    assert isinstance(data["f"], int)
