"""The digital twin's step loop compiled with numba: the same model, many steps per call.

The arithmetic of :class:`~omnical.twin.simulator.DigitalTwin`'s Python loop, in the same order,
as ``@njit(cache=True)`` kernels driven by :class:`CompiledCore`: bit-identical logs.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import astuple
from typing import Any, TypeVar, cast

import numba
import numpy as np
from numpy.typing import NDArray

from omnical.twin.noise import NoiseStream
from omnical.twin.params import StepModel

__all__ = ["CompiledCore"]

_F = TypeVar("_F", bound=Callable[..., object])
# the five logs (odometry, truth, IMU, dead wheels, magnetometer), indexed by L_*
_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]
_Logs = tuple[_F64, _F64, _F64, _F64, _F64]


# _nrt=False: no reference counting of the array arguments (the kernels allocate nothing)
_OPTIONS: dict[str, Any] = {"cache": True, "_nrt": False}


def _jit(func: _F) -> _F:
    return cast(_F, numba.njit(**_OPTIONS)(func))


def _jit_inline(func: _F) -> _F:
    # inlined into the caller in numba's IR, so LLVM optimises the whole step as one function
    return cast(_F, numba.njit(inline="always", **_OPTIONS)(func))


_GRAVITY_MPS2 = 9.80665
_FIELD_NORTH_G = 0.2
_FIELD_DOWN_G = 0.45
_MAG_NOISE_G = 0.002

# ---------------------------------------------------------------- layout of fp (constants)
P_DT = 0
P_DT_C = 1
P_AMAX = 2  # 3 values
P_WHEEL_MAX = 5
P_KP = 6
P_KI = 7
P_TAU = 8
P_CPR = 9
P_RPC = 10
P_INSTALLED = 11  # 7 factors in CorrectionFactors field order
P_TRUE = 18  # 7 factors
P_HALF_PLAY = 25
P_SLIP_ON = 26
P_SLIP_DECAY = 27
P_SLIP_DRIVE = 28
P_BIAS = 29
P_GYRO_SIGMA = 30
P_ACCEL_SIGMA = 31
P_IMU_NOISE = 32
P_DT_IMU = 33
P_VMAX = 34  # 3 values
P_PID_ON = 37  # > 0: the installed PID runs the wheel loop (no feed-forward)
P_PID_KP = 38
P_PID_KI_DT = 39  # Kp dt_c / Ti (0 without integral)
P_PID_KPTD = 40  # Kp Td
P_PID_TF = 41  # Td / N
P_ARRAYS = 42  # then J (n×3), Jp (3×n), Jp_true (3×n), motors (4×n), dead wheels (m×6)

# ---------------------------------------------------------------- layout of ip (ints)
I_N = 0
I_M = 1
I_CTRL_EVERY = 2
I_ODOM_EVERY = 3
I_GT_EVERY = 4
I_IMU_EVERY = 5
I_K = 6
I_ROWS = 7  # 5 row counts: odom, ground truth, IMU, dead wheels, magnetometer
I_NOISE_AT = 12  # 4 cursors: slip, gyro, accel, magnetometer
I_NOISE_LEN = 16  # 4 block lengths
I_PLAY_AT = 20  # next command of the block _play is playing
I_SIZE = 21

# ---------------------------------------------------------------- layout of fs (state)
S_CMD = 0
S_TGT = 3
S_SLIP = 6
S_ODOM = 9
S_ODOM_TW = 12
S_GT = 15
S_GT_TW = 18
S_IMU_PREV_V = 21
S_GYRO_Z = 23
# then per wheel (n each) u, wm, th_m, th_w, counts_prev, integ, ref_prev, meas, deriv,
# meas_prev; then the dead wheels' angles (m)
S_WHEELS = 24
W_U, W_WM, W_TH_M, W_TH_W, W_COUNTS_PREV = range(5)
W_INTEG, W_REF_PREV, W_MEAS, W_DERIV, W_MEAS_PREV = range(5, 10)
W_COUNT = 10

# noise channels in ``noise`` (the order of the kernel, not NoiseChannel's values)
N_SLIP, N_GYRO, N_ACCEL, N_MAG = range(4)
# logs, in CompiledCore.logs
L_ODOM, L_GT, L_IMU, L_DEAD, L_MAG = range(5)

# statuses of _advance: 0 done, 1 + channel a noise block ran out, 10 + log a log is full
ST_DONE = 0
ST_NOISE = 1
ST_LOG = 10


# ---------------------------------------------------------------- kernels
@_jit_inline
def _crosstalk(fp: _F64, o: int, vx: float, vy: float) -> float:
    # max(v, 0.0) as Python evaluates it: v unless 0.0 is greater (so max(-0.0, 0.0) is -0.0)
    rate: float = (
        fp[o + 3] * (0.0 if vx < 0.0 else vx)
        + fp[o + 4] * (0.0 if -vx < 0.0 else -vx)
        + fp[o + 5] * (0.0 if vy < 0.0 else vy)
        + fp[o + 6] * (0.0 if -vy < 0.0 else -vy)
    )
    return rate


@_jit_inline
def _motor_step(
    omega: float, command: float, gain: float, coulomb: float, droop: float, decay: float
) -> float:
    drive = gain * command
    if coulomb > 0.0:
        if omega == 0.0:
            if abs(drive) <= coulomb:
                return 0.0
            drive -= math.copysign(coulomb, drive)
        else:
            drive -= math.copysign(coulomb, omega)
    target = drive / (1.0 + droop)
    new = target + (omega - target) * decay
    if coulomb > 0.0 and new * omega < 0.0:
        return 0.0
    return new


@_jit_inline
def _pid_tick(
    fp: _F64, fs: _F64, wb: int, n: int, i: int, ref: float, meas: float, dt_c: float, wmax: float
) -> float:
    """The installed PID of wheel ``i`` (omnical.control.pid's law, conditional anti-windup)."""
    e = ref - meas
    tf = fp[P_PID_TF]
    deriv = fs[wb + W_DERIV * n + i]
    if fp[P_PID_KPTD] > 0.0:
        dy = meas - fs[wb + W_MEAS_PREV * n + i]
        deriv = (tf * deriv - fp[P_PID_KPTD] * dy) / (tf + dt_c)
    fs[wb + W_DERIV * n + i] = deriv
    fs[wb + W_MEAS_PREV * n + i] = meas
    integ = fs[wb + W_INTEG * n + i]
    raw = fp[P_PID_KP] * e + integ + deriv
    u: float = raw
    if u > wmax:
        u = wmax
    elif u < -wmax:
        u = -wmax
    increment = fp[P_PID_KI_DT] * e
    if u == raw or increment * (raw - u) < 0.0:
        fs[wb + W_INTEG * n + i] = integ + increment
    return u


@_jit_inline
def _firmware_tick(fp: _F64, fs: _F64, n: int) -> None:
    dt_c = fp[P_DT_C]
    for k in range(3):
        lim = fp[P_AMAX + k] * dt_c
        d = fs[S_CMD + k] - fs[S_TGT + k]
        fs[S_TGT + k] += lim if d > lim else (-lim if d < -lim else d)
    # compensation with the installed factors: cross-talk injected, then scaled
    tx, ty, tw = fs[S_TGT], fs[S_TGT + 1], fs[S_TGT + 2]
    wz = tw - _crosstalk(fp, P_INSTALLED, tx, ty)
    cx = tx * fp[P_INSTALLED]
    cy = ty * fp[P_INSTALLED + 1]
    cw = wz * fp[P_INSTALLED + 2]
    kp, ki, wmax = fp[P_KP], fp[P_KI], fp[P_WHEEL_MAX]
    tau = fp[P_TAU]
    cpr, rpc = fp[P_CPR], fp[P_RPC]
    j0 = P_ARRAYS
    jp0 = j0 + 3 * n
    wb = S_WHEELS
    sx = 0.0
    sy = 0.0
    sw = 0.0
    for i in range(n):
        ref = fp[j0 + 3 * i] * cx + fp[j0 + 3 * i + 1] * cy + fp[j0 + 3 * i + 2] * cw
        counts = float(math.floor(fs[wb + W_TH_M * n + i] * cpr / (2.0 * math.pi)))
        meas = (counts - fs[wb + W_COUNTS_PREV * n + i]) * rpc / dt_c
        fs[wb + W_MEAS * n + i] = meas
        fs[wb + W_COUNTS_PREV * n + i] = counts
        if fp[P_PID_ON] > 0.0:
            u = _pid_tick(fp, fs, wb, n, i, ref, meas, dt_c, wmax)
        else:
            ff = ref + tau * (ref - fs[wb + W_REF_PREV * n + i]) / dt_c
            fs[wb + W_REF_PREV * n + i] = ref
            e = ref - meas
            integ = fs[wb + W_INTEG * n + i] + e * dt_c
            u = ff + kp * e + ki * integ
            if u > wmax or u < -wmax:
                u = wmax if u > 0 else -wmax
            else:
                fs[wb + W_INTEG * n + i] = integ
        fs[wb + W_U * n + i] = u
    for i in range(n):
        meas = fs[wb + W_MEAS * n + i]
        sx += fp[jp0 + i] * meas
        sy += fp[jp0 + n + i] * meas
        sw += fp[jp0 + 2 * n + i] * meas
    # counter-compensation with the installed factors
    mx = sx / fp[P_INSTALLED]
    my = sy / fp[P_INSTALLED + 1]
    mw = sw / fp[P_INSTALLED + 2]
    mw = mw + _crosstalk(fp, P_INSTALLED, mx, my)
    yaw_mid = fs[S_ODOM + 2] + 0.5 * mw * dt_c
    c, s = math.cos(yaw_mid), math.sin(yaw_mid)
    fs[S_ODOM] += (mx * c - my * s) * dt_c
    fs[S_ODOM + 1] += (mx * s + my * c) * dt_c
    fs[S_ODOM + 2] += mw * dt_c
    fs[S_ODOM_TW] = mx
    fs[S_ODOM_TW + 1] = my
    fs[S_ODOM_TW + 2] = mw


@_jit_inline
def _log_sample(
    fp: _F64,
    fs: _F64,
    ip: _I64,
    noise: _F64,
    logs: _Logs,
    k: int,
    do_odom: bool,
    do_gt: bool,
    do_imu: bool,
) -> None:
    """Log step ``k``'s samples: odometry (and dead wheels), truth, IMU (and magnetometer)."""
    n = ip[I_N]
    m = ip[I_M]
    t = k * fp[P_DT]
    if do_odom:
        r = ip[I_ROWS + L_ODOM]
        log_odom = logs[L_ODOM]
        log_odom[r, 0] = t
        for c in range(3):
            log_odom[r, 1 + c] = fs[S_ODOM + c]
            log_odom[r, 4 + c] = fs[S_ODOM_TW + c]
        ip[I_ROWS + L_ODOM] = r + 1
        if m > 0:
            r = ip[I_ROWS + L_DEAD]
            log_dead = logs[L_DEAD]
            log_dead[r, 0] = t
            d0 = P_ARRAYS + 3 * n + 3 * n + 3 * n + 4 * n
            a0 = S_WHEELS + W_COUNT * n
            for j in range(m):
                cpr = fp[d0 + 6 * j + 5]
                log_dead[r, 1 + j] = float(math.floor(fs[a0 + j] * cpr / (2.0 * math.pi)))
            ip[I_ROWS + L_DEAD] = r + 1
    if do_gt:
        r = ip[I_ROWS + L_GT]
        log_gt = logs[L_GT]
        log_gt[r, 0] = t
        for c in range(3):
            log_gt[r, 1 + c] = fs[S_GT + c]
            log_gt[r, 4 + c] = fs[S_GT_TW + c]
        ip[I_ROWS + L_GT] = r + 1
    if do_imu:
        vx, vy, wz = fs[S_GT_TW], fs[S_GT_TW + 1], fs[S_GT_TW + 2]
        pvx, pvy = fs[S_IMU_PREV_V], fs[S_IMU_PREV_V + 1]
        dt_imu = fp[P_DT_IMU]
        ax = (vx - pvx) / dt_imu - wz * vy
        ay = (vy - pvy) / dt_imu + wz * vx
        fs[S_IMU_PREV_V] = vx
        fs[S_IMU_PREV_V + 1] = vy
        noisy = fp[P_IMU_NOISE] > 0.0 and k > 0
        sg = fp[P_GYRO_SIGMA] if noisy else 0.0
        sa = fp[P_ACCEL_SIGMA] if noisy else 0.0
        ng0 = ng1 = ng2 = na0 = na1 = na2 = 0.0
        if noisy:
            ig = ip[I_NOISE_AT + N_GYRO]
            ng0, ng1, ng2 = noise[N_GYRO, ig, 0], noise[N_GYRO, ig, 1], noise[N_GYRO, ig, 2]
            ip[I_NOISE_AT + N_GYRO] = ig + 1
            ia = ip[I_NOISE_AT + N_ACCEL]
            na0, na1, na2 = noise[N_ACCEL, ia, 0], noise[N_ACCEL, ia, 1], noise[N_ACCEL, ia, 2]
            ip[I_NOISE_AT + N_ACCEL] = ia + 1
        gyro_z = wz + fp[P_BIAS] + sg * ng2
        fs[S_GYRO_Z] = gyro_z
        if m > 0:
            yaw = fs[S_GT + 2]
            sm = _MAG_NOISE_G if noisy else 0.0
            nm0 = nm1 = nm2 = 0.0
            if noisy:
                im = ip[I_NOISE_AT + N_MAG]
                nm0, nm1, nm2 = noise[N_MAG, im, 0], noise[N_MAG, im, 1], noise[N_MAG, im, 2]
                ip[I_NOISE_AT + N_MAG] = im + 1
            r = ip[I_ROWS + L_MAG]
            log_mag = logs[L_MAG]
            log_mag[r, 0] = t
            log_mag[r, 1] = _FIELD_NORTH_G * math.cos(yaw) + sm * nm0
            log_mag[r, 2] = -_FIELD_NORTH_G * math.sin(yaw) + sm * nm1
            log_mag[r, 3] = _FIELD_DOWN_G + sm * nm2
            ip[I_ROWS + L_MAG] = r + 1
        r = ip[I_ROWS + L_IMU]
        log_imu = logs[L_IMU]
        log_imu[r, 0] = t
        log_imu[r, 1] = sg * ng0
        log_imu[r, 2] = sg * ng1
        log_imu[r, 3] = gyro_z
        log_imu[r, 4] = ax + sa * na0
        log_imu[r, 5] = ay + sa * na1
        log_imu[r, 6] = _GRAVITY_MPS2 + sa * na2
        ip[I_ROWS + L_IMU] = r + 1


@_jit_inline
def _blocked(fp: _F64, ip: _I64, logs: _Logs, do_odom: bool, do_gt: bool, do_imu: bool) -> int:
    """What keeps the next step (with these samples) from running; ST_DONE if nothing."""
    m = ip[I_M]
    if fp[P_SLIP_ON] > 0.0 and ip[I_NOISE_AT + N_SLIP] >= ip[I_NOISE_LEN + N_SLIP]:
        return ST_NOISE + N_SLIP
    if do_odom:
        if ip[I_ROWS + L_ODOM] >= logs[L_ODOM].shape[0]:
            return ST_LOG + L_ODOM
        if m > 0 and ip[I_ROWS + L_DEAD] >= logs[L_DEAD].shape[0]:
            return ST_LOG + L_DEAD
    if do_gt and ip[I_ROWS + L_GT] >= logs[L_GT].shape[0]:
        return ST_LOG + L_GT
    if do_imu:
        if ip[I_ROWS + L_IMU] >= logs[L_IMU].shape[0]:
            return ST_LOG + L_IMU
        if m > 0 and ip[I_ROWS + L_MAG] >= logs[L_MAG].shape[0]:
            return ST_LOG + L_MAG
    if do_imu and fp[P_IMU_NOISE] > 0.0:
        for ch in (N_GYRO, N_ACCEL, N_MAG):
            if (ch != N_MAG or m > 0) and ip[I_NOISE_AT + ch] >= ip[I_NOISE_LEN + ch]:
                return ST_NOISE + ch
    return ST_DONE


@_jit
def _advance(fp: _F64, fs: _F64, ip: _I64, noise: _F64, logs: _Logs, k_target: int) -> int:
    """Step until ``ip[I_K] == k_target``; a status other than ST_DONE stops before a step."""
    n = ip[I_N]
    m = ip[I_M]
    dt = fp[P_DT]
    half_play = fp[P_HALF_PLAY]
    jt0 = P_ARRAYS + 3 * n + 3 * n
    mo0 = jt0 + 3 * n
    d0 = mo0 + 4 * n
    wb = S_WHEELS
    a0 = S_WHEELS + W_COUNT * n
    k = ip[I_K]
    # the next steps with a firmware tick (at the step's start) and with each sample (at its end)
    ctrl_every, odom_every = ip[I_CTRL_EVERY], ip[I_ODOM_EVERY]
    gt_every, imu_every = ip[I_GT_EVERY], ip[I_IMU_EVERY]
    next_ctrl = k + (ctrl_every - k % ctrl_every) % ctrl_every
    next_odom = k + odom_every - k % odom_every
    next_gt = k + gt_every - k % gt_every
    next_imu = k + imu_every - k % imu_every
    while k < k_target:
        k1 = k + 1
        do_odom, do_gt, do_imu = k1 == next_odom, k1 == next_gt, k1 == next_imu
        status = _blocked(fp, ip, logs, do_odom, do_gt, do_imu)
        if status != ST_DONE:
            return status
        if k == next_ctrl:
            _firmware_tick(fp, fs, n)
            next_ctrl += ctrl_every
        tx = 0.0
        ty = 0.0
        tr = 0.0
        for i in range(n):
            wm = _motor_step(
                fs[wb + W_WM * n + i],
                fs[wb + W_U * n + i],
                fp[mo0 + i],
                fp[mo0 + n + i],
                fp[mo0 + 2 * n + i],
                fp[mo0 + 3 * n + i],
            )
            fs[wb + W_WM * n + i] = wm
            th = fs[wb + W_TH_M * n + i] + wm * dt
            fs[wb + W_TH_M * n + i] = th
            tw = fs[wb + W_TH_W * n + i]
            gap = th - tw
            if gap > half_play:
                new = th - half_play
            elif gap < -half_play:
                new = th + half_play
            else:
                new = tw
            ww = (new - tw) / dt
            fs[wb + W_TH_W * n + i] = new
            tx += fp[jt0 + i] * ww
            ty += fp[jt0 + n + i] * ww
            tr += fp[jt0 + 2 * n + i] * ww
        # the seven-factor truth: counter-compensation with the true factors
        vx = tx / fp[P_TRUE]
        vy = ty / fp[P_TRUE + 1]
        wz = tr / fp[P_TRUE + 2]
        wz = wz + _crosstalk(fp, P_TRUE, vx, vy)
        if fp[P_SLIP_ON] > 0.0:
            decay = fp[P_SLIP_DECAY]
            drive = fp[P_SLIP_DRIVE]
            js = ip[I_NOISE_AT + N_SLIP]
            for q in range(3):
                sl = fs[S_SLIP + q]
                fs[S_SLIP + q] = sl + (-sl * decay + drive * noise[N_SLIP, js, q])
            ip[I_NOISE_AT + N_SLIP] = js + 1
            s0, s1, s2 = fs[S_SLIP], fs[S_SLIP + 1], fs[S_SLIP + 2]
            wz = wz * (1.0 + s2) + 0.1 * s2 * (abs(vx) + abs(vy))
            vx *= 1.0 + s0
            vy *= 1.0 + s1
        yaw_mid = fs[S_GT + 2] + 0.5 * wz * dt
        c, s = math.cos(yaw_mid), math.sin(yaw_mid)
        fs[S_GT] += (vx * c - vy * s) * dt
        fs[S_GT + 1] += (vx * s + vy * c) * dt
        fs[S_GT + 2] += wz * dt
        fs[S_GT_TW] = vx
        fs[S_GT_TW + 1] = vy
        fs[S_GT_TW + 2] = wz
        for j in range(m):
            dx = fp[d0 + 6 * j]
            dy = fp[d0 + 6 * j + 1]
            along = fp[d0 + 6 * j + 2] * (vx - dy * wz) + fp[d0 + 6 * j + 3] * (vy + dx * wz)
            fs[a0 + j] += along * dt / fp[d0 + 6 * j + 4]
        k = k1
        ip[I_K] = k
        _log_sample(fp, fs, ip, noise, logs, k, do_odom, do_gt, do_imu)
        if do_odom:
            next_odom += odom_every
        if do_gt:
            next_gt += gt_every
        if do_imu:
            next_imu += imu_every
    return ST_DONE


@_jit
def _play(
    fp: _F64, fs: _F64, ip: _I64, noise: _F64, logs: _Logs, twists: _F64, targets: _I64
) -> int:
    """Command ``twists[i]`` then step to ``targets[i]``, from command ``ip[I_PLAY_AT]`` on.

    A status other than ST_DONE leaves ``ip[I_PLAY_AT]`` at the command to resume with
    (commanding it again is harmless: the same clamped twist).
    """
    for i in range(ip[I_PLAY_AT], len(targets)):
        for c in range(3):
            # DigitalTwin.send_twist's max(-v, min(v, x)), as Python evaluates it
            v = fp[P_VMAX + c]
            x = twists[i, c]
            lo = x if x < v else v
            fs[S_CMD + c] = lo if lo > -v else -v
        status = _advance(fp, fs, ip, noise, logs, targets[i])
        if status != ST_DONE:
            ip[I_PLAY_AT] = i
            return status
    ip[I_PLAY_AT] = 0
    return ST_DONE


# ---------------------------------------------------------------- Python side
_FIRST_ROWS = 4096


class CompiledCore:
    """State, noise and logs of one compiled twin; advances by whole kernel calls."""

    def __init__(self, model: StepModel, streams: Sequence[NoiseStream]) -> None:
        n = len(model.J)
        m = len(model.dead_wheels)
        self.n, self.m = n, m
        self._streams = tuple(streams)  # slip, gyro, accel, magnetometer
        block = max(s.block_size for s in self._streams)
        md = model
        fp = [
            md.dt,
            md.dt_c,
            *md.amax,
            md.wheel_max,
            md.kp,
            md.ki,
            md.tau,
            md.cpr,
            md.rad_per_count,
        ]
        fp += [*astuple(md.installed), *astuple(md.true), md.half_play, md.slip_on, md.slip_decay]
        fp += [md.slip_drive, md.gyro_bias, md.gyro_sigma, md.accel_sigma, md.imu_noise]
        fp += [md.imu_every * md.dt, *md.vmax, md.pid is not None, *(md.pid or (0.0,) * 4)]
        assert len(fp) == P_ARRAYS
        fp += [v for matrix in (md.J, md.Jp, md.Jp_true) for row in matrix for v in row]
        fp += [mo.gain for mo in md.motors] + [mo.coulomb_friction_radps for mo in md.motors]
        fp += [mo.viscous_droop for mo in md.motors] + list(md.motor_decay)
        fp += [v for d in md.dead_wheels for v in d]
        self.fp = np.array(fp, dtype=np.float64)
        self.ip = np.zeros(I_SIZE, dtype=np.int64)
        self.ip[[I_N, I_M, I_CTRL_EVERY, I_ODOM_EVERY, I_GT_EVERY, I_IMU_EVERY]] = (
            n,
            m,
            md.ctrl_every,
            md.odom_every,
            md.gt_every,
            md.imu_every,
        )
        self.fs = np.zeros(S_WHEELS + W_COUNT * n + m, dtype=np.float64)
        self.fs[S_GT : S_GT + 3] = md.start_pose
        self.noise = np.zeros((4, block, 3), dtype=np.float64)
        small = 1 if m == 0 else _FIRST_ROWS
        widths = ((_FIRST_ROWS, 7), (_FIRST_ROWS, 7), (_FIRST_ROWS, 7), (small, 1 + m), (small, 4))
        self.logs: _Logs = tuple(np.empty(shape) for shape in widths)  # type: ignore[assignment]
        self._full: list[list[NDArray[np.float64]]] = [[] for _ in self.logs]
        _log_sample(self.fp, self.fs, self.ip, self.noise, self.logs, 0, True, True, True)

    def advance(self, k_target: int) -> None:
        """Run the step loop until step ``k_target``."""
        while status := _advance(self.fp, self.fs, self.ip, self.noise, self.logs, k_target):
            self._unblock(int(status))

    def play(self, twists: NDArray[np.float64], targets: NDArray[np.int64]) -> list[float]:
        """Command each (N, 3) twist, then run to its target step; returns the last command."""
        self.ip[I_PLAY_AT] = 0
        while status := _play(self.fp, self.fs, self.ip, self.noise, self.logs, twists, targets):
            self._unblock(int(status))
        return cast(list[float], self.fs[S_CMD : S_CMD + 3].tolist())

    def _unblock(self, status: int) -> None:
        if status >= ST_LOG:
            self._grow(status - ST_LOG)
        else:
            self._refill(status - ST_NOISE)

    def _refill(self, channel: int) -> None:
        rows = self._streams[channel].take_rows()
        self.noise[channel, : len(rows)] = rows
        self.ip[I_NOISE_AT + channel] = 0
        self.ip[I_NOISE_LEN + channel] = len(rows)

    def _grow(self, which: int) -> None:
        # a full chunk is kept as it is; the next one is as large as all before it
        full = self.logs[which]
        self._full[which].append(full)
        total = sum(len(chunk) for chunk in self._full[which])
        logs = list(self.logs)
        logs[which] = np.empty((total, full.shape[1]))
        self.logs = tuple(logs)  # type: ignore[assignment]
        self.ip[I_ROWS + which] = 0

    def log_arrays(self) -> tuple[NDArray[np.float64], ...]:
        """Copies of the filled rows of the five logs (odom, truth, IMU, dead wheels, magnetometer)."""
        rows = self.ip[I_ROWS : I_ROWS + 5].tolist()
        return tuple(
            np.concatenate([*full, log[:r]]) if full else log[:r].copy()
            for log, r, full in zip(self.logs, rows, self._full, strict=True)
        )

    @property
    def step(self) -> int:
        """The step counter."""
        return int(self.ip[I_K])

    def set_command(self, vx_mps: float, vy_mps: float, wz_radps: float) -> None:
        """The commanded body twist (already clamped), held until the next command."""
        fs = self.fs
        fs[S_CMD] = vx_mps
        fs[S_CMD + 1] = vy_mps
        fs[S_CMD + 2] = wz_radps

    def robot_state(
        self,
    ) -> tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, ...], float]:
        """Odometry pose, odometry twist, measured wheel speeds and gyro z, as Python floats."""
        s: list[float] = self.fs[: S_WHEELS + W_COUNT * self.n].tolist()
        w = S_WHEELS + W_MEAS * self.n
        return (
            (s[S_ODOM], s[S_ODOM + 1], s[S_ODOM + 2]),
            (s[S_ODOM_TW], s[S_ODOM_TW + 1], s[S_ODOM_TW + 2]),
            tuple(s[w : w + self.n]),
            s[S_GYRO_Z],
        )

    def ground_truth_pose(self) -> tuple[float, float, float]:
        """True (x, y, yaw) in the map frame, as Python floats."""
        x, y, yaw = self.fs[S_GT : S_GT + 3].tolist()
        return (x, y, yaw)
