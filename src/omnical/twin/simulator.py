"""The digital twin: a simulated omnidirectional base that implements the :class:`Robot` port.

At every simulation step (``TwinParams.step_hz``, ≥ 200 Hz) the true plant moves; at the vehicle
controller's rate the firmware runs as on the real board:

1. acceleration limiting of the commanded body twist (the limits of the robot description);
2. compensation with the installed correction factors (seed 000 §3.2.3), nominal inverse kinematics;
3. quantised quadrature encoders → measured wheel speeds;
4. per-wheel PI speed loop with feed-forward, driving a first-order motor lag;
5. wheel odometry: nominal forward kinematics (pseudo-inverse), counter-compensation, integration.

The true plant turns the real wheel rotation (after gearbox backlash, with per-wheel radius
errors) into a body twist through the true forward kinematics, then applies the seven-factor
truth (robot travels 1/k of what the wheels say, plus direction-dependent cross-talk yaw) and a
correlated random slip. Ground truth, odometry and IMU samples are logged at their rates.

The step loop is plain Python on floats: for four wheels it is several times faster than numpy
on tiny arrays (see ``bench/bench_twin.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from omnical.experiment.ports import RobotState
from omnical.kinematics.jacobian import forward_jacobian, inverse_jacobian
from omnical.robot.description import RobotDescription, Wheel
from omnical.twin.params import TwinParams

__all__ = ["DigitalTwin", "TwinLog"]

_GRAVITY_MPS2 = 9.80665
_FIELD_NORTH_G = 0.2
_FIELD_DOWN_G = 0.45
_MAG_NOISE_G = 0.002
_NOISE_BLOCK = 4096


@dataclass(frozen=True)
class TwinLog:
    """What the twin's sensors and the truth recorded, as (N, k) arrays with times in seconds.

    Attributes:
        odom: (N, 7) t_s, x_m, y_m, yaw_rad, vx_mps, vy_mps, wz_radps (odom frame, twist in base_link).
        ground_truth: (N, 7) same layout, map frame.
        imu: (N, 7) t_s, gyro x/y/z rad/s, acc x/y/z m/s² (base_link).
        dead_wheel_counts: (N, 1 + k) t_s and the cumulative counts of the k dead-wheel encoders
            (seed 003's external encoders), at the odometry rate; (0, 1) without dead wheels.
        magnetometer: (N, 4) t_s and the magnetic field in base_link, x/y/z in gauss, at the IMU
            rate (a level robot in a field of 0.2 G north, 0.45 G down, north = map +x).
    """

    odom: NDArray[np.float64]
    ground_truth: NDArray[np.float64]
    imu: NDArray[np.float64]
    dead_wheel_counts: NDArray[np.float64]
    magnetometer: NDArray[np.float64]


def _rows(J: NDArray[np.float64]) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(v) for v in row) for row in J)


class DigitalTwin:
    """A simulated base; deterministic for a given ``seed``."""

    def __init__(self, robot: RobotDescription, params: TwinParams, *, seed: int = 0) -> None:
        self.robot = robot
        self.params = params
        n = robot.wheel_count
        self._n = n
        J = inverse_jacobian(robot.wheels)
        self._J = _rows(J)
        self._Jp = _rows(forward_jacobian(J))
        errors = params.wheel_radius_errors or (0.0,) * n
        true_wheels = [
            Wheel(
                w.name,
                w.x_m,
                w.y_m,
                w.roller_angle_rad,
                w.radius_m * (1.0 + e),
                w.drive_direction_rad,
            )
            for w, e in zip(robot.wheels, errors, strict=True)
        ]
        self._Jp_true = _rows(forward_jacobian(inverse_jacobian(true_wheels)))
        self._dt = 1.0 / params.step_hz
        dtr = robot.drive_train
        self._ctrl_every = max(1, round(params.step_hz / dtr.control_rate_hz))
        self._dt_c = self._ctrl_every * self._dt
        self._odom_every = max(1, round(params.step_hz / params.odom_rate_hz))
        self._gt_every = max(1, round(params.step_hz / params.ground_truth_rate_hz))
        self._imu_every = max(1, round(params.step_hz / robot.imu.rate_hz))
        self._alpha_motor = 1.0 - math.exp(-self._dt / dtr.motor_time_constant_s)
        self._cpr = dtr.counts_per_wheel_rev
        self._rad_per_count = 2.0 * math.pi / self._cpr
        lim = robot.limits
        self._amax = (lim.max_ax_mps2, lim.max_ay_mps2, lim.max_alpha_radps2)
        self._vmax = (lim.max_vx_mps, lim.max_vy_mps, lim.max_wz_radps)
        self._wheel_max = 1.25 * max(
            sum(abs(a) * b for a, b in zip(row, self._vmax, strict=True)) for row in self._J
        )
        self._rng = np.random.default_rng(seed)
        self._noise = self._rng.standard_normal((_NOISE_BLOCK, 6))
        self._noise_i = 0
        self._bias = (
            robot.imu.gyro_bias_radps if params.gyro_bias_radps is None else params.gyro_bias_radps
        )
        # state
        self._k = 0
        self._cmd = [0.0, 0.0, 0.0]
        self._tgt = [0.0, 0.0, 0.0]
        self._u = [0.0] * n
        self._wm = [0.0] * n
        self._th_m = [0.0] * n
        self._th_w = [0.0] * n
        self._counts_prev = [0] * n
        self._integ = [0.0] * n
        self._ref_prev = [0.0] * n
        self._meas = [0.0] * n
        self._odom = [0.0, 0.0, 0.0]
        self._odom_tw = (0.0, 0.0, 0.0)
        x0, y0, yaw0 = params.start_pose_map
        self._gt = [x0, y0, yaw0]
        self._gt_tw = (0.0, 0.0, 0.0)
        self._imu_prev_v = (0.0, 0.0)
        self._gyro_z = 0.0
        self._slip = [0.0, 0.0, 0.0]
        self._log_odom: list[tuple[float, ...]] = []
        self._log_gt: list[tuple[float, ...]] = []
        self._log_imu: list[tuple[float, ...]] = []
        self._dead = tuple(
            (
                d.x_m,
                d.y_m,
                math.cos(d.direction_rad),
                math.sin(d.direction_rad),
                d.radius_m,
                d.counts_per_rev,
            )
            for d in robot.dead_wheels
        )
        self._dead_angle = [0.0] * len(self._dead)
        self._log_dead: list[tuple[float, ...]] = []
        self._log_mag: list[tuple[float, ...]] = []
        self._log_sample(0)

    # ----------------------------------------------------------------- Robot port
    def send_twist(self, vx_mps: float, vy_mps: float, wz_radps: float) -> None:
        """Command a body twist; the firmware ramps to it at the robot's acceleration limits."""
        self._cmd = [
            max(-self._vmax[0], min(self._vmax[0], vx_mps)),
            max(-self._vmax[1], min(self._vmax[1], vy_mps)),
            max(-self._vmax[2], min(self._vmax[2], wz_radps)),
        ]

    def read_state(self) -> RobotState:
        """The latest odometry, wheel speeds and gyro reading."""
        return RobotState(
            t_s=self.t_s,
            odom_pose=(self._odom[0], self._odom[1], self._odom[2]),
            odom_twist=self._odom_tw,
            wheel_speeds_radps=tuple(self._meas),
            gyro_z_radps=self._gyro_z,
        )

    def stop(self) -> None:
        """Command zero twist (the firmware still decelerates at its limits)."""
        self._cmd = [0.0, 0.0, 0.0]

    # ----------------------------------------------------------------- simulation
    @property
    def t_s(self) -> float:
        """Simulated time in seconds."""
        return self._k * self._dt

    @property
    def ground_truth_pose(self) -> tuple[float, float, float]:
        """True (x, y, yaw) of base_link in the map frame."""
        return (self._gt[0], self._gt[1], self._gt[2])

    def advance_to(self, t_s: float) -> None:
        """Simulate until the twin's clock reaches ``t_s`` (to the nearest step)."""
        target = round(t_s / self._dt)
        while self._k < target:
            self._step()

    def log(self) -> TwinLog:
        """Everything logged so far."""
        return TwinLog(
            odom=np.array(self._log_odom, dtype=np.float64).reshape(-1, 7),
            ground_truth=np.array(self._log_gt, dtype=np.float64).reshape(-1, 7),
            imu=np.array(self._log_imu, dtype=np.float64).reshape(-1, 7),
            dead_wheel_counts=np.array(self._log_dead, dtype=np.float64).reshape(
                -1, 1 + len(self._dead)
            ),
            magnetometer=np.array(self._log_mag, dtype=np.float64).reshape(-1, 4),
        )

    def _normal(self) -> list[float]:
        if self._noise_i >= _NOISE_BLOCK:
            self._noise = self._rng.standard_normal((_NOISE_BLOCK, 6))
            self._noise_i = 0
        row = self._noise[self._noise_i].tolist()
        self._noise_i += 1
        return row  # type: ignore[no-any-return]

    def _firmware_tick(self) -> None:
        dt_c = self._dt_c
        tgt = self._tgt
        for k in range(3):
            lim = self._amax[k] * dt_c
            d = self._cmd[k] - tgt[k]
            tgt[k] += lim if d > lim else (-lim if d < -lim else d)
        f = self.params.installed_factors
        cx, cy, cw = tgt
        cw -= (
            f.crosstalk_forward_rad_per_m * max(cx, 0.0)
            + f.crosstalk_reverse_rad_per_m * max(-cx, 0.0)
            + f.crosstalk_left_rad_per_m * max(cy, 0.0)
            + f.crosstalk_right_rad_per_m * max(-cy, 0.0)
        )
        cx *= f.scale_longitudinal
        cy *= f.scale_lateral
        cw *= f.scale_rotational
        dtr = self.robot.drive_train
        kp, ki, wmax = dtr.speed_kp, dtr.speed_ki, self._wheel_max
        tau = dtr.motor_time_constant_s
        cpr, rpc = self._cpr, self._rad_per_count
        meas = self._meas
        for i in range(self._n):
            row = self._J[i]
            ref = row[0] * cx + row[1] * cy + row[2] * cw
            counts = math.floor(self._th_m[i] * cpr / (2.0 * math.pi))
            meas[i] = (counts - self._counts_prev[i]) * rpc / dt_c
            self._counts_prev[i] = counts
            # feed-forward through the inverse of the motor lag, PI on the measured error
            ff = ref + tau * (ref - self._ref_prev[i]) / dt_c
            self._ref_prev[i] = ref
            e = ref - meas[i]
            integ = self._integ[i] + e * dt_c
            u = ff + kp * e + ki * integ
            if u > wmax or u < -wmax:  # anti-windup: hold the integrator while saturated
                u = wmax if u > 0 else -wmax
            else:
                self._integ[i] = integ
            self._u[i] = u
        # wheel odometry as the vehicle controller computes it
        Jp = self._Jp
        mx = sum(Jp[0][i] * meas[i] for i in range(self._n))
        my = sum(Jp[1][i] * meas[i] for i in range(self._n))
        mw = sum(Jp[2][i] * meas[i] for i in range(self._n))
        mx /= f.scale_longitudinal
        my /= f.scale_lateral
        mw /= f.scale_rotational
        mw += (
            f.crosstalk_forward_rad_per_m * max(mx, 0.0)
            + f.crosstalk_reverse_rad_per_m * max(-mx, 0.0)
            + f.crosstalk_left_rad_per_m * max(my, 0.0)
            + f.crosstalk_right_rad_per_m * max(-my, 0.0)
        )
        o = self._odom
        yaw_mid = o[2] + 0.5 * mw * dt_c
        c, s = math.cos(yaw_mid), math.sin(yaw_mid)
        o[0] += (mx * c - my * s) * dt_c
        o[1] += (mx * s + my * c) * dt_c
        o[2] += mw * dt_c
        self._odom_tw = (mx, my, mw)

    def _step(self) -> None:
        if self._k % self._ctrl_every == 0:
            self._firmware_tick()
        dt = self._dt
        p = self.params
        a = self._alpha_motor
        half_play = 0.5 * p.backlash_rad
        n = self._n
        ww = [0.0] * n
        for i in range(n):
            wm = self._wm[i] + (self._u[i] - self._wm[i]) * a
            self._wm[i] = wm
            th = self._th_m[i] + wm * dt
            self._th_m[i] = th
            tw = self._th_w[i]
            gap = th - tw
            if gap > half_play:
                new = th - half_play
            elif gap < -half_play:
                new = th + half_play
            else:
                new = tw
            ww[i] = (new - tw) / dt
            self._th_w[i] = new
        Jp = self._Jp_true
        tx = sum(Jp[0][i] * ww[i] for i in range(n))
        ty = sum(Jp[1][i] * ww[i] for i in range(n))
        tr = sum(Jp[2][i] * ww[i] for i in range(n))
        f = p.true_factors
        vx = tx / f.scale_longitudinal
        vy = ty / f.scale_lateral
        wz = tr / f.scale_rotational + (
            f.crosstalk_forward_rad_per_m * max(vx, 0.0)
            + f.crosstalk_reverse_rad_per_m * max(-vx, 0.0)
            + f.crosstalk_left_rad_per_m * max(vy, 0.0)
            + f.crosstalk_right_rad_per_m * max(-vy, 0.0)
        )
        noise = self._normal()
        if p.slip_sigma > 0.0:
            decay = dt / p.slip_correlation_s
            drive = p.slip_sigma * math.sqrt(2.0 * decay)
            sl = self._slip
            for k in range(3):
                sl[k] += -sl[k] * decay + drive * noise[k]
            wz = wz * (1.0 + sl[2]) + 0.1 * sl[2] * (abs(vx) + abs(vy))
            vx *= 1.0 + sl[0]
            vy *= 1.0 + sl[1]
        g = self._gt
        yaw_mid = g[2] + 0.5 * wz * dt
        c, s = math.cos(yaw_mid), math.sin(yaw_mid)
        g[0] += (vx * c - vy * s) * dt
        g[1] += (vx * s + vy * c) * dt
        g[2] += wz * dt
        self._gt_tw = (vx, vy, wz)
        for j, (dx, dy, cphi, sphi, radius, _) in enumerate(self._dead):
            along = cphi * (vx - dy * wz) + sphi * (vy + dx * wz)
            self._dead_angle[j] += along * dt / radius
        self._k += 1
        self._log_sample(self._k, noise)

    def _log_sample(self, k: int, noise: list[float] | None = None) -> None:
        t = k * self._dt
        if k % self._odom_every == 0:
            o, tw = self._odom, self._odom_tw
            self._log_odom.append((t, o[0], o[1], o[2], tw[0], tw[1], tw[2]))
            if self._dead:
                self._log_dead.append(
                    (
                        t,
                        *(
                            float(math.floor(a * d[5] / (2.0 * math.pi)))
                            for a, d in zip(self._dead_angle, self._dead, strict=True)
                        ),
                    )
                )
        if k % self._gt_every == 0:
            g, tw = self._gt, self._gt_tw
            self._log_gt.append((t, g[0], g[1], g[2], tw[0], tw[1], tw[2]))
        if k % self._imu_every == 0:
            vx, vy, wz = self._gt_tw
            pvx, pvy = self._imu_prev_v
            dt_imu = self._imu_every * self._dt
            ax = (vx - pvx) / dt_imu - wz * vy
            ay = (vy - pvy) / dt_imu + wz * vx
            self._imu_prev_v = (vx, vy)
            sg = self.robot.imu.gyro_noise_radps if self.params.imu_noise else 0.0
            sa = self.robot.imu.accel_noise_mps2 if self.params.imu_noise else 0.0
            nz = noise if noise is not None else [0.0] * 6
            self._gyro_z = wz + self._bias + sg * nz[3]
            if self._dead:  # the 9-DoF IMU of seed 003's omni-X robot
                yaw = self._gt[2]
                sm = _MAG_NOISE_G if self.params.imu_noise else 0.0
                self._log_mag.append(
                    (
                        t,
                        _FIELD_NORTH_G * math.cos(yaw) + sm * nz[0],
                        -_FIELD_NORTH_G * math.sin(yaw) + sm * nz[1],
                        _FIELD_DOWN_G + sm * nz[2],
                    )
                )
            self._log_imu.append(
                (
                    t,
                    sg * nz[4],
                    sg * nz[5],
                    self._gyro_z,
                    ax + sa * nz[4],
                    ay + sa * nz[5],
                    _GRAVITY_MPS2 + sa * nz[3],
                )
            )
