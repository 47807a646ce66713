"""The digital twin: a simulated omnidirectional base that implements the :class:`Robot` port.

:class:`DigitalTwin` moves the true plant and runs the firmware at its rates, in Python or
compiled (``engine``, bit-identical logs). The model: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray

from omnical.errors import ConfigError
from omnical.experiment.ports import RobotState
from omnical.kinematics.correction import compensate_twist_scalar, counter_compensate_twist_scalar
from omnical.kinematics.jacobian import forward_jacobian, inverse_jacobian
from omnical.robot.description import RobotDescription
from omnical.twin.noise import NoiseChannel, NoiseStream
from omnical.twin.params import StepModel, TwinEngine, TwinParams, compiled_engine
from omnical.twin.wheel_motor import motor_decay, motor_speed_step

if TYPE_CHECKING:
    from omnical.twin._kernel import CompiledCore

__all__ = [
    "DigitalTwin",
    "ImuColumn",
    "MagnetometerColumn",
    "StateColumn",
    "TwinLog",
    "step_model",
    "wheel_command_limit",
]

_GRAVITY_MPS2 = 9.80665
_FIELD_NORTH_G = 0.2
_FIELD_DOWN_G = 0.45
_MAG_NOISE_G = 0.002
_ZERO3 = (0.0, 0.0, 0.0)
_NOISE_CHANNELS = (
    NoiseChannel.SLIP,
    NoiseChannel.GYRO,
    NoiseChannel.ACCEL,
    NoiseChannel.MAGNETOMETER,
)


class StateColumn(enum.IntEnum):
    """Columns of :attr:`TwinLog.odom` and :attr:`TwinLog.ground_truth`."""

    T_S = 0
    X_M = 1
    Y_M = 2
    YAW_RAD = 3
    VX_MPS = 4
    VY_MPS = 5
    WZ_RADPS = 6


class ImuColumn(enum.IntEnum):
    """Columns of :attr:`TwinLog.imu`."""

    T_S = 0
    GYRO_X_RADPS = 1
    GYRO_Y_RADPS = 2
    GYRO_Z_RADPS = 3
    ACC_X_MPS2 = 4
    ACC_Y_MPS2 = 5
    ACC_Z_MPS2 = 6


class MagnetometerColumn(enum.IntEnum):
    """Columns of :attr:`TwinLog.magnetometer`."""

    T_S = 0
    X_G = 1
    Y_G = 2
    Z_G = 3


_POSE = slice(StateColumn.X_M, StateColumn.YAW_RAD + 1)
_TWIST = slice(StateColumn.VX_MPS, StateColumn.WZ_RADPS + 1)
_GYRO = slice(ImuColumn.GYRO_X_RADPS, ImuColumn.GYRO_Z_RADPS + 1)
_ACC = slice(ImuColumn.ACC_X_MPS2, ImuColumn.ACC_Z_MPS2 + 1)


@dataclass(frozen=True)
class TwinLog:
    """What the twin's sensors and the truth recorded, as (N, k) arrays with times in seconds.

    The columns are named by :class:`StateColumn`, :class:`ImuColumn` and
    :class:`MagnetometerColumn`; the properties give the usual slices by name.

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

    @property
    def odom_t_s(self) -> NDArray[np.float64]:
        """(N,) times of the odometry samples, s."""
        return self.odom[:, StateColumn.T_S]

    @property
    def odom_pose(self) -> NDArray[np.float64]:
        """(N, 3) odometry x_m, y_m, yaw_rad in the odom frame."""
        return self.odom[:, _POSE]

    @property
    def odom_twist(self) -> NDArray[np.float64]:
        """(N, 3) odometry vx_mps, vy_mps, wz_radps in base_link."""
        return self.odom[:, _TWIST]

    @property
    def ground_truth_t_s(self) -> NDArray[np.float64]:
        """(N,) times of the ground-truth samples, s."""
        return self.ground_truth[:, StateColumn.T_S]

    @property
    def ground_truth_pose(self) -> NDArray[np.float64]:
        """(N, 3) true x_m, y_m, yaw_rad of base_link in the map frame."""
        return self.ground_truth[:, _POSE]

    @property
    def ground_truth_twist(self) -> NDArray[np.float64]:
        """(N, 3) true vx_mps, vy_mps, wz_radps in base_link."""
        return self.ground_truth[:, _TWIST]

    @property
    def imu_t_s(self) -> NDArray[np.float64]:
        """(N,) times of the IMU samples, s."""
        return self.imu[:, ImuColumn.T_S]

    @property
    def gyro_radps(self) -> NDArray[np.float64]:
        """(N, 3) gyro x, y, z in base_link, rad/s."""
        return self.imu[:, _GYRO]

    @property
    def accel_mps2(self) -> NDArray[np.float64]:
        """(N, 3) accelerometer x, y, z in base_link, m/s² (gravity included)."""
        return self.imu[:, _ACC]

    @property
    def magnetometer_t_s(self) -> NDArray[np.float64]:
        """(N,) times of the magnetometer samples, s."""
        return self.magnetometer[:, MagnetometerColumn.T_S]

    @property
    def magnetic_field_g(self) -> NDArray[np.float64]:
        """(N, 3) magnetic field x, y, z in base_link, gauss."""
        return self.magnetometer[:, MagnetometerColumn.X_G :]

    @property
    def dead_wheel_t_s(self) -> NDArray[np.float64]:
        """(N,) times of the dead-wheel samples, s."""
        return self.dead_wheel_counts[:, 0]

    @property
    def dead_wheel_cumulative_counts(self) -> NDArray[np.float64]:
        """(N, k) cumulative counts of the k dead-wheel encoders."""
        return self.dead_wheel_counts[:, 1:]


