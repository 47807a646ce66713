"""The Wheeltec vehicle controller as a :class:`~omnical.experiment.ports.Robot`, over pyserial.

:class:`WheeltecRobot` streams the command at a fixed rate, integrates odometry from the status
twist and sends a zero frame on stop, close, an exception, a stalled host or a silent device.
"""

from __future__ import annotations

import atexit
import contextlib
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Protocol, Self

import numpy as np

from omnical.drivers.frame_clock import frame_times, periods_between
from omnical.drivers.watchdog import Silence, Watched, silence_detail, wait_while_silent
from omnical.drivers.wheeltec import (
    STATUS_LENGTH,
    StatusFrame,
    StatusLimits,
    StatusReader,
    encode_command,
)
from omnical.errors import ConfigError, ProtocolError, SafetyStopError
from omnical.experiment.ports import RobotState
from omnical.recording.topics import IMU, ODOM

if TYPE_CHECKING:
    from omnical.kinematics.correction import CorrectionFactors
    from omnical.robot.description import RobotDescription

__all__ = [
    "DEFAULT_BAUDRATE",
    "DriverError",
    "SerialPort",
    "SerialRobotState",
    "StatusSample",
    "WheeltecRobot",
    "open_wheeltec_port",
]

DEFAULT_BAUDRATE = 115200
STATUS_PERIOD_S = 0.05
"""The firmware's data task runs at 20 Hz."""


class DriverError(ProtocolError):
    """The serial link to the vehicle controller failed (port gone, write refused)."""


class SerialPort(Protocol):
    """What the driver needs of a ``serial.Serial``."""

    @property
    def in_waiting(self) -> int: ...

    def read(self, size: int = 1, /) -> bytes: ...

    def write(self, data: bytes, /) -> int | None: ...

    def flush(self) -> None: ...

    def close(self) -> None: ...


def open_wheeltec_port(
    port: str, baudrate: int = DEFAULT_BAUDRATE, *, read_timeout_s: float = 0.005
) -> SerialPort:
    """Open the controller's port, 8N1, no flow control, short read timeout, input flushed.

    ``read_timeout_s`` bounds how late the driver's fixed-rate command tick can be when no byte
    arrives (keep it well below the command period; divide it by the time scale of a test).

    Raises:
        DriverError: the port cannot be opened (the message names it).
    """
    import serial  # the I/O edge

    try:
        ser = serial.Serial(port, baudrate=baudrate, timeout=read_timeout_s, write_timeout=0.5)
    except (serial.SerialException, ValueError, OSError) as err:
        msg = f"cannot open the vehicle controller port {port!r} at {baudrate} baud: {err}"
        raise DriverError(msg) from err
    ser.reset_input_buffer()
    return ser


@dataclass(frozen=True)
class SerialRobotState(RobotState):
    """The state of a serial base: the port's :class:`RobotState` plus what the link says.

    Attributes:
        stale: no valid status frame for ``stale_periods`` status periods (or none yet).
        age_s: time since the last valid status frame (inf before the first).
        battery_v: battery voltage of the last frame (nan before the first).
        stop_flag: the firmware's motors-disabled flag (low battery, E-stop, self-check).
        host_watchdog_tripped: the host loop stalled and the driver zeroed the command.
    """

    stale: bool = True
    age_s: float = math.inf
    battery_v: float = math.nan
    stop_flag: bool = False
    host_watchdog_tripped: bool = False


@dataclass(frozen=True)
class StatusSample:
    """One accepted status frame, as logged: host receive time and the integrated odometry."""

    t_s: float
    pose: tuple[float, float, float]
    status: StatusFrame


