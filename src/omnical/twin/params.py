"""Parameters of the digital twin: the imperfections that make calibration necessary.

:class:`TwinParams` holds the true plant's imperfections; :func:`default_twin` gives seed 000
Table 2 as the truth of ``rosy-mecanum``. Signs and defaults: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationError

from omnical.config_models import StrictModel
from omnical.control.pid import PidParams
from omnical.errors import ConfigError
from omnical.ips.beacons import BeaconMap, default_beacon_map
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors_layout import factors_from_layout
from omnical.robot.description import DeadWheel, DriveTrain, RobotDescription
from omnical.twin.ips_params import IpsParams
from omnical.twin.wheel_motor import WheelMotor
from omnical.userfiles import read_yaml

__all__ = [
    "StepModel",
    "TwinEngine",
    "TwinParams",
    "check_nlos_beacons",
    "compiled_engine",
    "default_twin",
    "load_twin",
    "parse_twin",
]

TwinEngine = Literal["auto", "compiled", "python"]
"""How a twin runs its step loop and its IPS's vendor solve: compiled with numba (``"compiled"``,
``"auto"``) or the plain-Python/numpy reference (``"python"``). Both give the same bits."""


def compiled_engine(engine: TwinEngine, what: str) -> bool:
    """True if ``engine`` picks the numba kernels, False for the reference.

    Raises:
        ConfigError: an unknown engine (``what`` names the part in the message).
    """
    if engine in ("auto", "compiled", "python"):
        return engine != "python"
    msg = f"unknown {what} engine {engine!r}; use 'auto', 'compiled' or 'python'"
    raise ConfigError(msg)


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
        wheel_pid: the wheel-speed PID installed in the firmware (seed 003: one Ziegler–Nichols
            PID for all four motors, no feed-forward); None = the robot description's PI with
            the nominal-model feed-forward (``speed_kp``, ``speed_ki``).
        dead_wheel_radius_errors: (k,) relative error of each dead wheel's true radius against
            the described one (0.004 = 0.4 % larger); () = none.
        dead_wheel_slip: fraction of the ground distance a dead wheel fails to roll (spring
            pressure, wear: it under-reads by this fraction).
        wheel_speed_jitter: relative σ of each wheel-speed reading (the reading window's
            timing jitter over its length), white; used by :mod:`omnical.twin.motor`.
        load_ripple: amplitude of the load torque ripple on each wheel, as a fraction of the
            drive, at ``load_ripple_per_rev`` cycles per wheel revolution; used by
            :mod:`omnical.twin.motor`.
        load_ripple_per_rev: ripple cycles per wheel revolution (rollers per wheel).
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
    wheel_pid: PidParams | None = None
    dead_wheel_radius_errors: tuple[float, ...] = ()
    dead_wheel_slip: float = 0.0
    wheel_speed_jitter: float = 0.0
    load_ripple: float = 0.0
    load_ripple_per_rev: float = 1.0
    engine: TwinEngine = "auto"

    @classmethod
    def ideal_twin(cls, **changes: Any) -> TwinParams:
        """A twin with no imperfections and noiseless sensors."""
        return replace(cls(imu_noise=False, gyro_bias_radps=0.0, ips=IpsParams.ideal()), **changes)

    def with_installed(self, factors: CorrectionFactors) -> TwinParams:
        """The same plant with the vehicle controller compensating with ``factors``."""
        return replace(self, installed_factors=factors)

    def with_wheel_pid(self, pid: PidParams | None) -> TwinParams:
        """The same plant with ``pid`` installed in the firmware's wheel-speed loops."""
        return replace(self, wheel_pid=pid)

    def firmware_pid(self, dt_c: float) -> tuple[float, float, float, float] | None:
        """The installed PID as the firmware runs it: (Kp, Kp dt_c / Ti, Kp Td, Td / N)."""
        pid = self.wheel_pid
        if pid is None:
            return None
        ki_dt = pid.kp * dt_c / pid.ti_s if math.isfinite(pid.ti_s) else 0.0
        return (pid.kp, ki_dt, pid.kp * pid.td_s, pid.td_s / pid.derivative_filter_n)

    def dead_wheel_effective_radii(self, dead_wheels: Sequence[DeadWheel]) -> tuple[float, ...]:
        """Radius each dead wheel really rolls with: true radius (error) over (1 − slip).

        Raises:
            ConfigError: ``dead_wheel_radius_errors`` has neither 0 nor one value per dead
                wheel, or the slip is outside [0, 0.5].
        """
        errors = self.dead_wheel_radius_errors or (0.0,) * len(dead_wheels)
        if len(errors) != len(dead_wheels):
            msg = (
                f"dead_wheel_radius_errors: {len(errors)} values for {len(dead_wheels)} dead wheels"
            )
            raise ConfigError(msg)
        if not 0.0 <= self.dead_wheel_slip <= 0.5:
            msg = f"dead_wheel_slip: {self.dead_wheel_slip} is outside [0, 0.5]"
            raise ConfigError(msg)
        if not (self.dead_wheel_radius_errors or self.dead_wheel_slip):
            return tuple(d.radius_m for d in dead_wheels)  # exactly the described radii
        return tuple(
            d.radius_m * (1.0 + e) / (1.0 - self.dead_wheel_slip)
            for d, e in zip(dead_wheels, errors, strict=True)
        )

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


