"""Plausibility and messages at the boundary (issue 29): angles, and what a bag holds.

Yaws are radians within a turn, or degrees said so.
``map --initial-pose 1.5,1.2,90`` built a map rotated by 116.6° and still reported a 0.3 cm
RMSE; ``navigate --start …,90`` ran. A yaw beyond ±2π is refused naming the option, with the
radians meant; ``90deg`` says degrees.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from omnical.cli.main import app
from omnical.cli.plan import parse_xy
from omnical.errors import ConfigError


def test_a_yaw_is_radians_or_says_degrees() -> None:
    assert parse_xy("1.5,1.2,1.5708", "--start", 3) == (1.5, 1.2, 1.5708)
    assert parse_xy("1.5, 1.2, 90deg", "--start", 3) == pytest.approx((1.5, 1.2, math.pi / 2))
    assert parse_xy("0,0,-6.2", "--start", 3)[2] == -6.2  # within a turn
    with pytest.raises(
        ConfigError, match=r"--start: a yaw of 90 rad is more than a full turn.*90deg"
    ):
        parse_xy("1.5,1.2,90", "--start", 3)
    with pytest.raises(ConfigError, match="expected X,Y,YAW"):
        parse_xy("1.5,1.2,ninetydeg", "--start", 3)


NAV = ["navigate", "--world", "lab-8x6", "--map", "lab-8x6", "--goal", "6.5,3", "--out", "n.mcap"]
RUN = ["run", "tour", "--robot", "serial:/dev/null", "--hedge", "none", "--out", "r.mcap"]


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["map", "RUN", "--initial-pose", "1.5,1.2,90", "--out", "m.yaml"], "--initial-pose: a yaw of 90"),
        ([*NAV, "--start", "1.5,1.2,90"], "--start: a yaw of 90 rad"),
        ([*RUN, "--start-yaw", "90"], "90 rad is more than a full turn"),
    ],
)  # fmt: skip
def test_degrees_where_radians_are_asked_are_refused(
    tmp_path: Path, args: list[str], needle: str
) -> None:
    def here(arg: str) -> str:
        return str(tmp_path / arg) if arg in ("m.yaml", "n.mcap", "r.mcap") else arg

    args = [here(a) for a in args]
    if "RUN" in args:  # map reads its bag first: any bag will do, the pose is refused after
        from omnical.bags.bag import write_bag
        from omnical.recording.recording import RecordingBuilder

        builder = RecordingBuilder()
        zero = [0.0, 0.0]
        builder.add_many("/cmd_vel", [1, 2], vx_mps=zero, vy_mps=zero, wz_radps=zero)
        bag = str(write_bag(builder.build(), tmp_path / "run.mcap"))
        args = [bag if a == "RUN" else a for a in args]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2, result.output
    assert needle in " ".join(result.output.split()), result.output
    assert not list(tmp_path.glob("[mnr].*"))  # nothing written


@pytest.mark.parametrize("pose", ["1e9,1.2,0", "1.5,-10000.5,0"])
def test_map_refuses_an_initial_pose_beyond_10_km(tmp_path: Path, pose: str) -> None:
    """``map --initial-pose 1e9,1.2,0`` wrote a map (origin 999999992.98) plan then refused."""
    out = tmp_path / "m.yaml"
    result = CliRunner().invoke(
        app, ["map", str(tmp_path / "no.mcap"), "--initial-pose", pose, "--out", str(out)]
    )
    assert result.exit_code == 2, result.output
    text = " ".join(result.output.split())
    assert f"--initial-pose {pose}: x, y must lie within ±10000 m" in text, text
    assert list(tmp_path.iterdir()) == []  # refused before SLAM, nothing written


def test_map_names_every_topic_of_a_bag_without_a_lidar(tmp_path: Path) -> None:
    """Issue 29: map's refusal listed 2 of the bag's 9 topics (those it had read)."""
    from omnical.bags.bag import write_bag
    from omnical.recording.recording import RecordingBuilder

    builder = RecordingBuilder()
    zero = [0.0, 0.0]
    builder.add_many("/cmd_vel", [1, 2], vx_mps=zero, vy_mps=zero, wz_radps=zero)
    builder.add_many("/imu", [1, 2], **dict.fromkeys(_IMU, zero))
    bag = write_bag(builder.build(), tmp_path / "run.mcap")
    result = CliRunner().invoke(app, ["map", str(bag), "--out", str(tmp_path / "m.yaml")])
    assert result.exit_code == 2, result.output
    text = " ".join(result.output.split())
    assert "no /scan and no /odom to map from" in text
    assert "/cmd_vel (geometry_msgs/msg/Twist)" in text and "/imu (sensor_msgs/msg/Imu)" in text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # nothing left behind


_IMU = ("gyro_x_radps", "gyro_y_radps", "gyro_z_radps", "acc_x_mps2", "acc_y_mps2", "acc_z_mps2")


def test_version_short_help_and_a_tilde_after_the_equals_sign(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 29: no --version, no -h, and --out=~/x.mcap made a directory named '~'."""
    from omnical.cli.entry import _expand_home

    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0 and result.output.startswith("omnical ")
    assert CliRunner().invoke(app, ["run", "-h"]).exit_code == 0
    monkeypatch.setenv("HOME", str(tmp_path))
    assert _expand_home("--out=~/x.mcap") == f"--out={tmp_path}/x.mcap"
    assert _expand_home("-o~/x.mcap") == f"-o{tmp_path}/x.mcap"
    assert _expand_home("--out") == "--out" and _expand_home("a=~/b") == "a=~/b"
    assert _expand_home("~/y.mcap") == f"{tmp_path}/y.mcap"  # quoted: the shell left it
    assert _expand_home("~user-x") == "~user-x"


def test_start_yaw_takes_radians_or_degrees_with_a_suffix() -> None:
    """Issue 29: run --start-yaw 90deg leaked pydantic's 'unable to parse' message."""
    import math

    from omnical.cli.serial_options import _parse_yaw

    assert _parse_yaw("90deg") == pytest.approx(math.pi / 2)
    assert _parse_yaw("-1.5") == -1.5
    for bad in ("90", "abc", "nan"):
        with pytest.raises(typer.BadParameter):
            _parse_yaw(bad)


def test_a_failed_command_leaves_no_directory_it_created(tmp_path: Path) -> None:
    """Issue 29: map, locate, plan, calibrate estimate and navigate left empty output
    directories behind when they failed."""
    from omnical.bags.bag import write_bag
    from omnical.recording.recording import RecordingBuilder

    bag = tmp_path / "odom-only.mcap"
    rec = RecordingBuilder()
    zeros = {c: np.zeros(3) for c in ("x_m", "y_m", "yaw_rad", "vx_mps", "vy_mps", "wz_radps")}
    rec.add_many("/odom", np.arange(3) * 10**8, **zeros)
    write_bag(rec.build(), bag)
    out = tmp_path / "new" / "deeper" / "fixes.csv"
    result = CliRunner().invoke(app, ["locate", str(bag.with_suffix("")), "--out", str(out)])
    assert result.exit_code == 2, result.output
    assert not (tmp_path / "new").exists()
