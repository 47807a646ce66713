"""Load and validate robot description files (YAML) into :class:`RobotDescription`.

Validation happens once, here, with pydantic; errors name the file, the field and the reason.
Angles in files are in degrees (``*_deg``), lengths in metres (``*_m``).
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Final

from pydantic import ConfigDict, Field, ValidationError

from omnical.config_models import StrictModel
from omnical.errors import ConfigError
from omnical.kinematics.jacobian import inverse_jacobian
from omnical.robot.description import (
    DeadWheel,
    DriveTrain,
    ImuNoise,
    LidarMount,
    Limits,
    RobotDescription,
    RobotFootprint,
    Wheel,
    WheelEncoders,
)
from omnical.userfiles import parse_yaml, read_yaml

__all__ = ["COUNTS_PER_REV_RANGE", "available_presets", "load_robot", "parse_robot"]

_PRESET_PACKAGE = "omnical.data.robots"


_Coordinate = Annotated[float, Field(ge=-10.0, le=10.0)]
"""A position on the robot, m: within 10 m of its centre."""


COUNTS_PER_REV_RANGE: Final = (4.0, 1e9)
"""Encoder counts per wheel revolution a robot file may give: from a single-line quadrature
encoder (4) to a 24-bit one behind a 50:1 gearbox (8.4e8). Fewer is no odometry at all."""


class _Strict(StrictModel):
    model_config = ConfigDict(frozen=True)


class _WheelModel(_Strict):
    name: str
    position_m: tuple[_Coordinate, _Coordinate]
    roller_angle_deg: float = Field(ge=-90.0, le=90.0)
    radius_m: float = Field(ge=1e-3, le=1.0)
    spin_axis_deg: float = Field(default=90.0, ge=-360.0, le=360.0)


class _DeadWheelModel(_Strict):
    name: str
    position_m: tuple[_Coordinate, _Coordinate]
    direction_deg: float = Field(ge=-360.0, le=360.0)
    radius_m: float = Field(ge=1e-3, le=1.0)
    counts_per_rev: int = Field(ge=COUNTS_PER_REV_RANGE[0], le=COUNTS_PER_REV_RANGE[1])


class _LimitsModel(_Strict):
    max_vx_mps: float = Field(gt=0.0, le=20.0)
    max_vy_mps: float = Field(gt=0.0, le=20.0)
    max_wz_radps: float = Field(gt=0.0, le=50.0)
    max_ax_mps2: float = Field(ge=1e-3, le=100.0)
    max_ay_mps2: float = Field(ge=1e-3, le=100.0)
    max_alpha_radps2: float = Field(ge=1e-3, le=500.0)


class _DriveTrainModel(_Strict):
    encoder_lines: int = Field(gt=0, le=1_000_000)
    gear_ratio: float = Field(ge=1e-3, le=1e4)
    motor_time_constant_s: float = Field(gt=0.0, le=5.0)
    speed_kp: float = Field(ge=0.0, le=1e4)
    speed_ki: float = Field(ge=0.0, le=1e6)
    control_rate_hz: float = Field(default=100.0, ge=1.0, le=10000.0)


class _ImuModel(_Strict):
    gyro_noise_radps: float = Field(default=0.002, ge=0.0, le=10.0)
    gyro_bias_radps: float = Field(default=0.001, ge=-10.0, le=10.0)
    accel_noise_mps2: float = Field(default=0.02, ge=0.0, le=100.0)
    rate_hz: float = Field(default=100.0, ge=1.0, le=10000.0)


class _FootprintModel(_Strict):
    length_m: float = Field(default=0.6, ge=0.01, le=10.0)
    width_m: float = Field(default=0.6, ge=0.01, le=10.0)


class _LidarModel(_Strict):
    position_m: tuple[_Coordinate, _Coordinate, _Coordinate] = (0.0, 0.0, 0.2)
    yaw_deg: float = Field(default=0.0, ge=-360.0, le=360.0)


class _WheelEncodersModel(_Strict):
    counts_per_rev: float | None = Field(
        default=None, ge=COUNTS_PER_REV_RANGE[0], le=COUNTS_PER_REV_RANGE[1]
    )
    joints: dict[str, str] = Field(default_factory=dict)
    reversed: list[str] = Field(default_factory=list)


class _RobotModel(_Strict):
    name: str
    kind: str = Field(pattern=r"^(mecanum|omni)$")
    wheels: list[_WheelModel] = Field(min_length=3)
    limits: _LimitsModel
    drive_train: _DriveTrainModel
    imu: _ImuModel = _ImuModel()
    hedge_offset_m: tuple[_Coordinate, _Coordinate, _Coordinate] = (0.0, 0.0, 0.0)
    odom_yaw_resolution_radps: float = Field(default=0.001, ge=0.0, le=0.1)
    dead_wheels: list[_DeadWheelModel] = Field(default_factory=list)
    footprint_m: _FootprintModel = _FootprintModel()
    lidar: _LidarModel = _LidarModel()
    wheel_encoders: _WheelEncodersModel | None = None


def _wheel_encoders(
    m: _WheelEncodersModel | None, wheels: list[str], source: str
) -> WheelEncoders | None:
    """The ``wheel_encoders`` section: joint names by wheel name, reversed wheels, counts."""
    if m is None:
        return None
    for key, names in (("joints", list(m.joints)), ("reversed", m.reversed)):
        if unknown := [n for n in names if n not in wheels]:
            msg = (
                f"{source}: field 'wheel_encoders.{key}': unknown wheel(s) {', '.join(unknown)} "
                f"(wheels: {', '.join(wheels)})"
            )
            raise ConfigError(msg)
    joints = tuple(m.joints.get(w, w) for w in wheels)
    if len(set(joints)) != len(joints):
        msg = f"{source}: field 'wheel_encoders.joints': joint names must be unique, got {joints}"
        raise ConfigError(msg)
    signs = tuple(-1.0 if w in m.reversed else 1.0 for w in wheels)
    return WheelEncoders(joints, m.counts_per_rev, signs)


def _format_validation_error(source: str, err: ValidationError) -> str:
    # An unknown key first: a misspelt key ('wheelz') also makes the right one missing, and the
    # misspelling is what the user must see.
    errors = sorted(err.errors(), key=lambda e: e["type"] != "extra_forbidden")
    first = errors[0]
    where = ".".join(str(p) for p in first["loc"]) or "(top level)"
    more = f" (and {err.error_count() - 1} more)" if err.error_count() > 1 else ""
    if first["type"] == "extra_forbidden":
        return f"{source}: field '{where}': unknown key{more}"
    return f"{source}: field '{where}': {first['msg']}{more}"


def parse_robot(data: Any, source: str = "<robot>") -> RobotDescription:
    """Validate a mapping (parsed YAML) into a RobotDescription."""
    if not isinstance(data, dict):
        msg = f"{source}: a robot description must be a mapping, got {type(data).__name__}"
        raise ConfigError(msg)
    try:
        m = _RobotModel.model_validate(data)
    except ValidationError as err:
        raise ConfigError(_format_validation_error(source, err)) from None
    names = [w.name for w in m.wheels]
    if len(set(names)) != len(names):
        msg = f"{source}: field 'wheels': wheel names must be unique, got {names}"
        raise ConfigError(msg)
    names = [d.name for d in m.dead_wheels]
    if len(set(names)) != len(names):
        msg = f"{source}: field 'dead_wheels': dead-wheel names must be unique, got {names}"
        raise ConfigError(msg)
    half_l, half_w = m.footprint_m.length_m / 2, m.footprint_m.width_m / 2
    lx, ly, _ = m.lidar.position_m
    if abs(lx) > half_l + 1e-9 or abs(ly) > half_w + 1e-9:
        msg = (
            f"{source}: field 'lidar.position_m': the LiDAR ({lx}, {ly}) m lies outside the "
            f"footprint ({m.footprint_m.length_m} × {m.footprint_m.width_m} m)"
        )
        raise ConfigError(msg)
    hx, hy, hz = m.hedge_offset_m
    if abs(hx) > half_l + 1e-9 or abs(hy) > half_w + 1e-9 or not 0.0 <= hz <= 5.0:
        msg = (
            f"{source}: field 'hedge_offset_m': the hedgehog ({hx}, {hy}, {hz}) m lies outside "
            f"the footprint ({m.footprint_m.length_m} × {m.footprint_m.width_m} m) or not 0 to "
            "5 m above base_link (metres: 4 cm is 0.04)"
        )
        raise ConfigError(msg)
    for i, w in enumerate(m.wheels):
        if abs(w.roller_angle_deg) < 1.0:
            msg = f"{source}: field 'wheels.{i}.roller_angle_deg': must not be near 0 (got {w.roller_angle_deg})"
            raise ConfigError(msg)
    wheels = tuple(
        Wheel(
            name=w.name,
            x_m=w.position_m[0],
            y_m=w.position_m[1],
            roller_angle_rad=math.radians(w.roller_angle_deg),
            radius_m=w.radius_m,
            drive_direction_rad=math.radians(w.spin_axis_deg - 90.0),
        )
        for w in m.wheels
    )
    dead = tuple(
        DeadWheel(
            name=d.name,
            x_m=d.position_m[0],
            y_m=d.position_m[1],
            direction_rad=math.radians(d.direction_deg),
            radius_m=d.radius_m,
            counts_per_rev=d.counts_per_rev,
        )
        for d in m.dead_wheels
    )
    robot = RobotDescription(
        name=m.name,
        kind=m.kind,
        wheels=wheels,
        limits=Limits(**m.limits.model_dump()),
        drive_train=DriveTrain(**m.drive_train.model_dump()),
        imu=ImuNoise(**m.imu.model_dump()),
        hedge_offset_m=m.hedge_offset_m,
        odom_yaw_resolution_radps=m.odom_yaw_resolution_radps,
        dead_wheels=dead,
        footprint=RobotFootprint(m.footprint_m.length_m, m.footprint_m.width_m),
        lidar_mount=LidarMount(
            m.lidar.position_m[0],
            m.lidar.position_m[1],
            m.lidar.position_m[2],
            math.radians(m.lidar.yaw_deg),
        ),
        wheel_encoders=_wheel_encoders(m.wheel_encoders, [w.name for w in m.wheels], source),
    )
    # Geometry check (rank of J) gives a clear message for a singular layout.
    try:
        inverse_jacobian(robot.wheels)
    except ConfigError as err:
        msg = f"{source}: field 'wheels': {err}"
        raise ConfigError(msg) from None
    return robot


def available_presets() -> list[str]:
    """Names of the robot presets shipped with omnical."""
    root = resources.files(_PRESET_PACKAGE)
    return sorted(p.name.removesuffix(".yaml") for p in root.iterdir() if p.name.endswith(".yaml"))


def load_robot(name_or_path: str | Path) -> RobotDescription:
    """Load a preset by name (``rosy-mecanum``, ``omni-x``) or a robot YAML file by path (one
    with ``base: PRESET`` changes that preset: its fields over the preset's).

    Raises:
        ConfigError: unknown preset, unreadable or invalid file.
    """
    text = str(name_or_path)
    path = Path(text)
    if path.suffix in {".yaml", ".yml"} or path.exists():
        data = read_yaml(path, "robot file")
        return parse_robot(_with_base(data, str(path)), str(path))
    return parse_robot(_preset_data(text), f"preset {text}")


def _preset_data(name: str) -> Any:
    """The parsed YAML of preset ``name``.

    Raises:
        ConfigError: no such preset.
    """
    presets = available_presets()
    if name not in presets:
        msg = f"unknown robot preset {name!r}; presets: {', '.join(presets)} (or give a YAML file path)"
        raise ConfigError(msg)
    res = resources.files(_PRESET_PACKAGE).joinpath(f"{name}.yaml")
    return parse_yaml(res.read_text(encoding="utf-8"), f"preset {name}", "robot file")


def _with_base(data: Any, source: str) -> Any:
    """A robot file with ``base: PRESET``: the preset with the file's fields over it (a mapping
    merged key by key, anything else replaced), so that a preset's robot can be changed in one
    line (``wheel_encoders: {counts_per_rev: 4096}``) without copying it."""
    if not isinstance(data, dict) or "base" not in data:
        return data
    rest = {k: v for k, v in data.items() if k != "base"}
    base = data["base"]
    if not isinstance(base, str) or base not in available_presets():
        msg = (
            f"{source}: field 'base': must name a robot preset "
            f"({', '.join(available_presets())}), got {base!r}"
        )
        raise ConfigError(msg)
    return _merged(_preset_data(base), rest)


def _merged(base: Any, over: Any) -> Any:
    if isinstance(base, dict) and isinstance(over, dict):
        out = dict(base)
        for key, value in over.items():
            out[key] = _merged(base[key], value) if key in base else value
        return out
    return over