def _rows(J: NDArray[np.float64]) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(v) for v in row) for row in J)


def wheel_command_limit(robot: RobotDescription) -> float:
    """The firmware's limit on each wheel's drive command, rad/s: 1.25 × the largest wheel
    speed the robot's twist limits ask for (the output saturation of its wheel-speed loops)."""
    rows = _rows(inverse_jacobian(robot.wheels))
    lim = robot.limits
    vmax = (lim.max_vx_mps, lim.max_vy_mps, lim.max_wz_radps)
    return 1.25 * max(sum(abs(a) * b for a, b in zip(row, vmax, strict=True)) for row in rows)


def step_model(robot: RobotDescription, params: TwinParams) -> StepModel:
    """The constants of the step loop of ``robot``'s twin with ``params``."""
    n = robot.wheel_count
    J = inverse_jacobian(robot.wheels)
    errors = params.wheel_radius_errors or (0.0,) * n
    true_wheels = [
        replace(w, radius_m=w.radius_m * (1.0 + e))
        for w, e in zip(robot.wheels, errors, strict=True)
    ]
    dt = 1.0 / params.step_hz
    dtr, lim, imu = robot.drive_train, robot.limits, robot.imu
    ctrl_every = max(1, round(params.step_hz / dtr.control_rate_hz))
    motors = params.wheel_motors(dtr, n)
    slip_on = params.slip_sigma > 0.0
    slip_decay = dt / params.slip_correlation_s if slip_on else 0.0
    radii = params.dead_wheel_effective_radii(robot.dead_wheels)
    bias = params.gyro_bias_radps
    return StepModel(
        dt=dt,
        dt_c=ctrl_every * dt,
        ctrl_every=ctrl_every,
        odom_every=max(1, round(params.step_hz / params.odom_rate_hz)),
        gt_every=max(1, round(params.step_hz / params.ground_truth_rate_hz)),
        imu_every=max(1, round(params.step_hz / imu.rate_hz)),
        amax=(lim.max_ax_mps2, lim.max_ay_mps2, lim.max_alpha_radps2),
        vmax=(lim.max_vx_mps, lim.max_vy_mps, lim.max_wz_radps),
        wheel_max=wheel_command_limit(robot),
        kp=dtr.speed_kp,
        ki=dtr.speed_ki,
        tau=dtr.motor_time_constant_s,
        cpr=dtr.counts_per_wheel_rev,
        rad_per_count=2.0 * math.pi / dtr.counts_per_wheel_rev,
        installed=params.installed_factors,
        true=params.true_factors,
        half_play=0.5 * params.backlash_rad,
        slip_on=slip_on,
        slip_decay=slip_decay,
        slip_drive=params.slip_sigma * math.sqrt(2.0 * slip_decay) if slip_on else 0.0,
        gyro_bias=imu.gyro_bias_radps if bias is None else bias,
        gyro_sigma=imu.gyro_noise_radps,
        accel_sigma=imu.accel_noise_mps2,
        imu_noise=params.imu_noise,
        J=_rows(J),
        Jp=_rows(forward_jacobian(J)),
        Jp_true=_rows(forward_jacobian(inverse_jacobian(true_wheels))),
        motors=motors,
        motor_decay=tuple(motor_decay(m, dt) for m in motors),
        dead_wheels=tuple(
            (
                d.x_m,
                d.y_m,
                math.cos(d.direction_rad),
                math.sin(d.direction_rad),
                r,
                d.counts_per_rev,
            )
            for d, r in zip(robot.dead_wheels, radii, strict=True)
        ),
        start_pose=params.start_pose_map,
        pid=params.firmware_pid(ctrl_every * dt),
    )