class WheeltecRobot:
    """The :class:`~omnical.experiment.ports.Robot` port over a Wheeltec serial link.

    Args:
        port: an open serial port (:func:`open_wheeltec_port`), or any object with the same
            methods (tests use a pseudo-terminal).
        rate_hz: command rate (≥ 10 Hz).
        robot: robot description; gives the derived wheel speeds and the plausibility limits.
        stale_periods: status periods without a valid frame before the state is stale.
        host_watchdog_s: zero the command if the host has not called ``send_twist`` / ``stop``
            for this long (None: never).
        limits: plausibility of status frames (default from ``robot``'s limits).
        max_gap_s: longest time per received frame still integrated, s.
        clock: monotonic time source, s.
        name: the device as the user names it, in messages ("vehicle controller on PORT").
        watchdog_s: the longest status silence while moving before the robot is stopped, s
            (default ``stale_periods`` status periods).
    """

    def __init__(
        self,
        port: SerialPort,
        *,
        rate_hz: float = 20.0,
        robot: RobotDescription | None = None,
        stale_periods: int = 3,
        host_watchdog_s: float | None = 0.5,
        limits: StatusLimits | None = None,
        max_gap_s: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
        name: str = "vehicle controller",
        watchdog_s: float | None = None,
    ) -> None:
        if not (math.isfinite(rate_hz) and 10.0 <= rate_hz <= 200.0):
            msg = f"command rate must be within 10–200 Hz, got {rate_hz}"
            raise ConfigError(msg)
        if host_watchdog_s is not None and not (
            math.isfinite(host_watchdog_s) and host_watchdog_s > 0.0
        ):
            msg = f"host_watchdog_s must be finite and > 0 or None, got {host_watchdog_s}"
            raise ConfigError(msg)
        if watchdog_s is not None and not (math.isfinite(watchdog_s) and watchdog_s > 0.0):
            msg = f"watchdog_s must be finite and > 0, got {watchdog_s}"
            raise ConfigError(msg)
        self._port = port
        self.name = name
        self._period = 1.0 / rate_hz
        self._clock = clock
        self._stale_s = stale_periods * STATUS_PERIOD_S
        self._watchdog_s = watchdog_s if watchdog_s is not None else self._stale_s
        self._required: list[Watched] = []
        self._fault: SafetyStopError | None = None
        self._bytes_at_valid = 0
        self._max_gap_s = max(self._stale_s, max_gap_s)
        self.gaps_skipped = 0
        self._host_watchdog_s = host_watchdog_s
        if limits is None and robot is not None:
            lim = robot.limits
            limits = StatusLimits(
                max_speed_mps=max(2.0 * max(lim.max_vx_mps, lim.max_vy_mps), 1.0),
                max_yaw_rate_radps=max(2.0 * lim.max_wz_radps, 3.0),
            )
        self._reader = StatusReader(limits if limits is not None else StatusLimits())
        self._J: np.ndarray | None = None
        if robot is not None:
            from omnical.kinematics.jacobian import inverse_jacobian

            self._J = np.asarray(inverse_jacobian(robot.wheels), dtype=np.float64)
        self._lock = threading.Lock()
        self._cmd = (0.0, 0.0, 0.0)
        self._frame = encode_command(0.0, 0.0, 0.0)
        self._last_call = clock()
        self._tripped = False
        self._pose = [0.0, 0.0, 0.0]
        self._last: StatusFrame | None = None
        self._last_rx = -math.inf  # the last valid frame's arrival (its silence counts from it)
        self._stamp = -math.inf  # and its stamp (firmware periods, bounded by the arrivals)
        self._end_at_valid = 0
        self._log: list[StatusSample] = []
        self._error: BaseException | None = None
        self._correction: CorrectionFactors | None = None
        self._closed = False
        self._stop_event = threading.Event()
        self.frames_sent = 0
        self._thread = threading.Thread(target=self._loop, name="wheeltec-driver", daemon=True)
        self._thread.start()
        atexit.register(self._atexit)

    # ----------------------------------------------------------------- Robot port
    def send_twist(self, vx_mps: float, vy_mps: float, wz_radps: float) -> None:
        """Command a body twist; sent at the fixed rate until the next command.

        Raises:
            SafetyStopError: a device the motion needs fell silent (the robot was stopped).
            DriverError: the link failed (the driver has tried to send zero).
        """
        twist = (float(vx_mps), float(vy_mps), float(wz_radps))
        moving = twist != (0.0, 0.0, 0.0)  # standing still is always allowed
        if moving:
            self._raise_if_failed()
            if self._cmd == (0.0, 0.0, 0.0):  # never start blind
                self._watch_at_start()  # (a motion going on is watched by the thread's ticks)
                self._raise_if_failed()
        frame = encode_command(*twist)
        with self._lock:
            if moving and self._fault is not None:  # the thread tripped meanwhile: keep zero
                raise self._fault
            changed = frame != self._frame
            self._cmd = twist
            self._frame = frame
            self._last_call = self._clock()
            self._tripped = False
        if changed:  # a new command goes out at once; the fixed-rate stream repeats it
            self._write_now(frame)

    def read_state(self) -> SerialRobotState:
        """The latest odometry and status; ``stale`` is evaluated now."""
        now = self._clock()
        with self._lock:
            last, pose = self._last, tuple(self._pose)
            age = now - self._last_rx
            tripped = self._tripped
        if last is None:
            return SerialRobotState(
                t_s=now,
                odom_pose=(pose[0], pose[1], pose[2]),
                odom_twist=(0.0, 0.0, 0.0),
                wheel_speeds_radps=(),
                gyro_z_radps=0.0,
                host_watchdog_tripped=tripped,
            )
        wheels: tuple[float, ...] = ()
        if self._J is not None:  # derived from the (uncorrected) forward-kinematics twist
            wheels = tuple(float(w) for w in self._J @ np.asarray(last.twist))
        twist = self.odometry_twist(last)
        return SerialRobotState(
            t_s=now,
            odom_pose=(pose[0], pose[1], pose[2]),
            odom_twist=twist,
            wheel_speeds_radps=wheels,
            gyro_z_radps=last.gyro_radps[2],
            stale=age > self._stale_s,
            age_s=age,
            battery_v=last.battery_v,
            stop_flag=bool(last.stop_flag),
            host_watchdog_tripped=tripped,
        )

    def stop(self) -> None:
        """Command zero and write a zero frame at once (not at the next tick)."""
        zero = encode_command(0.0, 0.0, 0.0)
        with self._lock:
            self._cmd = (0.0, 0.0, 0.0)
            self._frame = zero
            self._last_call = self._clock()
        self._write_now(zero)

    # ----------------------------------------------------------------- watchdog
    def require(self, device: Watched) -> None:
        """Stop the robot when ``device`` is silent beyond its limit while the robot moves."""
        with self._lock:
            self._required.append(device)

    def release(self, device: Watched) -> None:
        """No longer depend on ``device`` (it may stay silent)."""
        with self._lock:
            if device in self._required:
                self._required.remove(device)

    def silence(self, now_s: float) -> Silence:
        """The status stream's silence: time since the last valid frame, and what came since."""
        with self._lock:
            age = now_s - self._last_rx
            since = self._reader.stats.bytes_received - self._bytes_at_valid
        limit = self._watchdog_s if self._error is None else 0.0  # a failed port is silence
        return Silence(self.name, age, limit, silence_detail(since, self._error))

    @property
    def safety_stop(self) -> SafetyStopError | None:
        """The safety stop that ended the motion, if one did."""
        return self._fault

    # ----------------------------------------------------------------- extras
    @property
    def commanded(self) -> tuple[float, float, float]:
        """The twist being sent."""
        with self._lock:
            return self._cmd

    def drain_log(self) -> list[StatusSample]:
        """The status samples accepted since the last call (for recording)."""
        with self._lock:
            out, self._log = self._log, []
        return out

    def drain_rows(self) -> dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]:
        """The status samples since the last call as ``/odom`` and ``/imu`` rows:
        ``topic -> (host times s, {column: values})``, as a hedgehog's ``drain``."""
        samples = self.drain_log()
        if not samples:
            return {}
        t = np.array([s.t_s for s in samples])
        pose = np.array([s.pose for s in samples])
        twist = np.array([self.odometry_twist(s.status) for s in samples])
        gyro = np.array([s.status.gyro_radps for s in samples])
        acc = np.array([s.status.accel_mps2 for s in samples])
        odom = {"x_m": pose[:, 0], "y_m": pose[:, 1], "yaw_rad": pose[:, 2]}
        odom.update(vx_mps=twist[:, 0], vy_mps=twist[:, 1], wz_radps=twist[:, 2])
        imu = {"gyro_x_radps": gyro[:, 0], "gyro_y_radps": gyro[:, 1], "gyro_z_radps": gyro[:, 2]}
        imu.update(acc_x_mps2=acc[:, 0], acc_y_mps2=acc[:, 1], acc_z_mps2=acc[:, 2])
        return {ODOM: (t, odom), IMU: (t, imu)}

    def set_odometry_correction(self, factors: CorrectionFactors | None) -> None:
        """Counter-compensate every status twist with ``factors`` before integrating it."""
        with self._lock:
            self._correction = factors

    def odometry_twist(self, status: StatusFrame) -> tuple[float, float, float]:
        """The odometry twist of a status frame (counter-compensated if a correction is set)."""
        factors = self._correction
        if factors is None:
            return status.twist
        from omnical.kinematics.correction import counter_compensate_twist_scalar

        return counter_compensate_twist_scalar(*status.twist, factors)

    def reset_odometry(self, pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        """Restart the integrated odometry at ``pose``."""
        with self._lock:
            self._pose = list(pose)

    def close(self) -> None:
        """Send zero, stop the thread, send zero again, close the port. Idempotent."""
        if self._closed:
            return
        self._closed = True
        with self._lock:
            self._cmd = (0.0, 0.0, 0.0)
            self._frame = encode_command(0.0, 0.0, 0.0)
        self._write_now(self._frame)
        self._stop_event.set()
        self._thread.join(timeout=1.0)
        self._write_now(self._frame)
        with contextlib.suppress(Exception):  # closing a dead port must not hide the cause
            self._port.close()
        atexit.unregister(self._atexit)

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # ----------------------------------------------------------------- internals
    def _atexit(self) -> None:
        self.close()

    def _raise_if_failed(self) -> None:
        if self._fault is not None:
            raise self._fault
        if self._error is not None:
            msg = f"vehicle controller link failed: {self._error}"
            raise DriverError(msg) from self._error

    def _write_now(self, frame: bytes) -> None:
        try:
            with self._lock:
                self._port.write(frame)
                self.frames_sent += 1
        except Exception as err:
            self._fail(err)

    def _fail(self, err: BaseException) -> None:
        """The port failed: a moving robot's run ends as a safety stop (the fault set before
        the error, so no caller sees the plain link error meanwhile)."""
        if self._error is not None:
            return
        if self._cmd != (0.0, 0.0, 0.0) and self._fault is None:
            now = self._clock()
            with self._lock:
                age = now - self._last_rx
                self._cmd, self._frame = (0.0, 0.0, 0.0), encode_command(0.0, 0.0, 0.0)
                self._fault = SafetyStopError(self.name, age, f"port failed: {err}")
        self._error = err

    def _watch(self, now: float, *, moving: bool = True) -> None:
        """Trip the safety stop if the robot moves (or is to start) while a device it needs
        is silent."""
        if self._fault is not None:
            return
        for device in self._watched():
            silence = device.silence(now)
            if silence.exceeded:
                self._trip(silence, moving=moving)
                return

    def _watch_at_start(self) -> None:
        """Before a motion starts: every device it needs has sent valid data within its limit.

        A device silent beyond it gets one more limit's time (this process may have stalled
        with its data waiting unread; the readers take it meanwhile), then the watch trips.
        """
        wait_while_silent(self._watched, self._clock, self._watchdog_s)
        self._watch(self._clock(), moving=False)

    def _watched(self) -> list[Watched]:
        """The devices a motion needs: this robot's port and the required ones."""
        with self._lock:
            return [self, *self._required]

    def _trip(self, silence: Silence, *, moving: bool = True) -> None:
        """Zero the command at once and remember why (raised from every later motion)."""
        zero = encode_command(0.0, 0.0, 0.0)
        with self._lock:
            self._cmd = (0.0, 0.0, 0.0)
            self._frame = zero
            self._fault = SafetyStopError(
                silence.device, silence.silent_s, silence.detail, moving=moving
            )
        self._write_now(zero)

    def _loop(self) -> None:
        next_send = self._clock()
        skipped = False
        try:
            while not self._stop_event.is_set():
                now = self._clock()
                if now >= next_send:
                    # a tick more than a period late (this process stalled): the watch waits
                    # one tick for the readers, once
                    late = now - next_send > self._period and not skipped
                    self._tick(now, watch=not late)
                    skipped = late
                    next_send += self._period
                    if next_send < now:  # fell behind by more than a period: realign
                        next_send = now + self._period
                waiting = self._port.in_waiting
                data = self._port.read(max(1, min(waiting, 4096)))
                if data:
                    self._on_bytes(data, self._clock())
        except Exception as err:
            self._fail(err)  # the link died (under a moving robot: a safety stop)
            with contextlib.suppress(Exception):
                self._port.write(encode_command(0.0, 0.0, 0.0))

    def _tick(self, now: float, *, watch: bool = True) -> None:
        if watch and self._cmd != (0.0, 0.0, 0.0):
            self._watch(now)
        with self._lock:
            wd = self._host_watchdog_s
            if wd is not None and self._cmd != (0.0, 0.0, 0.0) and now - self._last_call > wd:
                self._cmd = (0.0, 0.0, 0.0)
                self._frame = encode_command(0.0, 0.0, 0.0)
                self._tripped = True
            frame = self._frame
            self._port.write(frame)
            self.frames_sent += 1

    def _on_bytes(self, data: bytes, t: float) -> None:
        frames = self._reader.feed(data)
        if not frames:
            return
        ends = self._reader.frame_ends
        with self._lock:
            # each frame stands for a firmware period; its arrival only bounds that
            times = frame_times(
                periods_between(ends, self._end_at_valid, STATUS_LENGTH),
                t,
                previous_stamp_s=self._stamp,
                previous_arrival_s=self._last_rx,
                period_s=STATUS_PERIOD_S,
                max_lag_s=self._watchdog_s,
                max_gap_s=self._max_gap_s,
            )
            if times.skipped:
                self.gaps_skipped += 1
            self._last_rx = max(t, self._last_rx + 1e-6 * len(frames))
            self._end_at_valid = ends[-1]
            for f, t_f, dt in zip(frames, times.stamps_s, times.steps_s, strict=True):
                vx, vy, wz = self.odometry_twist(f)
                if dt > 0.0:
                    x, y, yaw = self._pose
                    mid = yaw + 0.5 * wz * dt
                    c, s = math.cos(mid), math.sin(mid)
                    self._pose = [
                        x + (vx * c - vy * s) * dt,
                        y + (vx * s + vy * c) * dt,
                        yaw + wz * dt,
                    ]
                self._last = f
                self._stamp = t_f
                self._bytes_at_valid = self._reader.stats.bytes_received
                p = self._pose
                self._log.append(StatusSample(t_f, (p[0], p[1], p[2]), f))
