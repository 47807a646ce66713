"""``--area`` on a real robot is refused where it could not be checked (no hedgehog to place the
path; navigation without a hedgehog or a beacon map), before anything is opened."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from omnical.cli.main import app

runner = CliRunner()


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["run", "tour", "--robot", "serial:/dev/null", "--hedge", "none", "--yes"],
         "--area needs the hedgehog"),
        (["navigate", "--robot", "ros2", "--hedge", "none", "--map", "lab-8x6",
          "--start", "1,1,0", "--goal", "2,1", "--yes"], "give --beacons"),
    ],
)  # fmt: skip
def test_area_that_cannot_be_checked_is_refused(
    args: list[str], says: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_ros(**_: object) -> None:
        raise AssertionError("ROS 2 loaded before the options were checked")

    monkeypatch.setattr("omnical.ros2.runtime.ensure_ros_environment", no_ros)
    out = tmp_path / "x.mcap"
    result = runner.invoke(app, [*args, "--area", "0,0,5,5", "-o", str(out)])
    assert result.exit_code == 2, result.output
    assert says in result.output
    assert not out.exists()
