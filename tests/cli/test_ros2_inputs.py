"""Bad input to the ROS 2 commands, found by a new user: a bad ``ROS_DOMAIN_ID``, a world or map
that does not exist, each one line and exit 2 before anything is published."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "ros2"))
from ros2_env import needs_ros2, omnical_command, private_domain_id, ros_env


def _run(env: dict[str, str], *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        omnical_command(*args), env=env, capture_output=True, text=True, timeout=60, check=False
    )


@needs_ros2
def test_a_bad_domain_id_is_one_line() -> None:
    """One value through a real ``omnical ros2`` process (the line as a shell shows it); the
    others through the check that process calls (a process each was 1.2 s of CPU)."""
    from omnical.errors import ConfigError
    from omnical.ros2.runtime import check_domain_id

    env = ros_env(private_domain_id("inputs"))
    env["ROS_DOMAIN_ID"] = "abc"
    done = _run(env, "ros2", "map", "lab-8x6")
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        "omnical: error: ROS_DOMAIN_ID='abc': give a whole number from 0 to 232"
    ]
    for domain in ("abc", "500", "-1", "233", "1.5"):
        with pytest.raises(ConfigError) as err:
            check_domain_id(domain)
        assert str(err.value) == f"ROS_DOMAIN_ID={domain!r}: give a whole number from 0 to 232"
    for fine in (None, "", "0", "232"):
        check_domain_id(fine)


@needs_ros2
def test_a_missing_world_is_refused_before_the_twin_starts() -> None:
    done = _run(ros_env(private_domain_id("inputs-world")), "ros2", "twin", "--world", "nosuch")
    assert done.returncode == 2, done.stderr
    assert done.stdout == ""  # no hedgehog line: nothing was started
    assert "nosuch" in done.stderr and "Traceback" not in done.stderr


@needs_ros2
def test_ros2_map_takes_a_shipped_world_by_name() -> None:
    proc = subprocess.Popen(
        omnical_command("ros2", "map", "lab-8x6"), env=ros_env(private_domain_id("inputs-map")),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    try:
        time.sleep(3.0)  # resolved, read and published, or failed by now
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, err


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["correct", "--factors", "f.yaml", "--topic", "bad topic"], "--topic 'bad topic': give"),
        (["correct", "--factors", "f.yaml", "--topic", "/1abc"], "--topic '/1abc': give"),
        (["locate", "--hedge", "serial:/dev/null", "--sigma", "1e308"], "'--sigma'"),
        (["twin", "--cmd-timeout", "nan"], "--cmd-timeout nan: give seconds"),
        (["twin", "--cmd-timeout", "-1"], "--cmd-timeout -1: give seconds"),
    ],
)
def test_a_bad_ros2_option_is_one_line_before_ros_starts(
    args: list[str], says: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # found by a new user: an invalid topic name reached rclpy (InvalidTopicNameException, a
    # traceback), --sigma 1e308 overflowed squaring it, --cmd-timeout named an internal field
    from typer.testing import CliRunner

    from omnical.cli.main import app

    def no_ros(**_: object) -> None:
        raise AssertionError("ROS 2 loaded before the options were checked")

    monkeypatch.setattr("omnical.ros2.runtime.ensure_ros_environment", no_ros)
    result = CliRunner().invoke(app, ["ros2", *args])
    assert result.exit_code == 2, result.output
    assert says in result.output and "Traceback" not in result.output
