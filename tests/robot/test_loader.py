"""Robot description files: presets load, bad files give one clear line."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import pytest
import yaml
from typer.testing import CliRunner

from omnical.cli.main import app
from omnical.errors import ConfigError
from omnical.robot.loader import COUNTS_PER_REV_RANGE, available_presets, load_robot


def test_presets_ship() -> None:
    assert {"rosy-mecanum", "omni-x"} <= set(available_presets())
    rosy = load_robot("rosy-mecanum")
    assert rosy.wheel_count == 4
    assert rosy.drive_train.counts_per_wheel_rev == pytest.approx(4 * 500 * 18.5)
    assert rosy.wheels[0].radius_m == pytest.approx(0.0762)
    omni = load_robot("omni-x")
    assert len(omni.dead_wheels) == 3


def test_unknown_preset() -> None:
    with pytest.raises(ConfigError, match="unknown robot preset 'nope'"):
        load_robot("nope")


def test_invalid_yaml_names_file_and_line(tmp_path: Path) -> None:
    p = tmp_path / "bad.yaml"
    p.write_text("name: x\nwheels: [\n  - {a: 1\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml: invalid YAML at line"):
        load_robot(p)


def test_invalid_field_names_field(tmp_path: Path) -> None:
    src = (Path(__file__).parents[2] / "src/omnical/data/robots/rosy-mecanum.yaml").read_text()
    p = tmp_path / "r.yaml"
    p.write_text(src.replace("radius_m: 0.0762}", "radius_m: -1}", 1))
    with pytest.raises(ConfigError, match=r"r\.yaml: field 'wheels\.0\.radius_m'"):
        load_robot(p)
    p.write_text(src + "\nunexpected_key: 3\n")
    with pytest.raises(ConfigError, match="unexpected_key"):
        load_robot(p)
    # a misspelt key is named, not the required key it leaves missing
    p.write_text(src.replace("\nwheels:", "\nwheelz:", 1))
    with pytest.raises(ConfigError, match=r"r\.yaml: field 'wheelz': unknown key \(and 1 more\)"):
        load_robot(p)


def test_missing_file() -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_robot("/nonexistent/robot.yaml")


def test_footprint_lidar_and_dead_wheel_counts(tmp_path: Path) -> None:
    import math
    from importlib import resources

    import yaml

    rosy = load_robot("rosy-mecanum")
    assert (rosy.footprint.length_m, rosy.footprint.width_m) == (0.6, 0.6)
    assert rosy.lidar_mount.z_m == pytest.approx(0.25)
    omni = load_robot("omni-x")
    assert omni.footprint.length_m == pytest.approx(0.55)
    assert [d.counts_per_rev for d in omni.dead_wheels] == [2400, 2400, 2400]
    data = yaml.safe_load(
        resources.files("omnical.data.robots").joinpath("rosy-mecanum.yaml").read_text()
    )
    data["lidar"] = {"position_m": [0.1, -0.05, 0.3], "yaw_deg": 90}
    p = tmp_path / "r.yaml"
    p.write_text(yaml.safe_dump(data))
    robot = load_robot(p)
    assert robot.lidar_mount.yaw_rad == pytest.approx(math.pi / 2)
    assert (robot.lidar_mount.x_m, robot.lidar_mount.y_m) == (0.1, -0.05)
    data["lidar"] = {"position_m": [0.5, 0.0, 0.3]}
    p.write_text(yaml.safe_dump(data))
    with pytest.raises(
        ConfigError, match=r"r\.yaml: field 'lidar.position_m'.*outside the footprint"
    ):
        load_robot(p)
    data["lidar"] = {"position_m": [0.0, 0.0, 0.3]}
    data["footprint_m"] = {"length_m": -1.0, "width_m": 0.5}
    p.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r"field 'footprint_m.length_m'"):
        load_robot(p)


def _rosy_data() -> dict[str, Any]:
    from importlib import resources

    text = resources.files("omnical.data.robots").joinpath("rosy-mecanum.yaml").read_text()
    data: dict[str, Any] = yaml.safe_load(text)
    return data


@pytest.mark.parametrize(
    ("section", "value", "field", "reason"),
    [
        (
            "wheel_encoders",
            1e-300,
            "wheel_encoders.counts_per_rev",
            "Input should be greater than or equal to 4",
        ),
        (
            "wheel_encoders",
            2.0,
            "wheel_encoders.counts_per_rev",
            "Input should be greater than or equal to 4",
        ),
        (
            "wheel_encoders",
            2e9,
            "wheel_encoders.counts_per_rev",
            "Input should be less than or equal to 1000000000",
        ),
        (
            "wheel_encoders",
            True,
            "wheel_encoders.counts_per_rev",
            "expected a number, got a boolean",
        ),
        (
            "dead_wheels",
            0,
            "dead_wheels.0.counts_per_rev",
            "Input should be greater than or equal to 4",
        ),
        ("dead_wheels", True, "dead_wheels.0.counts_per_rev", "expected a number, got a boolean"),
        ("radius", True, "wheels.0.radius_m", "expected a number, got a boolean"),
        ("position", [True, 0.2], "wheels.0.position_m", "expected a number, got a boolean"),
    ],
)
def test_encoder_counts_out_of_any_encoder_and_booleans_are_refused(
    tmp_path: Path, section: str, value: object, field: str, reason: str
) -> None:
    """counts_per_rev 1e-300 passed '> 0' (2.41 m of odometry error) and true was taken as 1."""
    data = _rosy_data()
    if section == "wheel_encoders":
        data["wheel_encoders"] = {"counts_per_rev": value}
    elif section == "dead_wheels":
        data["dead_wheels"] = [
            {"name": "x", "position_m": [0, 0], "direction_deg": 0, "radius_m": 0.03}
        ]
        data["dead_wheels"][0]["counts_per_rev"] = value
    else:
        data["wheels"][0]["radius_m" if section == "radius" else "position_m"] = value
    path = tmp_path / "r.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        res = CliRunner().invoke(
            app, ["simulate", "tour", "--robot", str(path), "--out", str(tmp_path / "run.mcap")]
        )
    assert res.exit_code == 2, res.output
    (line,) = res.stderr.splitlines()
    assert line.startswith(f"omnical: error: {path}: field '{field}': {reason}"), line
    assert "Traceback" not in res.output and "Warning" not in res.output
    assert not (tmp_path / "run").exists()


def test_encoder_counts_of_real_encoders_load(tmp_path: Path) -> None:
    low, high = COUNTS_PER_REV_RANGE
    for counts in (low, 777.0, high):
        data = _rosy_data()
        data["wheel_encoders"] = {"counts_per_rev": counts}
        path = tmp_path / "r.yaml"
        path.write_text(yaml.safe_dump(data), encoding="utf-8")
        assert load_robot(path).encoders.counts_per_rev == counts


def test_a_file_based_on_a_preset_changes_only_what_it_gives(tmp_path: Path) -> None:
    """``base: PRESET``: the preset with the file's fields over it, mappings merged key by key
    (what the encoder-counts refusal tells a preset's user to write)."""
    path = tmp_path / "mine.yaml"
    path.write_text(
        "base: rosy-mecanum\nname: mine\nwheel_encoders: {counts_per_rev: 4096}\n"
        "footprint_m: {width_m: 0.7}\n",
        encoding="utf-8",
    )
    got = load_robot(path)
    preset = load_robot("rosy-mecanum")
    assert got.name == "mine"
    assert got.wheel_encoders is not None and got.wheel_encoders.counts_per_rev == 4096
    assert (got.footprint.length_m, got.footprint.width_m) == (0.6, 0.7)
    assert got.wheels == preset.wheels and got.limits == preset.limits


@pytest.mark.parametrize("base", ["nosuch", "[1, 2]", "./other.yaml"])
def test_a_base_that_is_not_a_preset_is_refused_naming_the_field(tmp_path: Path, base: str) -> None:
    path = tmp_path / "mine.yaml"
    path.write_text(f"base: {base}\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"mine\.yaml: field 'base': must name a robot preset"):
        load_robot(path)


@pytest.mark.parametrize("offset", [[4, -3, 0.4], [0.04, -0.03, -0.4], [0.04, -0.03, 6.0]])
def test_a_hedgehog_off_the_robot_is_refused(tmp_path: Path, offset: list[float]) -> None:
    """Issue 29 (sizes checked): hedge_offset_m in centimetres ([4, -3, 0.4]) put the hedgehog
    5 m from a robot 60 cm wide without a word (only ±10 m was checked)."""
    path = tmp_path / "r.yaml"
    path.write_text(f"base: rosy-mecanum\nhedge_offset_m: {offset}\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"r\.yaml: field 'hedge_offset_m': the hedgehog"):
        load_robot(path)
