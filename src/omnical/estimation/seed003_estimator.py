"""Seed 003's odometry as a running estimator: one sample in, one pose out (online and offline).

:class:`Seed003PoseSource` closes a control loop, :func:`seed003_track` replays a recording, bit for
bit the same; :func:`align_samples` builds the samples (dead wheels, gyro, accelerometer, field).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError
from omnical.estimation.se2 import Pose2, between, wrap_angle
from omnical.experiment.ports import RobotState
from omnical.recording.recording import Recording
from omnical.recording.topics import DEAD_WHEELS, IMU, IMU_MAG
from omnical.robot.description import DeadWheel

__all__ = [
    "SEED003_HEADING_GAIN",
    "Seed003Estimator",
    "Seed003Params",
    "Seed003PoseSource",
    "Seed003SampleSource",
    "Seed003Samples",
    "align_samples",
    "dead_wheel_measurement_matrix",
    "seed003_samples_of",
    "seed003_track",
]

F64 = NDArray[np.float64]

SEED003_HEADING_GAIN = 0.5
"""Weight of the encoder heading in seed 003's complementary filter (Eq. 17)."""


def dead_wheel_measurement_matrix(dead_wheels: Sequence[DeadWheel]) -> F64:
    """A (k, 3): each dead wheel's rolled distance from a body increment (dx, dy, dθ).

    Raises:
        ConfigError: the wheels cannot observe vx, vy and the yaw rate together (rank < 3).
    """
    rows = [
        (
            math.cos(d.direction_rad),
            math.sin(d.direction_rad),
            d.x_m * math.sin(d.direction_rad) - d.y_m * math.cos(d.direction_rad),
        )
        for d in dead_wheels
    ]
    A = np.array(rows, dtype=np.float64)
    if A.shape[0] < 3 or np.linalg.matrix_rank(A) < 3:
        msg = f"dead wheels: {len(rows)} encoders cannot observe vx, vy and yaw rate together"
        raise ConfigError(msg)
    return A


