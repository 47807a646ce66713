"""Without the ``[ros2]`` extra: ``omnical ros2 ...`` says in one line how to install it (exit 2),
and ``--help`` never loads rclpy nor omnical.ros2 (rclpy hidden by a ``sys.modules`` block)."""

from __future__ import annotations

import subprocess
import sys

import pytest

HIDDEN = "import sys; sys.modules['rclpy'] = None; "
RUN = "from omnical.cli.entry import main; sys.argv = ['omnical', *sys.argv[1:]]; main()"


def omnical_without_rclpy(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", HIDDEN + RUN, *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


@pytest.mark.parametrize(
    "args",
    [
        ("ros2", "twin"),
        ("ros2", "map", "lab-8x6"),  # a map that loads: it is read before ROS 2 starts
        ("ros2", "locate", "--hedge", "serial:/dev/null"),
        ("ros2", "correct", "--factors", "factors.yaml"),
        ("ros2", "build-tf2-msgs"),
    ],
)
def test_a_ros2_command_without_rclpy_says_how_to_install_it(args: tuple[str, ...]) -> None:
    done = omnical_without_rclpy(*args)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert "pip install 'omnical[ros2]'" in lines[0]
    assert "Traceback" not in done.stderr


def test_help_loads_neither_rclpy_nor_omnical_ros2() -> None:
    probe = (
        "import sys; from omnical.cli.main import app\n"
        "try:\n    app(['ros2', '--help'])\nexcept SystemExit:\n    pass\n"
        "try:\n    app(['--help'])\nexcept SystemExit:\n    pass\n"
        "loaded = [m for m in sys.modules if m.split('.')[0] in ('rclpy', 'nav_msgs') "
        "or m.startswith('omnical.ros2')]\n"
        "print('LOADED', loaded)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True
    )
    assert "LOADED []" in done.stdout
    assert "twin" in done.stdout and "correct" in done.stdout and "locate" in done.stdout
