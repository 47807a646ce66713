"""Parameters of the digital twin: the imperfections that make calibration necessary.

The true plant is the nominal kinematics plus these imperfections. The seven-factor truth uses the
definitions of :mod:`omnical.kinematics.correction`: the robot really travels 1/k of what the
wheels report and really turns c rad per metre travelled in each direction.

Default twin of ``rosy-mecanum``: seed 000 Table 2 as the truth. The paper gives magnitudes only;
omnical's default twin takes them with these signs (counter-clockwise positive):
forward +0.0072, reverse −0.00009, left +0.0389, right −0.0277 rad/m — the lateral pair of
opposite sign, as a misaligned roller set would make, so a calibration must find the signs too.

The default twin's motors differ from the firmware's nominal model (:mod:`omnical.twin.wheel_motor`):
gains a few per cent low and different per wheel, a 10 % slower lag, Coulomb friction and a
viscous load, so that the wheel-speed PI loop has real work to do and the open-loop odometry
follows the commanded reference at the millimetre level (seed 000 Table 4: about 8 mm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from omnical.errors import ConfigError
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors_layout import factors_from_layout
from omnical.robot.description import DriveTrain, RobotDescription
from omnical.robot.loader import read_yaml
from omnical.twin.ips_params import IpsParams
from omnical.twin.wheel_motor import WheelMotor

__all__ = ["TwinEngine", "TwinParams", "default_twin", "load_twin", "parse_twin"]

TwinEngine = Literal["auto", "compiled", "python"]
"""How a twin runs its step loop: compiled with numba, the plain-Python reference, or
``"auto"`` (compiled when numba imports). Both give the same logs."""

ROSY_TRUTH = CorrectionFactors(1.02, 1.13, 1.0236, 0.0072, -0.00009, 0.0389, -0.0277)

_DEFAULT_MOTOR_GAIN_ERRORS = (-0.02, -0.04, -0.03, -0.05)
DEFAULT_MOTOR_TIME_CONSTANT_ERROR = 0.08
DEFAULT_COULOMB_FRICTION_RADPS = 2.5
DEFAULT_VISCOUS_DROOP = 0.03


@dataclass(frozen=True)
class TwinParams:
    """Imperfections, sensor rates and start pose of a twin.

    Attributes:
        true_factors: the plant's real scaling and cross-talk (what calibration should find).
        wheel_radius_errors: (n,) relative radius error per wheel (0.002 = 0.2 % larger).
        slip_sigma: relative σ of random slip on the body twist (Ornstein–Uhlenbeck).
        slip_correlation_s: correlation time of the slip process.
        backlash_rad: dead band of each gearbox at the wheel, taken up at direction reversal.
        installed_factors: correction factors the vehicle controller applies (identity = uncalibrated).
        step_hz: simulation rate (≥ 200 Hz).
        odom_rate_hz, ground_truth_rate_hz: publication rates of /odom and /ground_truth.
        start_pose_map: (x, y, yaw) of base_link in the map frame at t = 0.
        gyro_bias_radps: None = the robot description's IMU bias.
        imu_noise: add the robot description's IMU white noise.
        ips: the simulated Marvelmind system (its hedgehog offset is set from hedge_offset_m).
        hedge_offset_m: true hedgehog mounting (x, y, z) in base_link; None = the description's.
        motor_gain_errors: (n,) relative error of each wheel motor's steady-state gain against
            the firmware's unit-gain model (−0.03 = 3 % weaker); () = none.
        motor_time_constant_error: relative error of the motors' time constant against the
            robot description's ``motor_time_constant_s`` (0.1 = 10 % slower).
        coulomb_friction_radps: Coulomb friction of each wheel (gearbox, rolling resistance) as
            the wheel speed it costs at steady state, rad/s; also the break-away threshold.
        viscous_droop: viscous friction and load, as the fraction of wheel speed lost at steady
            state (dimensionless).
        engine: the step loop's engine (:data:`TwinEngine`); not part of the plant.
    """

    true_factors: CorrectionFactors = field(default_factory=CorrectionFactors.identity)
    wheel_radius_errors: tuple[float, ...] = ()
    slip_sigma: float = 0.0
    slip_correlation_s: float = 0.5
    backlash_rad: float = 0.0
    installed_factors: CorrectionFactors = field(default_factory=CorrectionFactors.identity)
    step_hz: float = 200.0
    odom_rate_hz: float = 50.0
    ground_truth_rate_hz: float = 50.0
    start_pose_map: tuple[float, float, float] = (1.5, 1.2, 0.0)
    gyro_bias_radps: float | None = None
    imu_noise: bool = True
    ips: IpsParams = field(default_factory=IpsParams)
    hedge_offset_m: tuple[float, float, float] | None = None
    motor_gain_errors: tuple[float, ...] = ()
    motor_time_constant_error: float = 0.0
    coulomb_friction_radps: float = 0.0
    viscous_droop: float = 0.0
    engine: TwinEngine = "auto"

    @classmethod
    def ideal_twin(cls, **changes: Any) -> TwinParams:
        """A twin with no imperfections and noiseless sensors."""
        return replace(cls(imu_noise=False, gyro_bias_radps=0.0, ips=IpsParams.ideal()), **changes)

    def with_installed(self, factors: CorrectionFactors) -> TwinParams:
        """The same plant with the vehicle controller compensating with ``factors``."""
        return replace(self, installed_factors=factors)

    def wheel_motors(self, drive_train: DriveTrain, wheel_count: int) -> tuple[WheelMotor, ...]:
        """The true motor of each of ``wheel_count`` wheels.

        Raises:
            ConfigError: ``motor_gain_errors`` has neither 0 nor ``wheel_count`` values, or a
                motor parameter is out of range.
        """
        errors = self.motor_gain_errors or (0.0,) * wheel_count
        if len(errors) != wheel_count:
            msg = f"motor_gain_errors: {len(errors)} values for {wheel_count} wheels"
            raise ConfigError(msg)
        tau_s = drive_train.motor_time_constant_s * (1.0 + self.motor_time_constant_error)
        return tuple(
            WheelMotor(tau_s, 1.0 + e, self.coulomb_friction_radps, self.viscous_droop)
            for e in errors
        )


def default_twin(robot: RobotDescription) -> TwinParams:
    """The default imperfect twin of a robot (seed 000 Table 2 truth for Mecanum bases)."""
    truth = (
        ROSY_TRUTH
        if robot.kind == "mecanum"
        else CorrectionFactors(1.01, 1.03, 1.015, 0.004, -0.002, 0.01, -0.008)
    )
    n = robot.wheel_count
    return TwinParams(
        true_factors=truth,
        wheel_radius_errors=(0.0,) * n,
        slip_sigma=0.003,
        slip_correlation_s=0.5,
        backlash_rad=math.radians(0.3),
        motor_gain_errors=_DEFAULT_MOTOR_GAIN_ERRORS[:n] + (-0.03,) * max(0, n - 4),
        motor_time_constant_error=DEFAULT_MOTOR_TIME_CONSTANT_ERROR,
        coulomb_friction_radps=DEFAULT_COULOMB_FRICTION_RADPS,
        viscous_droop=DEFAULT_VISCOUS_DROOP,
    )


class _FactorsModel(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    scale: dict[str, float] = {}
    crosstalk_rad_per_m: dict[str, float] = {}


_Metres = Annotated[float, Field(ge=-1000.0, le=1000.0)]
"""A coordinate in the twin's world, m."""


