"""The digital twin as a device: the vehicle controller and the hedgehog behind pseudo-terminals.

:class:`TwinDeviceServer` (``omnical twin serve``) runs a twin in wall-clock time behind the
firmware's byte protocols and keeps its truth. Design: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import collections
import contextlib
import math
import os
import queue
import select
import threading
import time
import tty
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from omnical.drivers.wheeltec import CommandParser, StatusFrame, encode_status
from omnical.errors import ConfigError
from omnical.ips.beacons import BeaconMap, default_beacon_map
from omnical.ips.marvelmind.codec import encode
from omnical.ips.marvelmind.hedgehog import HedgehogSample, beacons_record, sample_frames
from omnical.recording.recording import Recording, RecordingBuilder
from omnical.robot.description import RobotDescription
from omnical.twin.ips_model import (
    VendorTrack,
    hedge_positions_map,
    measured_distances,
    measurement_rate_hz,
    select_submap,
)
from omnical.twin.ips_params import IpsParams
from omnical.twin.ips_vendor import quality_percent, solve_vendor_2d
from omnical.twin.params import TwinEngine, TwinParams
from omnical.twin.simulator import DigitalTwin

__all__ = ["DeviceConfig", "DeviceSnapshot", "PacedWriter", "PseudoTerminal", "TwinDeviceServer"]

_BITS_PER_BYTE = 10  # 8N1: start + 8 data + stop


@dataclass(frozen=True)
class DeviceConfig:
    """How the twin presents itself.

    Attributes:
        baudrate: vehicle-controller UART rate (Wheeltec: 115200).
        hedge_baudrate: hedgehog UART rate (Marvelmind UART default 500000; any over USB).
        status_hz: status frame rate (firmware data task: 20 Hz).
        watchdog_s: zero the target after this long without a valid command; None = off, as
            stock firmware ships.
        battery_v: battery voltage reported.
        tick_hz: the server's loop rate when no byte arrives (≥ the control tick; at most
            1 kHz of wall time when time-scaled).
        time_scale: robot seconds per wall second (1 = real time; > 1 only for tests).
        vehicle_port: serve the vehicle controller on a pty; False: no vehicle port, commands
            come through :meth:`TwinDeviceServer.command` (``omnical ros2 twin``'s ``/cmd_vel``).
    """

    baudrate: int = 115200
    hedge_baudrate: int = 115200
    status_hz: float = 20.0
    watchdog_s: float | None = None
    battery_v: float = 12.3
    tick_hz: float = 200.0
    time_scale: float = 1.0
    vehicle_port: bool = True

    def __post_init__(self) -> None:
        if not (math.isfinite(self.time_scale) and 0.1 <= self.time_scale <= 100.0):
            msg = f"time_scale must be within 0.1–100, got {self.time_scale}"
            raise ConfigError(msg)
        for name in ("baudrate", "hedge_baudrate"):
            if not 1200 <= getattr(self, name) <= 4_000_000:
                msg = f"{name} must be within 1200–4000000, got {getattr(self, name)}"
                raise ConfigError(msg)
        if not 1.0 <= self.status_hz <= 200.0:
            msg = f"status_hz must be within 1–200 Hz, got {self.status_hz}"
            raise ConfigError(msg)
        if self.watchdog_s is not None and not (
            math.isfinite(self.watchdog_s) and self.watchdog_s > 0
        ):
            msg = f"watchdog_s must be > 0 s or None (off), got {self.watchdog_s}"
            raise ConfigError(msg)


@dataclass(frozen=True)
class DeviceSnapshot:
    """What :meth:`TwinDeviceServer.snapshot` reads.

    Attributes:
        t_s: device time since start (robot seconds).
        truth_pose_map: the true pose in the map.
        odom_pose: the firmware's odometry pose (odom frame) and ``odom_twist`` its twist.
        last_command: the last (vx, vy, wz) commanded, or None.
        commands_applied: commands received so far; watchdog_trips: times it zeroed the target.
    """

    t_s: float
    truth_pose_map: tuple[float, float, float]
    odom_pose: tuple[float, float, float]
    odom_twist: tuple[float, float, float]
    last_command: tuple[float, float, float] | None
    commands_applied: int
    watchdog_trips: int


class PseudoTerminal:
    """A pty pair in raw mode; the server holds both ends so the host may open and close it."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        tty.setraw(self.master)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)

    def close(self) -> None:
        """Close both ends."""
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)