@dataclass(frozen=True)
class Seed003Params:
    """Settings of the seed 003 estimator.

    Attributes:
        heading_gain: g of Eq. 17, the weight of the encoder heading (the paper's 0.5).
        mag_gain: per-sample pull of the IMU yaw towards the magnetic yaw (0 = gyro only,
            1 = magnetometer only); 0.02 at 50 Hz is a 1 s time constant.
        tilt_compensation: use Eq. 7–8 tilt from the accelerometer in Eq. 11 (False: level).
    """

    heading_gain: float = SEED003_HEADING_GAIN
    mag_gain: float = 0.02
    tilt_compensation: bool = True

    def __post_init__(self) -> None:
        for name in ("heading_gain", "mag_gain"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                msg = f"{name} must be in [0, 1], got {value}"
                raise ConfigError(msg)


@dataclass(frozen=True, eq=False)
class Seed003Samples:
    """Time-aligned sensor samples, (N,) or (N, ·) arrays.

    Attributes:
        t_s: (N,) sample times, s.
        counts: (N, k) cumulative counts of the k dead wheels.
        gyro_z_radps: (N,) gyro z rate.
        accel_mps2: (N, 3) specific force in the body frame (z up: +g at rest).
        mag: (N, 3) magnetic field in the body frame (any unit).
    """

    t_s: F64
    counts: F64
    gyro_z_radps: F64
    accel_mps2: F64
    mag: F64

    def __post_init__(self) -> None:
        n = self.t_s.shape[0]
        shapes = (
            self.t_s.ndim == 1,
            self.counts.ndim == 2 and self.counts.shape[0] == n,
            self.gyro_z_radps.shape == (n,),
            self.accel_mps2.shape == (n, 3),
            self.mag.shape == (n, 3),
        )
        if not all(shapes):
            msg = (
                "seed 003 samples: expected t (N,), counts (N, k), gyro (N,), accel (N, 3), "
                f"mag (N, 3); got {self.t_s.shape}, {self.counts.shape}, "
                f"{self.gyro_z_radps.shape}, {self.accel_mps2.shape}, {self.mag.shape}"
            )
            raise ConfigError(msg)

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    def since(self, t_s: float) -> Seed003Samples:
        """The samples at or after ``t_s``."""
        keep = self.t_s >= t_s - 1e-9
        return Seed003Samples(
            self.t_s[keep],
            self.counts[keep],
            self.gyro_z_radps[keep],
            self.accel_mps2[keep],
            self.mag[keep],
        )


def _latest(t_from: F64, t_at: F64, what: str) -> NDArray[np.intp]:
    idx = np.searchsorted(t_from, t_at + 1e-9, side="right") - 1
    if idx.size and idx.min() < 0:
        msg = f"seed 003 samples: no {what} reading at or before t = {float(t_at[0]):.3f} s"
        raise ConfigError(msg)
    return idx


def align_samples(
    t_dead_s: ArrayLike,
    counts: ArrayLike,
    t_imu_s: ArrayLike,
    gyro_z_radps: ArrayLike,
    accel_mps2: ArrayLike,
    t_mag_s: ArrayLike,
    mag: ArrayLike,
) -> Seed003Samples:
    """Samples at the dead-wheel times with the latest IMU and magnetometer readings.

    Args:
        t_dead_s: (N,) dead-wheel sample times; counts: (N, k) cumulative counts.
        t_imu_s: (M,) increasing IMU times; gyro_z_radps: (M,); accel_mps2: (M, 3).
        t_mag_s: (L,) increasing magnetometer times; mag: (L, 3).

    Raises:
        ConfigError: shapes that do not match, or a dead-wheel sample before the first IMU or
            magnetometer reading.
    """
    td = np.asarray(t_dead_s, dtype=np.float64).reshape(-1)
    ti = np.asarray(t_imu_s, dtype=np.float64).reshape(-1)
    tm = np.asarray(t_mag_s, dtype=np.float64).reshape(-1)
    gz = np.asarray(gyro_z_radps, dtype=np.float64).reshape(-1)
    acc = np.asarray(accel_mps2, dtype=np.float64).reshape(-1, 3)
    m = np.asarray(mag, dtype=np.float64).reshape(-1, 3)
    if gz.shape[0] != ti.shape[0] or acc.shape[0] != ti.shape[0] or m.shape[0] != tm.shape[0]:
        msg = "seed 003 samples: IMU or magnetometer arrays of different lengths than their times"
        raise ConfigError(msg)
    c = np.asarray(counts, dtype=np.float64)
    c = c.reshape(td.shape[0], -1)
    ii = _latest(ti, td, "IMU")
    im = _latest(tm, td, "magnetometer")
    return Seed003Samples(td, c, gz[ii], acc[ii], m[im])


def _magnetic_yaw(mag: Sequence[float], acc: Sequence[float], tilt: bool) -> float:
    """Eq. 7–8 (tilt) and Eq. 11 (yaw, counter-clockwise from magnetic north)."""
    mx, my, mz = mag
    if tilt:
        fx, fy, fz = acc
        phi = math.atan2(fy, fz)
        theta = math.atan2(-fx, math.hypot(fy, fz))
    else:
        phi = theta = 0.0
    num = -my * math.cos(phi) + mz * math.sin(phi)
    den = (
        mx * math.cos(theta)
        + my * math.sin(theta) * math.sin(phi)
        + mz * math.sin(theta) * math.cos(phi)
    )
    return math.atan2(num, den)


class Seed003Estimator:
    """The recursive seed 003 estimator (docs/DESIGN-NOTES.md); poses in ``start_pose``'s frame.

    Args:
        dead_wheels: the dead-wheel layout (at least three, observing vx, vy and the yaw rate).
        params: filter settings.
        start_pose: pose at the first sample.

    Raises:
        ConfigError: a layout that cannot observe the planar motion.
    """

    def __init__(
        self,
        dead_wheels: Sequence[DeadWheel],
        params: Seed003Params | None = None,
        *,
        start_pose: Pose2 = (0.0, 0.0, 0.0),
    ) -> None:
        self.params = params or Seed003Params()
        a = dead_wheel_measurement_matrix(dead_wheels)
        solve = np.linalg.pinv(a)  # (3, k): body increment from the wheels' rolled distances
        per_count = [2.0 * math.pi * d.radius_m / d.counts_per_rev for d in dead_wheels]
        self._solve = tuple(
            tuple(float(v) * pc for v, pc in zip(row, per_count, strict=True)) for row in solve
        )
        self._k = len(dead_wheels)
        self._start = (float(start_pose[0]), float(start_pose[1]), float(start_pose[2]))
        self._pose = self._start
        self._t: float | None = None
        self._counts: tuple[float, ...] = ()
        self._gyro = 0.0
        self._theta_enc = self._start[2]
        self._imu_yaw = self._start[2]
        self._mag_offset = 0.0

    @property
    def pose(self) -> Pose2:
        """The current estimate (x m, y m, ψ rad)."""
        return self._pose

    @property
    def encoder_heading(self) -> float:
        """ϑ_rotary, rad (unwrapped)."""
        return self._theta_enc

    def feed(self, samples: Seed003Samples) -> list[tuple[float, float, float, float]]:
        """:meth:`update` with every sample in turn: (t_s, x, y, ψ) after each."""
        s = samples
        columns = (s.t_s, s.counts, s.gyro_z_radps, s.accel_mps2, s.mag)
        return [
            (t, *self.update(t, c, g, a, m))
            for t, c, g, a, m in zip(*(v.tolist() for v in columns), strict=True)
        ]

    def update(
        self,
        t_s: float,
        counts: Sequence[float],
        gyro_z_radps: float,
        accel_mps2: Sequence[float],
        mag: Sequence[float],
    ) -> Pose2:
        """Take one sample; the pose after it.

        Raises:
            ConfigError: a sample with the wrong number of encoders or going back in time.
        """
        if len(counts) != self._k:
            msg = f"seed 003 estimator: {len(counts)} counts for {self._k} dead wheels"
            raise ConfigError(msg)
        c = tuple(float(v) for v in counts)
        p = self.params
        yaw_mag = _magnetic_yaw(mag, accel_mps2, p.tilt_compensation)
        if self._t is None:
            self._t, self._counts, self._gyro = float(t_s), c, float(gyro_z_radps)
            self._mag_offset = self._start[2] - yaw_mag
            return self._pose
        dt = float(t_s) - self._t
        if not dt >= 0.0:
            msg = f"seed 003 estimator: sample at {t_s} s after one at {self._t} s"
            raise ConfigError(msg)
        d = [a - b for a, b in zip(c, self._counts, strict=True)]
        dx, dy, dth = (sum(r * v for r, v in zip(row, d, strict=True)) for row in self._solve)
        self._theta_enc += dth
        predicted = self._imu_yaw + 0.5 * (self._gyro + float(gyro_z_radps)) * dt
        self._imu_yaw = predicted + p.mag_gain * wrap_angle(yaw_mag + self._mag_offset - predicted)
        g = p.heading_gain
        x, y, psi_prev = self._pose
        psi = g * self._theta_enc + (1.0 - g) * self._imu_yaw
        mid = 0.5 * (psi_prev + psi)
        cm, sm = math.cos(mid), math.sin(mid)
        self._pose = (x + cm * dx - sm * dy, y + sm * dx + cm * dy, psi)
        self._t, self._counts, self._gyro = float(t_s), c, float(gyro_z_radps)
        return self._pose


def seed003_track(
    samples: Seed003Samples,
    dead_wheels: Sequence[DeadWheel],
    params: Seed003Params | None = None,
    *,
    start_pose: Pose2 = (0.0, 0.0, 0.0),
) -> F64:
    """The estimator over recorded samples: (N, 4) t_s, x, y, ψ (offline, same as online)."""
    rows = Seed003Estimator(dead_wheels, params, start_pose=start_pose).feed(samples)
    return np.array(rows, dtype=np.float64).reshape(-1, 4)


class Seed003SampleSource(Protocol):
    """Where the online estimator gets its samples (the twin's log, a live robot's topics)."""

    def poll(self) -> Seed003Samples:
        """The samples that arrived since the previous call, in time order."""


class Seed003PoseSource:
    """The seed 003 estimate as a loop pose source: ``RobotState → pose in the path frame``.

    Each call feeds the samples that arrived; the pose is in the frame of ``path_origin``.
    """

    def __init__(
        self,
        estimator: Seed003Estimator,
        samples: Seed003SampleSource,
        *,
        path_origin: Pose2 = (0.0, 0.0, 0.0),
    ) -> None:
        self.estimator = estimator
        self._samples = samples
        self._origin = path_origin
        self._log: list[tuple[float, float, float, float]] = []

    def __call__(self, robot_state: RobotState) -> Pose2:
        """Feed the new samples; the latest pose in the path frame."""
        self._log += self.estimator.feed(self._samples.poll())
        return between(self._origin, self.estimator.pose)

    def estimates(self) -> F64:
        """(N, 4) t_s, x, y, ψ of every sample so far, in the estimator's frame."""
        return np.array(self._log, dtype=np.float64).reshape(-1, 4)


def seed003_samples_of(
    recording: Recording,
    dead_wheels: Sequence[DeadWheel],
    *,
    since_s: float = 0.0,
    dead_wheel_topic: str = DEAD_WHEELS,
) -> Seed003Samples:
    """The seed 003 samples of a recording (a bag from the omni-X twin or a real robot).

    Dead-wheel JointState positions (rad, back to counts by ``counts_per_rev``), ``/imu`` and
    ``/imu/mag`` (any unit); times in seconds from the recording's first message, samples
    before ``since_s`` dropped.

    Raises:
        ConfigError: a topic is missing, or the dead wheels of the recording and of the robot
            description differ in number.
    """
    for topic in (dead_wheel_topic, IMU, IMU_MAG):
        if not recording.has(topic):
            msg = f"the seed 003 estimator needs {topic}: the recording has none"
            raise ConfigError(msg)
    t0 = recording.start_ns
    dead, imu, mag = (recording.topic(t) for t in (dead_wheel_topic, IMU, IMU_MAG))
    position = np.asarray(dead["position_rad"], dtype=np.float64)
    if position.ndim != 2 or position.shape[1] != len(dead_wheels):
        msg = (
            f"{dead_wheel_topic}: {position.shape[-1] if position.ndim == 2 else 0} joints, "
            f"the robot description has {len(dead_wheels)} dead wheels"
        )
        raise ConfigError(msg)
    per_rev = np.array([w.counts_per_rev for w in dead_wheels], dtype=np.float64)
    counts = np.round(position * per_rev / (2.0 * math.pi))
    accel = np.column_stack([imu["acc_x_mps2"], imu["acc_y_mps2"], imu["acc_z_mps2"]])
    field = np.column_stack([mag["mag_x_t"], mag["mag_y_t"], mag["mag_z_t"]])
    samples = align_samples(
        dead.t_s(t0), counts, imu.t_s(t0), imu["gyro_z_radps"], accel, mag.t_s(t0), field
    )
    return samples.since(since_s)
