"""The robot description: wheels, limits, drive train, IMU and hedgehog mounting (frozen values).

A wheel: contact point in ``base_link``, drive direction, roller angle γ (±45° Mecanum, 90° omni)
and radius (docs/CONVENTIONS.md); loading and validation: :mod:`omnical.robot.loader`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DeadWheel",
    "DriveTrain",
    "ImuNoise",
    "Limits",
    "RobotDescription",
    "Wheel",
    "WheelEncoders",
]


@dataclass(frozen=True)
class Wheel:
    """One driven wheel.

    Attributes:
        name: label used in messages ("rear_left").
        x_m, y_m: contact point in ``base_link``.
        roller_angle_rad: γ of seed 001 Eq. 3–5; ±π/4 Mecanum, π/2 omni.
        radius_m: rolling radius.
        drive_direction_rad: direction in ``base_link`` the hub moves for a positive wheel speed
            (0 = forward). The spin axis is this direction turned by +90°.
    """

    name: str
    x_m: float
    y_m: float
    roller_angle_rad: float
    radius_m: float
    drive_direction_rad: float = 0.0


@dataclass(frozen=True)
class DeadWheel:
    """An unpowered measuring wheel with its own encoder (seed 003's external encoders)."""

    name: str
    x_m: float
    y_m: float
    direction_rad: float
    radius_m: float
    counts_per_rev: int


@dataclass(frozen=True)
class WheelEncoders:
    """How a recording's ``sensor_msgs/JointState`` names and scales the driven wheels' encoders.

    Attributes:
        joints: the JointState joint name of each driven wheel, in the order of
            :attr:`RobotDescription.wheels`.
        counts_per_rev: encoder counts per *wheel* revolution, any positive number (42 counts
            per motor turn through an 18.5:1 gearbox: 777.0); None: the positions are radians
            (sensor_msgs' convention).
        signs: +1.0 or −1.0 per wheel: −1.0 where the encoder counts down while the wheel turns
            positively (the right-hand rule about its spin axis).
    """

    joints: tuple[str, ...]
    counts_per_rev: float | None = None
    signs: tuple[float, ...] = ()

    def radians_per_unit(self) -> NDArray[np.float64]:
        """(n,) factor from a JointState position to the wheel angle, rad (sign included)."""
        n = len(self.joints)
        signs = np.asarray(self.signs if self.signs else (1.0,) * n, dtype=np.float64)
        unit = 1.0 if self.counts_per_rev is None else 2.0 * math.pi / self.counts_per_rev
        out: NDArray[np.float64] = signs * unit
        return out


@dataclass(frozen=True)
class Limits:
    """Speed and acceleration limits of the base, SI units."""

    max_vx_mps: float
    max_vy_mps: float
    max_wz_radps: float
    max_ax_mps2: float
    max_ay_mps2: float
    max_alpha_radps2: float

    @property
    def max_twist(self) -> NDArray[np.float64]:
        """(3,) maximum |vx|, |vy|, |wz|."""
        return np.array([self.max_vx_mps, self.max_vy_mps, self.max_wz_radps])

    @property
    def max_accel(self) -> NDArray[np.float64]:
        """(3,) maximum |ax|, |ay|, |alpha|."""
        return np.array([self.max_ax_mps2, self.max_ay_mps2, self.max_alpha_radps2])


@dataclass(frozen=True)
class DriveTrain:
    """The motor, gearbox, encoder and wheel-speed loop as the vehicle controller firmware runs it.

    Attributes:
        encoder_lines: lines per motor revolution (counts per revolution are 4× in quadrature).
        gear_ratio: motor revolutions per wheel revolution.
        motor_time_constant_s: first-order lag of wheel speed to the drive command.
        speed_kp, speed_ki: PI gains of the wheel-speed loop (command in rad/s per rad/s error).
        control_rate_hz: rate of the firmware's speed loop and odometry.
    """

    encoder_lines: int
    gear_ratio: float
    motor_time_constant_s: float
    speed_kp: float
    speed_ki: float
    control_rate_hz: float = 100.0

    @property
    def counts_per_wheel_rev(self) -> float:
        """Quadrature counts per wheel revolution."""
        return 4.0 * self.encoder_lines * self.gear_ratio


@dataclass(frozen=True)
class ImuNoise:
    """Gyro and accelerometer noise (white noise σ per sample, constant bias)."""

    gyro_noise_radps: float = 0.002
    gyro_bias_radps: float = 0.001
    accel_noise_mps2: float = 0.02
    rate_hz: float = 100.0


@dataclass(frozen=True)
class RobotFootprint:
    """The robot's outline as a rectangle centred on ``base_link`` (seed 001: 60 cm a side).

    Navigation inflates obstacles by its circumscribed radius (or its inscribed one) and the
    twin's world checks it against the occupied cells.
    """

    length_m: float = 0.6
    width_m: float = 0.6


@dataclass(frozen=True)
class LidarMount:
    """Where the 2D LiDAR sits on the robot: its frame (``laser``) in ``base_link``.

    ``z_m`` is the scan plane's height (the twin's floor plans are 2D; ``omnical ros2 twin``
    publishes it in ``base_link → laser`` on ``/tf_static``).
    """

    x_m: float = 0.0
    y_m: float = 0.0
    z_m: float = 0.2
    yaw_rad: float = 0.0


@dataclass(frozen=True)
class RobotDescription:
    """Everything omnical needs to know about a robot."""

    name: str
    kind: str
    wheels: tuple[Wheel, ...]
    limits: Limits
    drive_train: DriveTrain
    imu: ImuNoise = field(default_factory=ImuNoise)
    hedge_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    dead_wheels: tuple[DeadWheel, ...] = ()
    footprint: RobotFootprint = field(default_factory=RobotFootprint)
    lidar_mount: LidarMount = field(default_factory=LidarMount)
    wheel_encoders: WheelEncoders | None = None
    odom_yaw_resolution_radps: float = 0.001
    """The smallest yaw rate the robot's odometry reports, rad/s (Wheeltec: 1 mrad/s); the
    calibration takes yaw rates up to 1.5 times this as none (0: yaw taken as recorded)."""

    @property
    def encoders(self) -> WheelEncoders:
        """The wheel encoders as a JointState reports them: :attr:`wheel_encoders`, else one
        joint per wheel named like the wheel, positions in radians."""
        if self.wheel_encoders is not None:
            return self.wheel_encoders
        return WheelEncoders(tuple(w.name for w in self.wheels))

    @property
    def wheel_count(self) -> int:
        """Number of driven wheels."""
        return len(self.wheels)