STALL_GRACE_S = 0.02
"""A loop gap longer than a tick and this (wall time) is a stall of the served twin's process;
a command is due when the usual interval, delay and this have passed since the newest one."""
STALL_WAIT_S = 0.25
"""With commands flowing (the last within this long of the stall, robot s), the twin waits for
the ones due during the stall (``command(sent_wall_ns=...)``), at most this long (robot s)."""


def command_due_s(recent: Sequence[tuple[float, float]], grace_s: float) -> float:
    """How long after the send time of the newest command (device s) the next is due, from the
    recent ones' (send, arrival) times: their usual interval (the median; :data:`STALL_WAIT_S`
    before two), their shortest delay (a sender's clock behind or ahead counts in it; the
    longest are the ones a stall held back) and ``grace_s``."""
    if len(recent) < 2:
        return STALL_WAIT_S + grace_s
    sent = np.array([s for s, _ in recent])
    heard = np.array([h for _, h in recent])
    interval = min(float(np.median(np.diff(sent))), STALL_WAIT_S)
    return interval + float(np.min(heard - sent)) + grace_s


class PacedWriter:
    """Writes to a pty master at a baud rate's real speed, from its own thread.

    Bytes go out in slices of about 1 ms of wire time; after each slice the writer waits until
    the wire would have carried it. Bytes the pty cannot take (no reader, buffer full) are
    dropped and counted. With ``time_scale`` = k a byte takes 1/k of its wire time.
    """

    def __init__(self, fd: int, baudrate: int, name: str, time_scale: float = 1.0) -> None:
        self._fd = fd
        self._byte_s = _BITS_PER_BYTE / (baudrate * time_scale)
        self._slice = max(1, int(0.001 / self._byte_s))
        self._queue: queue.Queue[bytes | None] = queue.Queue()
        self.bytes_written = 0
        self.bytes_dropped = 0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def put(self, data: bytes) -> None:
        """Queue bytes for sending."""
        self._queue.put(data)

    def close(self) -> None:
        """Stop after the queued bytes."""
        self._queue.put(None)
        self._thread.join(timeout=2.0)

    def _run(self) -> None:
        busy_until = time.monotonic()
        while True:
            data = self._queue.get()
            if data is None:
                return
            for i in range(0, len(data), self._slice):
                chunk = data[i : i + self._slice]
                now = time.monotonic()
                busy_until = max(busy_until, now)
                try:
                    n = os.write(self._fd, chunk)
                except BlockingIOError:
                    n = 0
                except OSError:
                    return
                self.bytes_written += n
                self.bytes_dropped += len(chunk) - n
                busy_until += len(chunk) * self._byte_s
                delay = busy_until - time.monotonic()
                if delay > 0:
                    time.sleep(delay)


