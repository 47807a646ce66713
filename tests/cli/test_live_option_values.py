"""A live run's guard options refuse the values that would switch the guard off (a NaN
``--margin`` passed every path; a NaN ``--host-watchdog`` never tripped), in one line naming the
option, before anything is opened (the monitor link too: it would reset the page)."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from omnical.cli.main import app
from omnical.cli.serial_options import LiveOptions
from omnical.errors import ConfigError

runner = CliRunner()

COMMANDS = {
    "run": ["run", "tour", "--robot", "ros2", "--hedge", "none", "--yes"],
    "navigate": ["navigate", "--robot", "ros2", "--hedge", "none", "--map", "lab-8x6",
                 "--start", "1,1,0", "--goal", "2,1", "--yes"],
    "campaign": ["calibrate", "campaign", "--robot", "ros2", "--model", "rosy-mecanum",
                 "--hedge", "serial:/dev/null", "--yes"],
}  # fmt: skip

BAD = [
    ("--margin", "nan"),
    ("--margin", "inf"),
    ("--host-watchdog", "nan"),
    ("--host-watchdog", "-1"),
    ("--host-watchdog", "0"),
    ("--host-watchdog", "1e308"),
]


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize(("option", "value"), BAD)
def test_a_guard_switched_off_is_refused_before_anything_opens(
    command: str, option: str, value: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_ros(**_: object) -> None:
        raise AssertionError("ROS 2 loaded before the options were checked")

    monkeypatch.setattr("omnical.ros2.runtime.ensure_ros_environment", no_ros)
    out = tmp_path / "out"
    args = [*COMMANDS[command], option, value, "-o", str(out), "--monitor", "9"]
    result = runner.invoke(app, args)  # port 9: nobody listens, which the link would say
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"omnical: error: {option} "), result.output
    assert not out.exists()


def test_the_guards_limits_are_kept() -> None:
    assert LiveOptions(margin_m=0.0, host_watchdog_s=10.0).margin_m == 0.0  # at the limits
    assert LiveOptions(margin_m=-100.0).margin_m == -100.0  # the user allows the path outside
    with pytest.raises(ConfigError, match=r"--host-watchdog 10\.01"):
        LiveOptions(host_watchdog_s=10.01)


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--watchdog", "nan"], "--watchdog 'nan': 'off' or a timeout in seconds (> 0)"),
        (["--watchdog", "-1"], "--watchdog '-1': 'off' or a timeout in seconds (> 0)"),
        (
            ["--time-scale", "nan"],
            "--time-scale nan: give robot seconds per wall second from 0.1 to 100",
        ),
    ],
)
def test_twin_serve_names_its_own_options(args: list[str], says: str) -> None:
    # they named DeviceConfig's fields (watchdog_s, time_scale), after the "robot:" line
    result = runner.invoke(app, ["twin", "serve", *args])
    assert result.exit_code == 2, result.output
    assert result.output.strip().splitlines() == [f"omnical: error: {says}"]
