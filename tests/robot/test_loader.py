"""Robot description files: presets load, bad files give one clear line."""

from __future__ import annotations

from pathlib import Path

import pytest

from omnical.errors import ConfigError
from omnical.robot import available_presets, load_robot


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