class _OnlineHedgehog:
    """Marvelmind measurements generated online from the twin's true pose (docs/DESIGN-NOTES.md).

    The vendor's solve runs on the numba kernel (bit-identical to the numpy reference, and fast
    enough for a x10 clock), compiled or loaded from numba's cache here, before any port opens.
    """

    def __init__(self, ips: IpsParams, beacons: BeaconMap, rng: np.random.Generator) -> None:
        self.p = ips
        self.addresses = np.asarray(beacons.addresses, dtype=np.int64)
        self.positions = np.asarray(beacons.positions_m, dtype=np.float64)
        self.rng = rng
        self.track = VendorTrack(ips)
        self.last_xy: tuple[float, float] | None = None
        # the warm-up (numba's import and cache load, ≈ 0.8 s; a compilation on a cold cache),
        # with the argument types of :meth:`measure`'s: a writable copy (the map's positions
        # are read-only, another specialisation, compiled in the loop: a 2.6-s stall)
        slots, used = self.positions[None].copy(), np.ones((1, len(self.positions)), np.bool_)
        solve_vendor_2d(slots, used.astype(np.float64), used, 0.0, 3, 0.1, engine="compiled")

    def measure(self, t_s: float, pose: tuple[float, float, float]) -> tuple[float, list[bytes]]:
        """(measurement rate in force, frames of the burst) for an emission at ``t_s``: the
        distances, vendor solution, track filter and averaging of
        :func:`~omnical.twin.ips_model.simulate_ips`, one measurement at a time."""
        p, rng = self.p, self.rng
        hedge = hedge_positions_map(np.array([pose]), p.hedge_offset_base_m)
        sel, spacing = select_submap(hedge, self.addresses, self.positions, p.max_beacons)
        rate = float(measurement_rate_hz(spacing, p)[0])
        slots = self.positions[sel[0]]
        d_true = np.linalg.norm(slots - hedge[0], axis=1)
        d_meas, _ = measured_distances(d_true[None], hedge, sel, self.addresses, p, rng)
        d = d_meas[0]
        received = (rng.random(len(d)) >= p.distance_drop_probability) & (d_true <= p.max_range_m)
        if rng.random() < p.measurement_drop_probability:
            return rate, []
        vendor = solve_vendor_2d(
            slots[None],
            d[None],
            received[None],
            p.hedge_offset_base_m[2],
            p.min_beacons_for_fix,
            p.vendor_outlier_rms_m,
            engine="compiled",
        )
        reported = self.track.push(vendor.xy_m[0], bool(vendor.ok[0]))
        vendor = replace(vendor, ok=np.array([reported is not None]))
        q = int(
            quality_percent(
                vendor,
                np.array([len(d)], dtype=np.int64),
                p.quality_residual_scale_m,
                p.quality_hdop_good,
            )[0]
        )
        if reported is not None:
            xy = reported + rng.normal(0.0, 1.0, 2) * p.vendor_jitter_m
            self.last_xy = (float(xy[0]), float(xy[1]))
        # no fix: the last one held, flagged unavailable (simulate_ips's _hold_last_fix)
        position = (
            None if self.last_xy is None else (self.last_xy[0], self.last_xy[1], float(hedge[0, 2]))
        )
        latency_ms = round(1000.0 * (p.latency_s + p.latency_periods / rate))
        sample = HedgehogSample(
            timestamp_ms=round(1000.0 * (p.device_uptime_at_start_s + t_s)) % 2**32,
            position_m=position,
            distances_m=tuple(
                (int(self.addresses[s]), float(v))
                for s, v, ok in zip(sel[0], d, received, strict=True)
                if ok
            ),
            quality_percent=q,
            latency_ms=latency_ms,
            unavailable=reported is None,
        )
        return rate, sample_frames(sample, address=p.hedge_address)

    def beacon_frame(self) -> bytes:
        """The stationary-beacon packet (0x0012)."""
        return encode(
            beacons_record(
                {
                    int(a): (float(x), float(y), float(z))
                    for a, (x, y, z) in zip(self.addresses, self.positions, strict=True)
                }
            )
        )