@dataclass(frozen=True)
class StepModel:
    """The constants of a twin's step loop, derived once from the robot and its
    :class:`TwinParams`; both engines of :class:`~omnical.twin.simulator.DigitalTwin` run on it.

    Steps of ``dt`` s; the firmware ticks every ``ctrl_every`` steps (``dt_c`` s), the samples
    are logged every ``*_every`` steps. Matrices are row tuples; ``dead_wheels`` holds per dead
    wheel (x, y, cos φ, sin φ, effective radius, counts/rev); ``pid`` is the installed wheel PID
    as (Kp, Kp dt_c / Ti, Kp Td, Td / N), None = PI (``kp``, ``ki``) with feed-forward (``tau``).
    """

    dt: float
    dt_c: float
    ctrl_every: int
    odom_every: int
    gt_every: int
    imu_every: int
    amax: tuple[float, float, float]
    vmax: tuple[float, float, float]
    wheel_max: float
    kp: float
    ki: float
    tau: float
    cpr: float
    rad_per_count: float
    installed: CorrectionFactors
    true: CorrectionFactors
    half_play: float
    slip_on: bool
    slip_decay: float
    slip_drive: float
    gyro_bias: float
    gyro_sigma: float
    accel_sigma: float
    imu_noise: bool
    J: tuple[tuple[float, ...], ...]
    Jp: tuple[tuple[float, ...], ...]
    Jp_true: tuple[tuple[float, ...], ...]
    motors: tuple[WheelMotor, ...]
    motor_decay: tuple[float, ...]
    dead_wheels: tuple[tuple[float, float, float, float, float, int], ...]
    start_pose: tuple[float, float, float]
    pid: tuple[float, float, float, float] | None


#: The omni-X twin's wheel-speed PID: :func:`omnical.twin.motor.seed003_motor_tuning` on the
#: twin's first motor at 100 rpm (Tyreus–Luyben row); a test holds these numbers to it.
OMNI_X_WHEEL_KU = 21.9453125
OMNI_X_WHEEL_PU_S = 0.03542168674698795
OMNI_X_WHEEL_PID = PidParams(
    kp=OMNI_X_WHEEL_KU / 2.2,
    ti_s=2.2 * OMNI_X_WHEEL_PU_S,
    td_s=OMNI_X_WHEEL_PU_S / 6.3,
)
#: Seed 003's external encoders on the omni-X twin: radius errors and slip (an error source the
#: paper names).
OMNI_X_DEAD_WHEEL_RADIUS_ERRORS = (0.003, -0.002, 0.004)
OMNI_X_DEAD_WHEEL_SLIP = 0.01
#: The omni-X motors' speed-reading jitter and load ripple (once per wheel turn).
OMNI_X_WHEEL_SPEED_JITTER = 0.005
OMNI_X_LOAD_RIPPLE = 0.05


def default_twin(robot: RobotDescription) -> TwinParams:
    """The default imperfect twin of a robot (seed 000 Table 2 truth for Mecanum bases).

    An omni base with dead wheels (seed 003's omni-X) also gets its tuned wheel PID installed
    (:data:`OMNI_X_WHEEL_PID`), imperfect dead wheels and the speed-reading noise of its motors.
    """
    truth = (
        ROSY_TRUTH
        if robot.kind == "mecanum"
        else CorrectionFactors(1.01, 1.03, 1.015, 0.004, -0.002, 0.01, -0.008)
    )
    n = robot.wheel_count
    seed003: dict[str, Any] = {}
    if robot.kind == "omni" and len(robot.dead_wheels) == len(OMNI_X_DEAD_WHEEL_RADIUS_ERRORS):
        seed003 = {
            "wheel_pid": OMNI_X_WHEEL_PID,
            "dead_wheel_radius_errors": OMNI_X_DEAD_WHEEL_RADIUS_ERRORS,
            "dead_wheel_slip": OMNI_X_DEAD_WHEEL_SLIP,
            "wheel_speed_jitter": OMNI_X_WHEEL_SPEED_JITTER,
            "load_ripple": OMNI_X_LOAD_RIPPLE,
        }
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
        **seed003,
    )