class DigitalTwin:
    """A simulated base; deterministic for a given ``seed``.

    Args:
        robot: the robot description (nominal kinematics, drive train, limits, IMU).
        params: the twin's imperfections and rates.
        seed: seed of the named noise streams.
        engine: ``"compiled"``, ``"python"`` (the reference) or ``"auto"``; None =
            ``params.engine``. Both give the same logs.

    Raises:
        ConfigError: an unknown engine.
    """

    def __init__(
        self,
        robot: RobotDescription,
        params: TwinParams,
        *,
        seed: int = 0,
        engine: TwinEngine | None = None,
    ) -> None:
        chosen = params.engine if engine is None else engine
        self.engine: Literal["compiled", "python"] = (
            "compiled" if compiled_engine(chosen, "twin") else "python"
        )
        self.robot = robot
        self.params = params
        self._model = m = step_model(robot, params)
        self._n = n = robot.wheel_count
        self._dt = m.dt
        # slip, gyro, accel, magnetometer: the order of the compiled core
        self._noise = tuple(NoiseStream(seed, c) for c in _NOISE_CHANNELS)
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
        self._deriv = [0.0] * n
        self._meas_prev = [0.0] * n
        self._odom = [0.0, 0.0, 0.0]
        self._odom_tw = (0.0, 0.0, 0.0)
        self._gt = list(m.start_pose)
        self._gt_tw = (0.0, 0.0, 0.0)
        self._imu_prev_v = (0.0, 0.0)
        self._gyro_z = 0.0
        self._slip = [0.0, 0.0, 0.0]
        self._dead_angle = [0.0] * len(m.dead_wheels)
        # the Python reference's logs: odometry, truth, IMU, dead wheels, magnetometer
        self._logs: tuple[list[tuple[float, ...]], ...] = ([], [], [], [], [])
        self._log_odom, self._log_gt, self._log_imu, self._log_dead, self._log_mag = self._logs
        self._core: CompiledCore | None = None
        if self.engine == "compiled":
            from omnical.twin._kernel import CompiledCore

            self._core = CompiledCore(m, self._noise)
        else:
            self._log_sample(0)

    # ----------------------------------------------------------------- Robot port
    def send_twist(self, vx_mps: float, vy_mps: float, wz_radps: float) -> None:
        """Command a body twist; the firmware ramps to it at the robot's acceleration limits.

        Numbers of any real type are taken as Python floats (numpy scalars stop here).
        """
        vmax = self._model.vmax
        cmd = [
            max(-vmax[0], min(vmax[0], float(vx_mps))),
            max(-vmax[1], min(vmax[1], float(vy_mps))),
            max(-vmax[2], min(vmax[2], float(wz_radps))),
        ]
        if self._core is not None:
            self._core.set_command(cmd[0], cmd[1], cmd[2])
        self._cmd = cmd

    def read_state(self) -> RobotState:
        """The latest odometry, wheel speeds and gyro reading (Python floats)."""
        if self._core is not None:
            pose, twist, wheels, gyro_z = self._core.robot_state()
            return RobotState(
                t_s=self.t_s,
                odom_pose=pose,
                odom_twist=twist,
                wheel_speeds_radps=wheels,
                gyro_z_radps=gyro_z,
            )
        return RobotState(
            t_s=self.t_s,
            odom_pose=(self._odom[0], self._odom[1], self._odom[2]),
            odom_twist=self._odom_tw,
            wheel_speeds_radps=tuple(self._meas),
            gyro_z_radps=self._gyro_z,
        )

    def stop(self) -> None:
        """Command zero twist (the firmware still decelerates at its limits)."""
        self.send_twist(0.0, 0.0, 0.0)

    # ----------------------------------------------------------------- simulation
    @property
    def t_s(self) -> float:
        """Simulated time in seconds."""
        return self._k * self._dt

    @property
    def ground_truth_pose(self) -> tuple[float, float, float]:
        """True (x, y, yaw) of base_link in the map frame."""
        if self._core is not None:
            return self._core.ground_truth_pose()
        return (self._gt[0], self._gt[1], self._gt[2])

    def advance_to(self, t_s: float) -> None:
        """Simulate until the twin's clock reaches ``t_s`` (to the nearest step)."""
        target = round(float(t_s) / self._dt)
        if self._k >= target:
            return
        if self._core is not None:
            self._core.advance(target)
            self._k = target
            return
        while self._k < target:
            self._step()

    def play(self, twists: NDArray[np.float64], wake_s: NDArray[np.float64]) -> None:
        """Play timed commands: for each i, ``send_twist(*twists[i])`` then ``advance_to(wake_s[i])``.

        The compiled engine runs the whole block in one kernel call; the result is the same.

        Args:
            twists: (N, 3) body twists vx m/s, vy m/s, wz rad/s.
            wake_s: (N,) simulated time to advance to after each command, s.
        """
        tw = np.ascontiguousarray(twists, dtype=np.float64).reshape(-1, 3)
        wake = np.asarray(wake_s, dtype=np.float64).reshape(-1)
        if len(tw) != len(wake):
            msg = f"play: {len(tw)} twists for {len(wake)} wake times"
            raise ConfigError(msg)
        if len(tw) == 0:
            return
        if self._core is None:
            for (vx, vy, wz), t in zip(tw.tolist(), wake.tolist(), strict=True):
                self.send_twist(vx, vy, wz)
                self.advance_to(t)
            return
        targets = np.round(wake / self._dt).astype(np.int64)
        self._cmd = self._core.play(tw, targets)
        self._k = self._core.step

    def log(self) -> TwinLog:
        """Everything logged so far."""
        return TwinLog(*self._log_rows((0, 0, 0, 0, 0)))

    def log_since(self, odom_from: int, ground_truth_from: int, imu_from: int) -> TwinLog:
        """The odometry, ground-truth and IMU rows logged after the first ``*_from`` rows (a live
        reader's tail, e.g. ``omnical ros2 twin``); no dead-wheel or magnetometer rows."""
        skip = (len(self._log_dead), len(self._log_mag))  # not returned: not converted
        odom, gt, imu, _, _ = self._log_rows((odom_from, ground_truth_from, imu_from, *skip))
        return TwinLog(odom, gt, imu, np.zeros((0, 1)), np.zeros((0, 4)))

    def _log_rows(self, starts: tuple[int, ...]) -> tuple[NDArray[np.float64], ...]:
        """The five logs from row ``starts[i]`` on, as (N, k) arrays."""
        if self._core is not None:
            return tuple(a[s:] for a, s in zip(self._core.log_arrays(), starts, strict=True))
        widths = (7, 7, 7, 1 + len(self._model.dead_wheels), 4)
        return tuple(
            np.array(rows[s:], dtype=np.float64).reshape(-1, w)
            for rows, s, w in zip(self._logs, starts, widths, strict=True)
        )

    def _pid_tick(self, i: int, ref: float, meas: float, dt_c: float, wmax: float) -> float:
        """The installed PID of wheel ``i``: :func:`omnical.control.pid.pid_step`'s law with
        conditional anti-windup at the firmware's output limit, no feed-forward (seed 003 Fig. 4).
        """
        kp, ki_dt, kptd, tf = self._model.pid  # type: ignore[misc]
        e = ref - meas
        deriv = self._deriv[i]
        if kptd > 0.0:
            dy = meas - self._meas_prev[i]
            deriv = (tf * deriv - kptd * dy) / (tf + dt_c)
        self._deriv[i] = deriv
        self._meas_prev[i] = meas
        integ = self._integ[i]
        raw = kp * e + integ + deriv
        u = raw
        if u > wmax:
            u = wmax
        elif u < -wmax:
            u = -wmax
        increment = ki_dt * e
        if u == raw or increment * (raw - u) < 0.0:
            self._integ[i] = integ + increment
        return u

    def _firmware_tick(self) -> None:
        m = self._model
        dt_c = m.dt_c
        tgt = self._tgt
        for k in range(3):
            lim = m.amax[k] * dt_c
            d = self._cmd[k] - tgt[k]
            tgt[k] += lim if d > lim else (-lim if d < -lim else d)
        cx, cy, cw = compensate_twist_scalar(tgt[0], tgt[1], tgt[2], m.installed)
        kp, ki, wmax, tau = m.kp, m.ki, m.wheel_max, m.tau
        cpr, rpc = m.cpr, m.rad_per_count
        meas = self._meas
        for i in range(self._n):
            row = m.J[i]
            ref = row[0] * cx + row[1] * cy + row[2] * cw
            counts = math.floor(self._th_m[i] * cpr / (2.0 * math.pi))
            meas[i] = (counts - self._counts_prev[i]) * rpc / dt_c
            self._counts_prev[i] = counts
            if m.pid is not None:
                u = self._pid_tick(i, ref, meas[i], dt_c, wmax)
            else:
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
        Jp = m.Jp
        mx, my, mw = counter_compensate_twist_scalar(
            sum(Jp[0][i] * meas[i] for i in range(self._n)),
            sum(Jp[1][i] * meas[i] for i in range(self._n)),
            sum(Jp[2][i] * meas[i] for i in range(self._n)),
            m.installed,
        )
        o = self._odom
        yaw_mid = o[2] + 0.5 * mw * dt_c
        c, s = math.cos(yaw_mid), math.sin(yaw_mid)
        o[0] += (mx * c - my * s) * dt_c
        o[1] += (mx * s + my * c) * dt_c
        o[2] += mw * dt_c
        self._odom_tw = (mx, my, mw)

    def _step(self) -> None:
        m = self._model
        if self._k % m.ctrl_every == 0:
            self._firmware_tick()
        dt = m.dt
        half_play = m.half_play
        n = self._n
        ww = [0.0] * n
        for i in range(n):
            wm = motor_speed_step(self._wm[i], self._u[i], m.motors[i], m.motor_decay[i])
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
        Jp = m.Jp_true
        tx = sum(Jp[0][i] * ww[i] for i in range(n))
        ty = sum(Jp[1][i] * ww[i] for i in range(n))
        tr = sum(Jp[2][i] * ww[i] for i in range(n))
        # the seven-factor truth: the model of counter-compensation, with the true factors
        vx, vy, wz = counter_compensate_twist_scalar(tx, ty, tr, m.true)
        if m.slip_on:
            sl = self._slip
            noise = self._noise[0].next3()
            for k in range(3):
                sl[k] += -sl[k] * m.slip_decay + m.slip_drive * noise[k]
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
        for j, (dx, dy, cphi, sphi, radius, _) in enumerate(m.dead_wheels):
            along = cphi * (vx - dy * wz) + sphi * (vy + dx * wz)
            self._dead_angle[j] += along * dt / radius
        self._k += 1
        self._log_sample(self._k)

    def _log_sample(self, k: int) -> None:
        m = self._model
        t = k * m.dt
        if k % m.odom_every == 0:
            o, tw = self._odom, self._odom_tw
            self._log_odom.append((t, o[0], o[1], o[2], tw[0], tw[1], tw[2]))
            if m.dead_wheels:
                self._log_dead.append(
                    (
                        t,
                        *(
                            float(math.floor(a * d[5] / (2.0 * math.pi)))
                            for a, d in zip(self._dead_angle, m.dead_wheels, strict=True)
                        ),
                    )
                )
        if k % m.gt_every == 0:
            g, tw = self._gt, self._gt_tw
            self._log_gt.append((t, g[0], g[1], g[2], tw[0], tw[1], tw[2]))
        if k % m.imu_every == 0:
            vx, vy, wz = self._gt_tw
            pvx, pvy = self._imu_prev_v
            dt_imu = m.imu_every * m.dt
            ax = (vx - pvx) / dt_imu - wz * vy
            ay = (vy - pvy) / dt_imu + wz * vx
            self._imu_prev_v = (vx, vy)
            noisy = m.imu_noise and k > 0
            sg = m.gyro_sigma if noisy else 0.0
            sa = m.accel_sigma if noisy else 0.0
            _, gyro, accel, magnetometer = self._noise
            ng = gyro.next3() if noisy else _ZERO3
            na = accel.next3() if noisy else _ZERO3
            self._gyro_z = wz + m.gyro_bias + sg * ng[2]
            if m.dead_wheels:  # the 9-DoF IMU of seed 003's omni-X robot
                yaw = self._gt[2]
                sm = _MAG_NOISE_G if noisy else 0.0
                nm = magnetometer.next3() if noisy else _ZERO3
                self._log_mag.append(
                    (
                        t,
                        _FIELD_NORTH_G * math.cos(yaw) + sm * nm[0],
                        -_FIELD_NORTH_G * math.sin(yaw) + sm * nm[1],
                        _FIELD_DOWN_G + sm * nm[2],
                    )
                )
            self._log_imu.append(
                (
                    t,
                    sg * ng[0],
                    sg * ng[1],
                    self._gyro_z,
                    ax + sa * na[0],
                    ay + sa * na[1],
                    _GRAVITY_MPS2 + sa * na[2],
                )
            )