class TwinDeviceServer:
    """The twin behind two pseudo-terminals, in wall-clock time (docs/DESIGN-NOTES.md).

    Args:
        robot: the robot description.
        params: the twin.
        seed: seed of the twin's noise streams and of the hedgehog's draws.
        beacons: the beacon map (default: seed 000 Table 3).
        config: ports, rates and the command watchdog.
        engine: the twin's engine ("python" by default: no compilation pause at start).
        on_tick: called by the loop with the lock held, after the twin advanced, with the twin
            and the device time since start (s), at every iteration (at least ``tick_hz``); an
            exception in it stops the server as one of the loop's would.
        on_stall: called by the loop with the device time (s) and the pause (wall s) when a
            stall of this process paused the status stream near a host's silence limit.
    """

    def __init__(
        self,
        robot: RobotDescription,
        params: TwinParams,
        *,
        seed: int = 0,
        beacons: BeaconMap | None = None,
        config: DeviceConfig | None = None,
        engine: TwinEngine = "python",
        on_tick: Callable[[DigitalTwin, float], None] | None = None,
        on_stall: Callable[[float, float], None] | None = None,
    ) -> None:
        self.robot = robot
        self.params = params
        self.config = config if config is not None else DeviceConfig()
        self.twin = DigitalTwin(robot, params, seed=seed, engine=engine)
        offset = (
            params.hedge_offset_m if params.hedge_offset_m is not None else robot.hedge_offset_m
        )
        ox, oy, oz = (float(v) for v in offset)
        ips = replace(params.ips, hedge_offset_base_m=(ox, oy, oz))
        self._ips = ips
        self._hedge = _OnlineHedgehog(
            ips,
            beacons if beacons is not None else default_beacon_map(),
            np.random.default_rng([seed, 0x1B5, 0xDE]),
        )
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._vehicle: PseudoTerminal | None = None
        self._hedgehog: PseudoTerminal | None = None
        self._vwriter: PacedWriter | None = None
        self._hwriter: PacedWriter | None = None
        self._history: collections.deque[tuple[float, float, float, float]] = collections.deque(
            maxlen=200 * 600
        )
        self._commands: collections.deque[tuple[float, float, float, float]] = collections.deque(
            maxlen=50 * 600
        )
        self.parser = CommandParser()
        self._on_tick = on_tick
        self._on_stall = on_stall
        self._external: list[tuple[float, float, float, float | None]] = []
        self._wake: tuple[int, int] | None = None
        self.t0_mono = 0.0
        self.t0_wall_ns = 0
        self.commands_applied = 0
        self.last_command: tuple[float, float, float] | None = None
        self.watchdog_trips = 0
        self.error: BaseException | None = None

    @property
    def vehicle_path(self) -> str:
        """The vehicle controller's device path (``/dev/pts/N``)."""
        assert self._vehicle is not None, "server not started"
        return self._vehicle.path

    @property
    def hedge_path(self) -> str:
        """The hedgehog's device path."""
        assert self._hedgehog is not None, "server not started"
        return self._hedgehog.path

    def start(self) -> None:
        """Open the pseudo-terminals and start the twin at the current wall time."""
        self._wake = os.pipe()
        os.set_blocking(self._wake[0], False)
        os.set_blocking(self._wake[1], False)
        self._hedgehog = PseudoTerminal()
        scale = self.config.time_scale
        if self.config.vehicle_port:
            self._vehicle = PseudoTerminal()
            self._vwriter = PacedWriter(
                self._vehicle.master, self.config.baudrate, "twin-vehicle-tx", scale
            )
        self._hwriter = PacedWriter(
            self._hedgehog.master, self.config.hedge_baudrate, "twin-hedge-tx", scale
        )
        self.t0_mono = time.monotonic()
        self.t0_wall_ns = time.time_ns()
        self._thread = threading.Thread(target=self._run, name="twin-device", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the loop and close the ports. Idempotent."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for w in (self._vwriter, self._hwriter):
            if w is not None:
                w.close()
        self._vwriter = self._hwriter = None
        for p in (self._vehicle, self._hedgehog):
            if p is not None:
                p.close()
        if self._wake is not None:
            for fd in self._wake:
                with contextlib.suppress(OSError):
                    os.close(fd)
            self._wake = None

    def command(
        self, vx_mps: float, vy_mps: float, wz_radps: float, sent_wall_ns: int | None = None
    ) -> None:
        """Command a body twist from another thread; the loop applies it at once and counts it
        for the watchdog. ``sent_wall_ns`` (``time.time_ns``): when sent; a command that arrives
        after a stall of this process is applied at that time."""
        at = None
        if sent_wall_ns is not None:
            at = self.t0_mono + (sent_wall_ns - self.t0_wall_ns) / 1e9 * self.config.time_scale
        with self._lock:
            self._external.append((float(vx_mps), float(vy_mps), float(wz_radps), at))
        wake = self._wake
        if wake is not None:
            with contextlib.suppress(BlockingIOError, OSError):
                os.write(wake[1], b"x")

    def __enter__(self) -> TwinDeviceServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def now_s(self) -> float:
        """The device's clock: host monotonic time, run ``time_scale`` times faster from start."""
        t0 = self.t0_mono
        return t0 + (time.monotonic() - t0) * self.config.time_scale

    def serve_forever(self) -> None:
        """Block until :meth:`stop` (from a signal handler or another thread)."""
        while not self._stop.wait(0.2):
            if self.error is not None:
                raise self.error

    # ---------------------------------------------------------------- truth
    def command_history(self) -> list[tuple[float, float, float, float]]:
        """(device time :meth:`now_s`, vx, vy, wz) of every command the twin took, at the time
        it took it (a host's stall shows as a gap)."""
        with self._lock:
            return list(self._commands)

    def truth_history(self) -> list[tuple[float, float, float, float]]:
        """(device time :meth:`now_s`, x, y, yaw) of the true pose at every loop iteration."""
        with self._lock:
            return list(self._history)

    def recording(self) -> Recording:
        """The twin's truth and sensors (``/ground_truth``, ``/odom``, ``/imu``), wall-clock stamped."""
        from omnical.twin.record import write_state_logs  # the runner's modules: not at start

        with self._lock:
            log = self.twin.log()
        builder = RecordingBuilder()
        write_state_logs(builder, log, self.t0_wall_ns)
        return builder.build()

    def snapshot(self) -> DeviceSnapshot:
        """The device's present state, read under the loop's lock (a live view polls it)."""
        with self._lock:
            state = self.twin.read_state()
            x, y, yaw = self.twin.ground_truth_pose
            t_s = self.twin.t_s
            return DeviceSnapshot(
                t_s=float(t_s),
                truth_pose_map=(float(x), float(y), float(yaw)),
                odom_pose=tuple(float(v) for v in state.odom_pose),  # type: ignore[arg-type]
                odom_twist=tuple(float(v) for v in state.odom_twist),  # type: ignore[arg-type]
                last_command=self.last_command,
                commands_applied=self.commands_applied,
                watchdog_trips=self.watchdog_trips,
            )

    # ---------------------------------------------------------------- loop
    def _status_frame(self, twin: DigitalTwin) -> bytes:
        """The 24-byte status frame of the twin's present state."""
        state = twin.read_state()
        status = StatusFrame.from_si(
            state.odom_twist,
            gyro_radps=(0.0, 0.0, state.gyro_z_radps),
            battery_v=self.config.battery_v,
        )
        return encode_status(status)

    def _await_commands(self, sent_after: float, wall_s: float) -> None:
        """After a stall: wait up to ``wall_s`` until a command sent after ``sent_after`` (device
        time) has arrived, so that the ones due during the stall (delivered in order) are applied
        at their times."""
        end = time.monotonic() + wall_s
        while True:
            with self._lock:
                if any(at is None or at > sent_after for *_, at in self._external):
                    return
            if time.monotonic() >= end:
                return
            time.sleep(0.002)

    def _watchdog(self, twin: DigitalTwin, last_cmd: float, until: float, zeroed: bool) -> bool:
        """Stop the twin when the watchdog's time since ``last_cmd`` ran out before ``until``
        (device times), at that moment; whether it stands stopped by the watchdog."""
        limit = self.config.watchdog_s
        if limit is None or zeroed or until - last_cmd <= limit:
            return zeroed
        twin.advance_to(last_cmd + limit - self.t0_mono)
        twin.stop()
        self.watchdog_trips += 1
        return True

    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as err:
            self.error = err

    def _loop(self) -> None:
        assert self._hwriter is not None and self._wake is not None
        cfg = self.config
        vm = self._vehicle.master if self._vehicle is not None else None
        vwriter = self._vwriter
        wake_r = self._wake[0]
        watched = [wake_r] if vm is None else [vm, wake_r]
        t0 = self.t0_mono
        status_period = 1.0 / cfg.status_hz
        scale = cfg.time_scale
        tick = max(1.0 / cfg.tick_hz, 0.001 * scale)  # the wall-clock loop stays ≤ 1 kHz
        clock = self.now_s
        next_status = t0 + status_period
        rng = self._hedge.rng
        next_ips = t0 + float(rng.uniform(0.0, 0.04))
        next_beacons = t0 + self._ips.beacon_first_s
        pending: list[tuple[float, list[bytes]]] = []
        last_cmd = last_now = t0
        recent: collections.deque[tuple[float, float]] = collections.deque(maxlen=9)  # sent, heard
        zeroed = True
        while not self._stop.is_set():
            now = clock()
            wake = min(next_status, next_ips, now + tick, *(t for t, _ in pending[:1]))
            readable, _, _ = select.select(watched, [], [], max(0.0, wake - now) / scale)
            now = clock()
            if vm is None and now - last_now > tick + STALL_GRACE_S * scale:
                # a stall of this process (anywhere in the loop: in on_tick's publishing too):
                # wait for the commands sent meanwhile, applied at their send times, before
                # simulating up to now (the hedgehog waits too). Commands flowing: only when
                # one was due during it, at most STALL_WAIT_S; none flowing (at rest, or the
                # sender quiet): STALL_GRACE_S for one sent during it (a drive's first command:
                # applied once the twin simulated past it, the drive started late)
                due_s = command_due_s(recent, STALL_GRACE_S * scale)
                if zeroed or last_now - last_cmd > STALL_WAIT_S:
                    self._await_commands(last_now, STALL_GRACE_S)
                elif recent and recent[-1][0] + due_s < now:
                    limit = min(STALL_WAIT_S, cfg.watchdog_s or math.inf)
                    self._await_commands(now - due_s, limit / scale)
                now = clock()
            data = b""
            if vm is not None and vm in readable:
                with contextlib.suppress(BlockingIOError, OSError):
                    data = os.read(vm, 4096)
            if wake_r in readable:
                with contextlib.suppress(BlockingIOError, OSError):
                    os.read(wake_r, 4096)
            # the status stream's pause, wall s: a host stops the robot after 3 periods at x1
            # (0.15 s), after SCALED_STALL_S of wall time on a scaled clock (services/hil.py)
            paused_s = (now - next_status + status_period) / scale
            if (
                vwriter is not None
                and self._on_stall is not None
                and paused_s >= max(0.12 if scale == 1.0 else 0.4, 2.5 * status_period / scale)
            ):
                self._on_stall(now - t0, paused_s)
            with self._lock:
                twin = self.twin
                # status frames due during a stall of this loop go out now, each with the
                # twin's state at its own time (the firmware never skips one)
                while vwriter is not None and next_status + status_period <= now:
                    twin.advance_to(next_status - t0)
                    vwriter.put(self._status_frame(twin))
                    next_status += status_period
                external, self._external = self._external, []
                commands = [(at, (vx, vy, wz)) for vx, vy, wz, at in external]
                commands += [(None, cmd.twist) for cmd in self.parser.feed(data)]
                for sent, twist in commands:  # in arrival order: a twin's time only advances
                    if sent is None:  # no send time (serial): when it came
                        at = heard = now
                    elif sent >= t0 + twin.t_s:  # sent during a stall: at its time, the
                        at = heard = min(sent, now)  # watchdog's time checked first
                        zeroed = self._watchdog(twin, last_cmd, at, zeroed)
                    else:  # sent before the time simulated to (late, or a sender's clock
                        at, heard = t0 + twin.t_s, now  # behind): at once; heard now
                    twin.advance_to(at - t0)
                    twin.send_twist(*twist)
                    self._commands.append((at, *twist))
                    self.last_command = twist
                    self.commands_applied += 1
                    last_cmd = heard
                    recent.append((now if sent is None else sent, now))
                    zeroed = False
                zeroed = self._watchdog(twin, last_cmd, now, zeroed)
                twin.advance_to(now - t0)
                last_now = now
                x, y, yaw = twin.ground_truth_pose
                self._history.append((now, x, y, yaw))
                if now >= next_status:
                    if vwriter is not None:
                        vwriter.put(self._status_frame(twin))
                    next_status += status_period
                if self._on_tick is not None:
                    self._on_tick(twin, now - t0)
                if now >= next_ips:
                    t_emit = now - t0
                    jitter = float(rng.uniform(-1.0, 1.0)) * self._ips.timing_jitter_s
                    rate, frames = self._hedge.measure(t_emit, (x, y, yaw))
                    if frames:
                        delay = self._ips.latency_s + self._ips.latency_periods / rate
                        pending.append((now + delay, frames))
                    next_ips = max(now, next_ips + 1.0 / rate + jitter)
            if now >= next_beacons:
                self._hwriter.put(self._hedge.beacon_frame())
                next_beacons += self._ips.beacon_repeat_period_s
            while pending and pending[0][0] <= now:
                _, frames = pending.pop(0)
                self._hwriter.put(b"".join(frames))