class _FactorsModel(StrictModel):
    scale: dict[str, float] = Field(default_factory=dict)
    crosstalk_rad_per_m: dict[str, float] = Field(default_factory=dict)


_Metres = Annotated[float, Field(ge=-1000.0, le=1000.0)]
"""A coordinate in the twin's world, m."""

_YawRad = Annotated[float, Field(ge=-2.0 * math.pi, le=2.0 * math.pi)]
"""A yaw, rad, within ±2π (a 90 there is degrees where radians are asked)."""


class _TwinModel(StrictModel):
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
    start_pose_map: tuple[_Metres, _Metres, _YawRad] | None = None
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
        if where == "start_pose_map.2" and isinstance(first.get("input"), int | float):
            yaw = float(first["input"])
            msg = (
                f"{source}: field '{where}': a yaw of {yaw:g} rad is more than a full turn: "
                f"give radians (e.g. {math.radians(yaw):.4g} for {yaw:g}°)"
            )
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
    for name in ("wheel_radius_errors", "motor_gain_errors"):
        values = getattr(m, name)
        if values is not None and len(values) != robot.wheel_count:
            msg = f"{source}: field '{name}': {len(values)} values for {robot.wheel_count} wheels"
            raise ConfigError(msg)
    if m.wheel_radius_errors is not None:
        changes["wheel_radius_errors"] = tuple(m.wheel_radius_errors)
    if m.motor_gain_errors is not None:
        for i, e in enumerate(m.motor_gain_errors):
            if not -0.9 < e <= 5.0:
                msg = f"{source}: field 'motor_gain_errors.{i}': {e} is not a plausible gain error"
                raise ConfigError(msg)
        changes["motor_gain_errors"] = tuple(m.motor_gain_errors)
    if m.hedge_offset_m is not None:
        hx, hy, hz = m.hedge_offset_m
        fp = robot.footprint
        if abs(hx) > fp.length_m / 2 or abs(hy) > fp.width_m / 2 or not 0.0 <= hz <= 5.0:
            msg = (
                f"{source}: field 'hedge_offset_m': the hedgehog ({hx}, {hy}, {hz}) m lies "
                f"outside {robot.name}'s footprint ({fp.length_m} × {fp.width_m} m) or not 0 "
                "to 5 m above base_link (metres: 4 cm is 0.04)"
            )
            raise ConfigError(msg)
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
        except ConfigError as err:  # "NAME: reason" of IpsParams ("ips: unknown key ...")
            name, _, reason = str(err).partition(": ")
            where = name if name == "ips" else f"ips.{name}"
            msg = f"{source}: field '{where}': {reason}"
            raise ConfigError(msg) from None
    if m.backlash_deg is not None:
        changes["backlash_rad"] = math.radians(m.backlash_deg)
    return replace(params, **changes)


def load_twin(
    path: str | Path, robot: RobotDescription, beacons: BeaconMap | None = None
) -> TwinParams:
    """Load a twin YAML file (``base: default|ideal`` plus overrides); ``ideal``/``default`` as
    names. Its NLOS zones must name beacons of ``beacons`` (default: seed 000 Table 3).

    Raises:
        ConfigError: the file is invalid (named, with the field).
    """
    text = str(path)
    if text == "ideal":
        return TwinParams.ideal_twin()
    if text == "default":
        return default_twin(robot)
    p = Path(text)
    if not p.exists():
        msg = f"{text}: no such twin file, and not a built-in twin ('default' or 'ideal')"
        raise ConfigError(msg)
    params = parse_twin(read_yaml(p, "twin file", allow_empty=True), robot, str(p))
    check_nlos_beacons(params, beacons, str(p))
    return params


def check_nlos_beacons(params: TwinParams, beacons: BeaconMap | None, source: str) -> None:
    """Every NLOS zone of the twin names a beacon of ``beacons`` (default: seed 000 Table 3).

    Raises:
        ConfigError: ``source: ips.nlos_zones[i].beacon: …`` for the first that does not.
    """
    known = (beacons if beacons is not None else default_beacon_map()).addresses.tolist()
    for i, zone in enumerate(params.ips.nlos_zones):
        if zone.beacon_address not in known:
            msg = (
                f"{source}: ips.nlos_zones[{i}].beacon: {zone.beacon_address} is not in the "
                f"beacon map (beacons {', '.join(map(str, known))})"
            )
            raise ConfigError(msg)