class _TwinModel(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    base: str = Field(default="default", pattern=r"^(default|ideal)$")
    true_factors: _FactorsModel | None = None
    installed_factors: _FactorsModel | None = None
    wheel_radius_errors: list[Annotated[float, Field(ge=-0.5, le=0.5)]] | None = None
    slip_sigma: float | None = Field(default=None, ge=0.0, le=0.5)
    slip_correlation_s: float | None = Field(default=None, ge=0.005, le=60.0)
    backlash_deg: float | None = Field(default=None, ge=0.0, le=20.0)
    step_hz: float | None = Field(default=None, ge=200.0, le=5000.0)
    odom_rate_hz: float | None = Field(default=None, ge=1.0, le=1000.0)
    ground_truth_rate_hz: float | None = Field(default=None, ge=1.0, le=1000.0)
    start_pose_map: tuple[_Metres, _Metres, Annotated[float, Field(ge=-100.0, le=100.0)]] | None = (
        None
    )
    gyro_bias_radps: float | None = Field(default=None, ge=-10.0, le=10.0)
    hedge_offset_m: tuple[_Metres, _Metres, _Metres] | None = None
    ips: dict[str, Any] | None = None
    motor_gain_errors: list[Annotated[float, Field(gt=-0.9, le=5.0)]] | None = None
    motor_time_constant_error: float | None = Field(default=None, gt=-0.9, le=5.0)
    coulomb_friction_radps: float | None = Field(default=None, ge=0.0, le=100.0)
    viscous_droop: float | None = Field(default=None, ge=0.0, le=5.0)


def parse_twin(data: Any, robot: RobotDescription, source: str = "<twin>") -> TwinParams:
    """Validate a twin mapping (parsed YAML) on top of the default or ideal twin of ``robot``."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        msg = f"{source}: a twin file must be a mapping, got {type(data).__name__}"
        raise ConfigError(msg)
    try:
        m = _TwinModel.model_validate(data)
    except ValidationError as err:
        first = err.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "(top level)"
        msg = f"{source}: field '{where}': {first['msg']}"
        raise ConfigError(msg) from None
    params = TwinParams.ideal_twin() if m.base == "ideal" else default_twin(robot)
    changes: dict[str, Any] = {}
    if m.true_factors is not None:
        changes["true_factors"] = factors_from_layout(
            m.true_factors.model_dump(exclude_unset=True),
            source,
            "true_factors.",
            params.true_factors,
        )
    if m.installed_factors is not None:
        changes["installed_factors"] = factors_from_layout(
            m.installed_factors.model_dump(exclude_unset=True),
            source,
            "installed_factors.",
            CorrectionFactors(),
        )
    if m.wheel_radius_errors is not None:
        if len(m.wheel_radius_errors) != robot.wheel_count:
            msg = (
                f"{source}: field 'wheel_radius_errors': {len(m.wheel_radius_errors)} values for "
                f"{robot.wheel_count} wheels"
            )
            raise ConfigError(msg)
        changes["wheel_radius_errors"] = tuple(m.wheel_radius_errors)
    if m.motor_gain_errors is not None:
        if len(m.motor_gain_errors) != robot.wheel_count:
            msg = (
                f"{source}: field 'motor_gain_errors': {len(m.motor_gain_errors)} values for "
                f"{robot.wheel_count} wheels"
            )
            raise ConfigError(msg)
        for i, e in enumerate(m.motor_gain_errors):
            if not -0.9 < e <= 5.0:
                msg = f"{source}: field 'motor_gain_errors.{i}': {e} is not a plausible gain error"
                raise ConfigError(msg)
        changes["motor_gain_errors"] = tuple(m.motor_gain_errors)
    for name in (
        "slip_sigma",
        "slip_correlation_s",
        "step_hz",
        "odom_rate_hz",
        "ground_truth_rate_hz",
        "start_pose_map",
        "gyro_bias_radps",
        "hedge_offset_m",
        "motor_time_constant_error",
        "coulomb_friction_radps",
        "viscous_droop",
    ):
        value = getattr(m, name)
        if value is not None:
            changes[name] = value
    if m.ips is not None:
        try:
            changes["ips"] = params.ips.with_overrides(m.ips)
        except ConfigError as err:
            msg = f"{source}: field '{err}"
            raise ConfigError(msg.replace(": unknown key", "': unknown key", 1)) from None
    if m.backlash_deg is not None:
        changes["backlash_rad"] = math.radians(m.backlash_deg)
    return replace(params, **changes)


def load_twin(path: str | Path, robot: RobotDescription) -> TwinParams:
    """Load a twin YAML file (``base: default|ideal`` plus overrides); ``ideal``/``default`` as names."""
    text = str(path)
    if text == "ideal":
        return TwinParams.ideal_twin()
    if text == "default":
        return default_twin(robot)
    p = Path(text)
    return parse_twin(read_yaml(p), robot, str(p))
