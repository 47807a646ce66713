"""Hardware in the loop: a robot over its serial ports as a rig, and the campaign's bench on it.

:class:`SerialRig` runs experiments on a Wheeltec vehicle controller and a live hedgehog in
wall-clock time; :func:`serial_campaign_bench` makes the campaign's :class:`SerialBench`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from omnical.calibration.procedures.scripts import hull_margin_m
from omnical.drivers.compensation import CompensatingRobot
from omnical.drivers.hedgehog import HedgeFix, SerialHedgehog
from omnical.drivers.safety import Area, check_path, shrink_to_fit
from omnical.drivers.watchdog import GapLog, Watched
from omnical.drivers.wheeltec_serial import SerialRobotState, WheeltecRobot
from omnical.errors import ConfigError, LimitError, ProtocolError, SafetyStopError
from omnical.estimation.fusion import IpsFix
from omnical.estimation.se2 import wrap_angle
from omnical.experiment.rig import TAIL_S, RowSink, run_script_on
from omnical.experiment.script import MotionScript, parse_script
from omnical.ips.beacons import BeaconMap
from omnical.ips.marvelmind.position import PositionFlag
from omnical.kinematics.correction import CorrectionFactors
from omnical.recording.recording import Recording, RecordingBuilder
from omnical.recording.topics import CMD_VEL, EVENTS, HEDGE_POS_ANG, ODOM
from omnical.robot.description import RobotDescription

if TYPE_CHECKING:
    from omnical.twin.lidar import LidarParams

__all__ = [
    "ABORT_KEYS",
    "SCALED_STALL_S",
    "CampaignPlan",
    "DeviceRows",
    "HedgeFixSource",
    "HostClock",
    "LiveHedgehog",
    "LiveLidar",
    "LiveRobot",
    "SerialBench",
    "SerialRig",
    "abort_keys",
    "heading_after_run",
    "hedgehog_start",
    "open_serial_hedgehog",
    "open_serial_robot",
    "plan_procedures",
    "return_home",
    "serial_campaign_bench",
    "serial_devices",
    "wait_for_status",
]

SCALED_STALL_S = 1.0
"""On a time-scaled clock (tests only): the wall time a device may be silent during motion."""
FLUSH_EVERY_S = 0.5


@dataclass(frozen=True)
class HostClock:
    """The host's robot-time clock: the monotonic clock, ``time_scale`` times faster from start.

    Attributes:
        time_scale: robot seconds per wall second (1 on a robot; > 1 only against a device
            server on the same scale, in tests).
        origin_s: monotonic time the scaling starts from.
    """

    time_scale: float = 1.0
    origin_s: float = field(default_factory=time.monotonic)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.time_scale) and 0.1 <= self.time_scale <= 100.0):
            msg = f"time scale must be within 0.1–100, got {self.time_scale}"
            raise ConfigError(msg)

    def now_s(self) -> float:
        """Robot time, s (the monotonic clock itself at scale 1)."""
        return self.origin_s + (time.monotonic() - self.origin_s) * self.time_scale

    def sleep_s(self, duration_s: float) -> None:
        """Sleep ``duration_s`` of robot time."""
        if duration_s > 0:
            time.sleep(duration_s / self.time_scale)

    def wall_ns(self) -> int:
        """Wall-clock ns now (``time.time_ns``; bag stamps advance in robot time from it)."""
        return time.time_ns()


class _MonoClock:
    """Robot time for the Runner, seconds since ``t0`` on the host clock."""

    def __init__(self, t0: float, host: HostClock) -> None:
        self.t0 = t0
        self.host = host

    def now_s(self) -> float:
        return self.host.now_s() - self.t0

    def sleep_until(self, t_s: float) -> None:
        self.host.sleep_s(t_s - self.now_s())


ABORT_KEYS = frozenset({b" ", b"q", b"Q", b"\x1b"})
"""Space, q and Esc stop a serial run as Ctrl-C does."""


class _AbortWatch:
    """Reads single keys from the controlling terminal in a thread (see :func:`abort_keys`)."""

    def __init__(self, fd: int) -> None:
        import termios
        import tty

        self.fd = fd
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)  # keys one by one, no echo; Ctrl-C still raises SIGINT
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="abort-keys", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import _thread
        import select

        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self.fd], [], [], 0.05)
                key = os.read(self.fd, 1) if ready else b""
            except OSError:
                return
            if key in ABORT_KEYS:
                _thread.interrupt_main()  # a KeyboardInterrupt in the run: zero command
                return

    def close(self) -> None:
        import termios

        self._stop.set()
        self._thread.join(timeout=1.0)
        with contextlib.suppress(OSError, termios.error):
            termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)


@contextlib.contextmanager
def abort_keys(enabled: bool = True) -> Iterator[_AbortWatch | None]:
    """While inside: space, ``q`` or Esc on the terminal raise ``KeyboardInterrupt`` in the run.

    Active only when ``enabled``, stdin is a terminal and this process is in its foreground;
    yields the watch or None; the terminal's mode is restored on leaving.
    """
    watch: _AbortWatch | None = None
    if enabled:
        with contextlib.suppress(OSError, ValueError, AttributeError, ImportError):
            fd = sys.stdin.fileno()
            if os.isatty(fd) and os.tcgetpgrp(fd) == os.getpgrp():
                watch = _AbortWatch(fd)
    try:
        yield watch
    finally:
        if watch is not None:
            watch.close()


def open_serial_robot(
    port: str,
    baudrate: int,
    robot: RobotDescription,
    clock: HostClock,
    *,
    host_watchdog_s: float | None,
) -> WheeltecRobot:
    """The vehicle controller's driver on ``port``, stamping with ``clock``.

    Safety stop after 3 status periods (0.15 s) of silence during motion, a lost link after
    1 s; on a k-times clock (tests) these limits and ``host_watchdog_s`` are wall time
    (:data:`SCALED_STALL_S` and 1 s).
    """
    from omnical.drivers.wheeltec_serial import STATUS_PERIOD_S, open_wheeltec_port

    k = clock.time_scale
    return WheeltecRobot(
        open_wheeltec_port(port, baudrate, read_timeout_s=0.005 / k),
        robot=robot,
        # the host's own stall, wall time too: k times longer in robot time on a k-times clock
        host_watchdog_s=None if host_watchdog_s is None else host_watchdog_s * k,
        max_gap_s=1.0 * k,
        watchdog_s=3 * STATUS_PERIOD_S if k == 1.0 else SCALED_STALL_S * k,
        clock=clock.now_s,
        name=f"vehicle controller on {port}",
    )


def open_serial_hedgehog(port: str, baudrate: int, clock: HostClock) -> SerialHedgehog:
    """The hedgehog on ``port``, stamping with ``clock`` (its silence limit at least 0.3 s; on
    a k-times clock, :data:`SCALED_STALL_S` of wall time)."""
    k = clock.time_scale
    floor_s = 0.3 if k == 1.0 else SCALED_STALL_S * k
    return SerialHedgehog.open(port, baudrate, clock=clock.now_s, min_limit_s=floor_s)


@contextlib.contextmanager
def serial_devices(
    robot_port: str,
    baudrate: int,
    hedge_port: str | None,
    hedge_baudrate: int,
    robot: RobotDescription,
    clock: HostClock,
    *,
    host_watchdog_s: float | None,
    say: Callable[[str], None],
) -> Iterator[tuple[WheeltecRobot, SerialHedgehog | None]]:
    """The vehicle controller and the hedgehog (``hedge_port`` None: none) on their ports,
    checked before anything moves: a valid status frame (its battery said), no stop flag.
    Leaving closes both, the driver first (a zero command), whatever happened.

    Raises:
        DriverError: a port cannot be opened.
        ProtocolError: no valid status frame.
        LimitError: the controller's stop flag is set (E-stop, low battery).
    """
    driver = open_serial_robot(robot_port, baudrate, robot, clock, host_watchdog_s=host_watchdog_s)
    hedgehog: SerialHedgehog | None = None
    try:
        wait_for_status(driver)
        state = driver.read_state()
        say(f"vehicle controller on {robot_port}: battery {state.battery_v:.2f} V")
        if state.stop_flag:
            msg = "the controller reports its motors disabled (stop flag: E-stop or low battery)"
            raise LimitError(msg)
        if hedge_port is not None:
            hedgehog = open_serial_hedgehog(hedge_port, hedge_baudrate, clock)
        yield driver, hedgehog
    finally:
        driver.close()
        if hedgehog is not None:
            hedgehog.close()


def wait_for_status(robot: WheeltecRobot, timeout_s: float = 2.0) -> None:
    """Wait for the first valid status frame (any since the port opened: whether the stream
    keeps up is the silence limits' part, once the robot moves).

    Raises:
        ProtocolError: none within ``timeout_s`` (wrong port or baud rate, controller off).
    """
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if math.isfinite(robot.read_state().age_s):
            return
        time.sleep(0.01)
    msg = (
        f"no valid status frame from the vehicle controller within {timeout_s:.1f} s "
        "(wrong port or baud rate, controller off, or still in its 10-s power-on delay)"
    )
    raise ProtocolError(msg)


DeviceRows = Mapping[str, tuple[np.ndarray, Mapping[str, np.ndarray]]]
"""What a live device logged since the last drain: ``topic -> (host times s, {column: values})``."""


class LiveRobot(Watched, Protocol):
    """A robot's driver as :class:`SerialRig` drives it (Wheeltec serial, a ROS 2 robot's topics).

    Besides the :class:`~omnical.experiment.ports.Robot` port: a safety stop when it or a
    required device falls silent during motion (:class:`SafetyStopError` from the next motion
    command), a zero command when the host stops calling, its rows in ``drain_rows``.
    """

    def send_twist(self, vx_mps: float, vy_mps: float, wz_radps: float) -> None: ...

    def read_state(self) -> SerialRobotState: ...

    def stop(self) -> None: ...

    def require(self, device: Watched) -> None: ...

    def release(self, device: Watched) -> None: ...

    def reset_odometry(self, pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None: ...

    def set_odometry_correction(self, factors: CorrectionFactors | None) -> None: ...

    def drain_rows(self) -> DeviceRows: ...

    def close(self) -> None: ...


class LiveHedgehog(Watched, Protocol):
    """The positioning system live: :class:`~omnical.drivers.hedgehog.SerialHedgehog`, or a
    ROS 2 position topic. ``beacons``: address → (x, y, z) m as streamed (may stay empty)."""

    @property
    def beacons(self) -> Mapping[int, tuple[float, float, float]]: ...

    def latest_fix(self) -> HedgeFix | None: ...

    def drain(self) -> DeviceRows: ...

    def close(self) -> None: ...


class LiveLidar(Protocol):
    """A live 2-D LiDAR (a ROS 2 robot's ``/scan``): its beams, its newest ranges, its rows."""

    def lidar_params(self) -> LidarParams: ...

    def scan_now(self) -> NDArray[np.float64]: ...

    def scan_age_s(self) -> float:
        """How long ago (robot time, s) the rays of the newest scan were taken."""
        ...

    def drain(self) -> DeviceRows: ...


class _Recorder:
    """Drains the driver and the hedgehog into a sink, stamped from one time base."""

    def __init__(
        self,
        sink: RowSink,
        robot: LiveRobot,
        hedge: LiveHedgehog | None,
        t0: float,
        host: HostClock,
        *,
        on_warning: Callable[[str], None] | None = None,
        flush_every_s: float = FLUSH_EVERY_S,
        lidar: LiveLidar | None = None,
    ) -> None:
        self.sink, self.robot, self.hedge, self.t0, self.host = sink, robot, hedge, t0, host
        self.flush_every_s = flush_every_s
        self.lidar = lidar
        self.wall0_ns = host.wall_ns() - round((host.now_s() - t0) * 1e9)
        self.counts: dict[str, int] = {}
        self._last = host.now_s()
        self.gaps = GapLog()
        self.watch_gaps = hedge is not None
        self.on_warning = on_warning

    def ns(self, t_rel_s: Any) -> np.ndarray:
        return self.wall0_ns + np.round(np.asarray(t_rel_s, dtype=np.float64) * 1e9).astype(
            np.int64
        )

    def _write(self, topic: str, t_rel: Any, **cols: Any) -> None:
        n = len(np.asarray(t_rel))
        if n == 0:
            return
        self.sink.write_rows(topic, self.ns(t_rel), **cols)
        self.counts[topic] = self.counts.get(topic, 0) + n

    def maybe_drain(self) -> None:
        now = self.host.now_s()
        if self.hedge is not None and self.watch_gaps:
            line = self.gaps.update(self.hedge.silence(now), now - self.t0)
            if line is not None and self.on_warning is not None:
                self.on_warning(line)
        if now - self._last >= self.flush_every_s * self.host.time_scale:
            self.drain()

    def write_rows(self, topic: str, t_rel: Any, **cols: Any) -> None:
        """Rows stamped in robot seconds since ``t0``."""
        self._write(topic, t_rel, **cols)

    def write_events(self, events: list[tuple[float, str]]) -> None:
        """``/omnical/events``: ``events`` (robot seconds since ``t0``) and the gaps, in order."""
        if self.hedge is not None and self.watch_gaps:
            now = self.host.now_s()
            self.gaps.close(self.hedge.silence(now), now - self.t0)
        merged = sorted([*events, *self.gaps.events], key=lambda e: e[0])
        if merged:
            self._write(
                EVENTS,
                np.array([t for t, _ in merged], dtype=np.float64),
                text=np.array([e for _, e in merged], dtype=object),
            )

    def drain(self) -> None:
        self._last = self.host.now_s()
        drained = [self.robot.drain_rows()]
        drained += [d.drain() for d in (self.hedge, self.lidar) if d is not None]
        for rows in drained:
            for topic, (times, cols) in rows.items():
                self._write(topic, times - self.t0, **cols)


@dataclass
class SerialRig:
    """A robot over its serial ports as a :class:`~omnical.experiment.rig.Rig`, in robot time.

    A session commands the robot (through :class:`CompensatingRobot` when factors are
    installed), records its status stream and the hedgehog into the sink from one time base and
    watches the abort keys. A silent controller is a safety stop; so is a silent hedgehog when
    the session requires positions, else its gaps are marked and said to ``on_warning``.

    Attributes:
        robot: the open driver.
        hedge: the open hedgehog, or None.
        clock: the host's robot-time clock (the driver and the hedgehog stamp with it).
        abort_key: space, q or Esc on the terminal stop a run as Ctrl-C does.
        on_warning: receives a line when the hedgehog falls silent or comes back.
        messages: rows written per topic, over every session.
        flush_every_s: how often (robot time) the devices are drained into the sink.
        lidar: a live LiDAR (a ROS 2 robot's ``/scan``) to localise on and record, or None.
    """

    robot: LiveRobot
    hedge: LiveHedgehog | None
    clock: HostClock = field(default_factory=HostClock)
    abort_key: bool = True
    on_warning: Callable[[str], None] | None = None
    messages: dict[str, int] = field(default_factory=dict)
    flush_every_s: float = FLUSH_EVERY_S
    lidar: LiveLidar | None = None

    @property
    def sources(self) -> frozenset[str]:
        """Odometry, and odometry fused with the hedgehog's fixes if there is one."""
        return frozenset({"odometry"} if self.hedge is None else {"odometry", "fused"})

    @contextlib.contextmanager
    def session(
        self,
        sink: RowSink,
        *,
        installed: CorrectionFactors | None = None,
        require_positions: bool = False,
    ) -> Iterator[_SerialSession]:
        """A run recorded into ``sink``; leaving it stops the robot and drains the devices."""
        robot, host = self.robot, self.clock
        t0 = host.now_s()
        rec = _Recorder(
            sink, robot, self.hedge, t0, host, on_warning=self.on_warning,
            flush_every_s=self.flush_every_s, lidar=self.lidar,
        )  # fmt: skip
        port: Any = robot if installed is None else CompensatingRobot(robot, installed)
        required = self.hedge if require_positions else None
        if required is not None:
            rec.watch_gaps = False  # required: a silence is a safety stop, not a gap
            robot.require(required)
        try:
            with abort_keys(self.abort_key):
                session_port = _SessionPort(port, t0)
                yield _SerialSession(session_port, _MonoClock(t0, host), rec, self.hedge)
        finally:
            robot.stop()
            if required is not None:
                robot.release(required)
            rec.drain()
            if isinstance(port, CompensatingRobot):
                port.release()
            for topic, n in rec.counts.items():
                self.messages[topic] = self.messages.get(topic, 0) + n


class HedgeFixSource:
    """A :class:`~omnical.estimation.fusion.FixSource` on a live hedgehog: its newest position,
    once (a second fix arriving between two polls is skipped)."""

    def __init__(self, hedge: LiveHedgehog, clock: HostClock, t0: float) -> None:
        self.hedge, self.clock, self.t0 = hedge, clock, t0
        self._last_t: float | None = None

    def poll(self) -> list[IpsFix]:
        """The fix that arrived since the previous poll, if any (session times)."""
        fix = self.hedge.latest_fix()
        if fix is None or fix.t_s == self._last_t:
            return []
        self._last_t = fix.t_s
        return [IpsFix(fix.t_s - self.t0, self.clock.now_s() - self.t0, fix.x_m, fix.y_m)]


class _SessionPort:
    """The robot port of a session: its states stamped in session time (clock seconds)."""

    def __init__(self, port: Any, t0: float) -> None:
        self.port, self.t0 = port, t0

    def send_twist(self, vx_mps: float, vy_mps: float, wz_radps: float) -> None:
        self.port.send_twist(vx_mps, vy_mps, wz_radps)

    def read_state(self) -> Any:
        state = self.port.read_state()
        return dataclasses.replace(state, t_s=state.t_s - self.t0)

    def stop(self) -> None:
        self.port.stop()


class _SerialSession:
    """One run of a :class:`SerialRig`."""

    def __init__(
        self, port: Any, clock: _MonoClock, rec: _Recorder, hedge: LiveHedgehog | None
    ) -> None:
        self._port, self._clock, self.rec, self._hedge = port, clock, rec, hedge
        self.origin_ns = rec.wall0_ns
        self._fixes: HedgeFixSource | None = None

    @property
    def robot(self) -> Any:
        return self._port

    @property
    def clock(self) -> _MonoClock:
        return self._clock

    def hold(self, duration_s: float) -> None:
        _hold(self.rec.robot, self._clock, duration_s, self.rec)

    def poll(self) -> None:
        self.rec.maybe_drain()

    def fixes(self) -> HedgeFixSource:
        """The live hedgehog's fixes (ConfigError: no hedgehog)."""
        if self._hedge is None:
            msg = "no hedgehog: give --hedge serial:PORT to localise the robot"
            raise ConfigError(msg)
        if self._fixes is None:
            self._fixes = HedgeFixSource(self._hedge, self.rec.host, self._clock.t0)
        return self._fixes

    def own_pose_source(self, choice: str) -> Any:
        """ConfigError: the ground truth and the seed 003 estimate exist on a twin only."""
        msg = f"a serial robot has no {choice!r} pose source (a twin has)"
        raise ConfigError(msg)

    def lidar_params(self) -> Any:
        """The rig's LiDAR (ConfigError: none; a serial robot has no LiDAR driver)."""
        if self.rec.lidar is None:
            msg = (
                "this robot has no LiDAR (none over serial, no /scan): localise it by its hedgehog"
            )
            raise ConfigError(msg)
        return self.rec.lidar.lidar_params()

    def scan_now(self) -> Any:
        """The LiDAR's newest ranges, m (ConfigError: no LiDAR)."""
        self.lidar_params()
        assert self.rec.lidar is not None
        return self.rec.lidar.scan_now()

    def scan_age_s(self) -> float:
        """How long ago (robot time, s) the newest scan's rays were taken (ConfigError: no LiDAR)."""
        self.lidar_params()
        assert self.rec.lidar is not None
        return self.rec.lidar.scan_age_s()

    def alarm(self) -> str:
        """The controller's stop flag (E-stop, low battery) while it is raised, else ""."""
        if self.rec.robot.read_state().stop_flag:
            return "the controller raised its stop flag (E-stop or low battery)"
        return ""

    def ground_truth(self) -> None:
        """None: the truth is the device server's (``twin serve --truth-out``)."""
        return

    def estimates(self) -> None:
        """None: a serial robot has no pose source of its own."""
        return

    def finish(self, cmd_vel: np.ndarray, events: Sequence[tuple[float, str]]) -> None:
        self.rec.drain()
        self.rec.write_rows(
            CMD_VEL, cmd_vel[:, 0], vx_mps=cmd_vel[:, 1], vy_mps=cmd_vel[:, 2],
            wz_radps=cmd_vel[:, 3],
        )  # fmt: skip
        self.rec.write_events(list(events))


def _hold(robot: LiveRobot, clock: _MonoClock, duration_s: float, rec: _Recorder) -> None:
    end = clock.now_s() + duration_s
    while clock.now_s() < end:
        robot.send_twist(0.0, 0.0, 0.0)  # keeps the host watchdog fed
        rec.maybe_drain()
        clock.sleep_until(min(end, clock.now_s() + 0.05))


# ----------------------------------------------------------------------------- the campaign


_PROCEDURES: dict[str, Callable[[float], dict[str, Any]]] = {}


def _procedure_factories() -> dict[str, Callable[[float], dict[str, Any]]]:
    """Seed 000's procedures by script name, as ``make(scale)`` (1 = run_campaign's size)."""
    if not _PROCEDURES:
        from omnical.calibration.procedures.scripts import (
            lateral_procedure,
            longitudinal_procedure,
            rotation_procedure,
        )

        _PROCEDURES.update(
            {
                "rotation-procedure": lambda k: rotation_procedure(
                    distance_m=2.5 * k, approach_left_m=1.0 * k
                ),
                "longitudinal-procedure": lambda k: longitudinal_procedure(distance_m=3.5 * k),
                "lateral-procedure": lambda k: lateral_procedure(
                    distance_m=3.0 * k, reference_m=3.5 * k
                ),
            }
        )
    return _PROCEDURES


@dataclass(frozen=True)
class CampaignPlan:
    """The procedures as they will run from the home pose, checked before the first motion.

    Attributes:
        home_pose_map: (x, y, yaw) of base_link where every procedure starts.
        scripts: procedure name → the script to run (shrunk if it had to be).
        scales: procedure name → its size relative to the campaign's (1.0: unchanged).
        coverage_margin_m: procedure name → how far its path stays inside the beacon coverage.
    """

    home_pose_map: tuple[float, float, float]
    scripts: Mapping[str, MotionScript]
    scales: Mapping[str, float]
    coverage_margin_m: Mapping[str, float]

    def summary(self) -> list[str]:
        """One line per procedure."""
        return [
            f"{name}: {self.scales[name]:.0%} of its size, "
            f"{self.coverage_margin_m[name]:.2f} m inside the beacon coverage"
            for name in self.scripts
        ]


def plan_procedures(
    robot: RobotDescription,
    home_pose_map: tuple[float, float, float],
    beacons: BeaconMap,
    *,
    margin_m: float = 0.3,
    allowed: Area | None = None,
    min_scale: float = 0.5,
) -> CampaignPlan:
    """Check each of seed 000's procedures from ``home_pose_map``; shrink the ones that leave.

    Raises:
        LimitError: a procedure does not fit even at ``min_scale`` of its size (the reason).
    """
    scripts: dict[str, MotionScript] = {}
    scales: dict[str, float] = {}
    margins: dict[str, float] = {}
    for name, make in _procedure_factories().items():

        def compiled(k: float, make: Callable[[float], dict[str, Any]] = make) -> MotionScript:
            return parse_script(make(k), robot.limits)

        script, scale = shrink_to_fit(
            compiled,
            home_pose_map,
            beacons,
            margin_m=margin_m,
            allowed=allowed,
            min_scale=min_scale,
        )
        verdict = check_path(script, home_pose_map, beacons, margin_m=margin_m, allowed=allowed)
        scripts[name], scales[name], margins[name] = script, scale, verdict.coverage_margin_m
    return CampaignPlan(home_pose_map, scripts, scales, margins)


def _base_from_hedge(
    robot: RobotDescription, xy: tuple[float, float], yaw: float
) -> tuple[float, float]:
    ox, oy = float(robot.hedge_offset_m[0]), float(robot.hedge_offset_m[1])
    c, s = math.cos(yaw), math.sin(yaw)
    return xy[0] - (c * ox - s * oy), xy[1] - (s * ox + c * oy)


def _hedge_at_rest(rec: Recording, t_from_ns: int, t_to_ns: int) -> tuple[float, float] | None:
    """Median hedgehog position between two stamps (None: fewer than 3 fixes)."""
    if not rec.has(HEDGE_POS_ANG):
        return None
    tab = rec.topic(HEDGE_POS_ANG)
    t = np.asarray(tab.t_ns, dtype=np.int64)
    unavailable = int(PositionFlag.COORDINATES_UNAVAILABLE)
    ok = (t >= t_from_ns) & (t <= t_to_ns) & ((np.asarray(tab["flags"]) & unavailable) == 0)
    if int(ok.sum()) < 3:
        return None
    return float(np.median(np.asarray(tab["x_m"])[ok])), float(
        np.median(np.asarray(tab["y_m"])[ok])
    )


def _last_straight_move(rec: Recording) -> tuple[int, int] | None:
    """(start, end) stamps of the run's last translation without rotation command."""
    if not rec.has(CMD_VEL):
        return None
    cmd = rec.topic(CMD_VEL)
    t = np.asarray(cmd.t_ns, dtype=np.int64)
    moving = np.hypot(np.asarray(cmd["vx_mps"]), np.asarray(cmd["vy_mps"])) > 1e-6
    straight = moving & (np.abs(np.asarray(cmd["wz_radps"])) < 1e-6)
    idx = np.flatnonzero(straight)
    if len(idx) == 0:
        return None
    end = int(idx[-1])
    start = end
    while start > 0 and straight[start - 1]:
        start -= 1
    return int(t[start]), int(t[min(end + 1, len(t) - 1)])


def heading_after_run(
    rec: Recording, previous_heading_rad: float | None = None
) -> tuple[float | None, float]:
    """The robot's heading in the map at the end of a run, and the translation it came from.

    The map←odometry rotation over the run's last straight move (the hedgehog at rest before
    and after it vs the odometry) turns the odometry's final yaw into the map. A move shorter
    than 0.3 m gives no heading: ``previous_heading_rad`` plus the odometry's yaw change.

    Returns:
        (heading or None, length of the move used in m).
    """
    odom = rec.topic(ODOM) if rec.has(ODOM) else None
    if odom is None or len(odom.t_ns) == 0:
        return previous_heading_rad, 0.0
    t_o = np.asarray(odom.t_ns, dtype=np.int64)
    x, y = np.asarray(odom["x_m"]), np.asarray(odom["y_m"])
    yaw = np.unwrap(np.asarray(odom["yaw_rad"]))
    move = _last_straight_move(rec)
    if move is not None:
        a, b = move
        settle, window = 300_000_000, 1_500_000_000
        before = _hedge_at_rest(rec, a - window, a - 50_000_000)
        after = _hedge_at_rest(rec, b + settle + 200_000_000, b + settle + window)
        if before is not None and after is not None:
            dh = np.subtract(after, before)
            ta, tb = a - window // 2, b + settle + window // 2
            do = (
                np.interp(tb, t_o, x) - np.interp(ta, t_o, x),
                np.interp(tb, t_o, y) - np.interp(ta, t_o, y),
            )
            length = float(np.hypot(*dh))
            if length >= 0.3 and math.hypot(*do) >= 0.3:
                rot = math.atan2(dh[1], dh[0]) - math.atan2(do[1], do[0])
                return wrap_angle(float(yaw[-1]) + rot), length
    if previous_heading_rad is None:
        return None, 0.0
    return wrap_angle(previous_heading_rad + float(yaw[-1] - yaw[0])), 0.0


@dataclass
class _Homing:
    """What the bench knows of where the robot is (mutable, private to :class:`SerialBench`)."""

    home: tuple[float, float, float]
    heading_rad: float
    position: tuple[float, float] | None = None
    residual_m: float = 0.0


def return_home(
    bench: SerialBench,
    installed: CorrectionFactors,
    *,
    tolerance_m: float = 0.03,
    attempts: int = 3,
) -> float:
    """Drive back to the home pose: turn to its heading, then translate until within tolerance.

    Heading from the last run (:func:`heading_after_run`), position from the hedgehog at rest
    after every move; each move runs with ``installed`` compensating, is checked against the
    beacon coverage and is not recorded in the campaign.

    Returns:
        The distance to home left after the last move, m.

    Raises:
        LimitError: the hedgehog gave no position at rest, or a homing move would leave the
            coverage.
    """
    state, robot = bench.homing, bench.robot_description
    assert state is not None and robot is not None, "homing needs a home and a description"
    hx, hy, hyaw = state.home
    turn = wrap_angle(hyaw - state.heading_rad)
    if abs(turn) > math.radians(1.0):
        rate = math.copysign(0.5, turn)
        rec = bench.run_raw(
            {"name": "home-turn", "steps": [
                {"move": {"wz_radps": rate, "angle_deg": math.degrees(abs(turn))}}
            ]},
            installed,
        )  # fmt: skip
        turned, _ = heading_after_run(rec, state.heading_rad)
        state.heading_rad = turned if turned is not None else hyaw
    left = math.inf
    for _ in range(attempts):
        if state.position is None and bench.hedge is not None:
            state.position = _hedge_median(bench.hedge, bench.clock, 1.0)
        if state.position is None:
            msg = "no hedgehog position at rest to drive home from: refusing to move"
            raise LimitError(msg)
        bx, by = _base_from_hedge(robot, state.position, state.heading_rad)
        dx, dy = hx - bx, hy - by
        left = math.hypot(dx, dy)
        if left <= tolerance_m:
            break
        c, s = math.cos(state.heading_rad), math.sin(state.heading_rad)
        bxv, byv = c * dx + s * dy, -s * dx + c * dy  # map → body
        speed = 0.2 if left > 0.3 else 0.1
        script = {
            "name": "home",
            "steps": [{"move": {
                "vx_mps": speed * bxv / left, "vy_mps": speed * byv / left, "distance_m": left,
            }}],
        }  # fmt: skip
        compiled = parse_script(script, robot.limits)
        if bench.beacons is not None:
            # home is inside the coverage and the hull is convex: a straight move home never
            # goes further out than where the robot stands (if a run ended outside it)
            here = hull_margin_m(np.array([[bx, by]]), bench.beacons)
            verdict = check_path(
                compiled,
                (bx, by, state.heading_rad),
                bench.beacons,
                margin_m=min(0.0, here) - 0.05,
            )
            if not verdict.ok:
                raise LimitError(f"refused to drive home: {verdict.reason}")
        rec = bench.run_raw(script, installed)
        heading, _ = heading_after_run(rec, state.heading_rad)
        state.heading_rad = heading if heading is not None else state.heading_rad
    state.residual_m = left
    return left


@dataclass
class SerialBench:
    """The campaign's ``Bench`` on a serial base: factors applied host-side, runs in robot time.

    Every run goes through :class:`CompensatingRobot` with the run's factors; with ``homing``
    the robot drives home before every run but the first (:func:`return_home`); every
    recording is kept in ``recordings`` as soon as it is made.

    Attributes:
        robot: the open driver.
        hedge: the open hedgehog.
        robot_description: the robot (limits of the homing moves, hedgehog offset).
        before_run: called with the run's name before it moves (None: nothing).
        plan: the checked procedures (None: run the scripts as given, unchecked).
        beacons: the beacon map (homing moves are checked against it).
        homing: where home is and what is known of the robot's pose (None: no homing).
        clock: the host's robot-time clock.
        abort_key: watch the terminal for the abort keys during runs.
        recordings: name → recording of every finished run (a stopped one as ``NAME-stopped``).
        stopped_run: what the last run recorded if a stop ended it.
        on_message: receives one line per homing and shrink decision.
        margin_m: margin inside the coverage of a run checked where it starts (no homing).
        allowed: the allowed area of that check.
        tee: wraps each run's sink (a live view: rows also to the monitor, as they come).
    """

    robot: LiveRobot
    hedge: LiveHedgehog | None
    robot_description: RobotDescription | None = None
    before_run: Callable[[str], None] | None = None
    plan: CampaignPlan | None = None
    beacons: BeaconMap | None = None
    homing: _Homing | None = None
    clock: HostClock = field(default_factory=HostClock)
    abort_key: bool = True
    recordings: dict[str, Recording] = field(default_factory=dict)
    stopped_run: Recording | None = None
    on_message: Callable[[str], None] | None = None
    margin_m: float = 0.3
    allowed: Area | None = None
    tee: Callable[[RowSink], RowSink] | None = None
    _runs: int = 0

    def run_raw(
        self,
        script: MotionScript | Mapping[str, Any],
        installed: CorrectionFactors,
        on_tick: Callable[[float, float], None] | None = None,
    ) -> Recording:
        """Run a script now with ``installed`` compensating; its recording (not kept).

        Raises:
            KeyboardInterrupt: the run was interrupted (the robot was stopped).
        """
        if not isinstance(script, MotionScript):
            assert self.robot_description is not None
            script = parse_script(dict(script), self.robot_description.limits)
        self.robot.reset_odometry()
        if self.hedge is not None:
            self.hedge.drain()
        self.robot.drain_rows()
        builder = RecordingBuilder()
        rig = SerialRig(self.robot, self.hedge, self.clock, self.abort_key)
        if self.tee is not None:
            rig.flush_every_s = 0.05  # the live view at the status stream's rate
        log = run_script_on(
            rig,
            script,
            builder if self.tee is None else self.tee(builder),
            installed=installed,  # the campaign adds the installed_factors event itself
            require_positions=True,  # the procedures' analysis and the homing need its ranges
            on_tick=on_tick,
        )
        if log.interrupted:
            self.stopped_run = builder.build()  # what the stopped run recorded, for its caller
            raise log.interruption or KeyboardInterrupt()
        recording = builder.build()
        if self.homing is not None:
            tab = recording.topic(CMD_VEL)
            end = int(np.asarray(tab.t_ns)[-1])
            self.homing.position = _hedge_at_rest(
                recording, end + 300_000_000, end + round(TAIL_S * 1e9)
            )
        return recording

    def run(
        self,
        script: MotionScript,
        installed: CorrectionFactors,
        *,
        name: str,
        on_tick: Callable[[float, float], None] | None = None,
    ) -> Recording:
        """Run ``script`` with ``installed`` compensating host-side; the recording in memory."""
        if self.plan is not None and script.name in self.plan.scripts:
            script = self.plan.scripts[script.name]
        if self.homing is not None and self._runs > 0:
            self._say(f"{name}: driving home first")  # the homing moves take a while
            left = return_home(self, installed)
            self._say(f"{name}: drove home ({left * 100:.1f} cm from it)")
        if self.before_run is not None:
            self.before_run(name)
        if self.homing is None and self._runs > 0:
            self._check_here(script)
        self.stopped_run = None
        try:
            recording = self.run_raw(script, installed, on_tick)
        except (KeyboardInterrupt, SafetyStopError):
            if self.stopped_run is not None and self.stopped_run.message_count:
                self.recordings[f"{name}-stopped"] = _with_installed(self.stopped_run, installed)
            raise
        self._runs += 1
        self.recordings[name] = _with_installed(
            recording, installed
        )  # kept before anything is said
        if self.homing is not None:
            heading, length = heading_after_run(recording, self.homing.heading_rad)
            if heading is not None:
                self.homing.heading_rad = heading
            pos = self.homing.position
            where = "?" if pos is None else f"({pos[0]:.2f}, {pos[1]:.2f}) m"
            if pos is not None and self.beacons is not None:
                outside = -hull_margin_m(np.array([pos]), self.beacons)
                if outside > 0.0:
                    self._say(
                        f"{name}: ended {outside:.2f} m outside the beacon coverage (the robot's "
                        "errors took it off the checked path): give a larger --margin"
                    )
            self._say(
                f"{name}: hedgehog at rest at {where}, heading "
                f"{math.degrees(self.homing.heading_rad):.1f}° (from a {length:.1f} m move)"
            )
        return recording

    def _check_here(self, script: MotionScript) -> None:
        """Without homing: check the run's path from where the robot stands (home heading).

        Raises:
            LimitError: the path leaves the coverage or the area from here.
        """
        if self.plan is None or self.hedge is None or self.beacons is None:
            return
        assert self.robot_description is not None
        yaw = self.plan.home_pose_map[2]
        bx, by = _base_from_hedge(
            self.robot_description, _hedge_median(self.hedge, self.clock, 1.0), yaw
        )
        verdict = check_path(
            script, (bx, by, yaw), self.beacons, margin_m=self.margin_m, allowed=self.allowed
        )
        if not verdict.ok:
            msg = f"refused from ({bx:.2f}, {by:.2f}) m: {verdict.reason}"
            raise LimitError(msg)

    def _say(self, line: str) -> None:
        if self.on_message is not None:
            self.on_message(line)


def _with_installed(recording: Recording, installed: CorrectionFactors) -> Recording:
    from omnical.calibration.campaign import with_installed_event

    return with_installed_event(recording, installed)


def _wait_for_hedgehog(
    hedge: LiveHedgehog, beacons: BeaconMap | None, clock: HostClock, timeout_s: float
) -> BeaconMap:
    """The beacon map (given, else as streamed) once the hedgehog gives positions.

    Raises:
        LimitError: no position, or no beacon map, within ``timeout_s`` of robot time (of wall
            time on a scaled clock: starting up is not part of the experiment).
    """
    end = clock.now_s() + timeout_s * max(1.0, clock.time_scale)
    while clock.now_s() < end:
        if hedge.latest_fix() is not None and (beacons is not None or len(hedge.beacons) >= 3):
            break
        clock.sleep_s(0.02)
    if beacons is None and len(hedge.beacons) >= 3:
        addrs = sorted(hedge.beacons)
        beacons = BeaconMap(np.array(addrs), np.array([hedge.beacons[a] for a in addrs]))
    if hedge.latest_fix() is None or beacons is None:
        msg = "no position or beacon map from the hedgehog: refusing to move"
        raise LimitError(msg)
    return beacons


def _hedge_median(hedge: LiveHedgehog, clock: HostClock, duration_s: float) -> tuple[float, float]:
    """Median hedgehog position over ``duration_s`` of robot time (the robot standing still)."""
    hedge.drain()
    clock.sleep_s(duration_s)
    rows = hedge.drain().get(HEDGE_POS_ANG)
    if rows is None:
        msg = "no hedgehog position while standing still: refusing to move"
        raise LimitError(msg)
    _, cols = rows
    ok = (np.asarray(cols["flags"]) & int(PositionFlag.COORDINATES_UNAVAILABLE)) == 0
    if int(ok.sum()) < 3:
        msg = "fewer than 3 hedgehog positions in the stand-still: refusing to move"
        raise LimitError(msg)
    return float(np.median(cols["x_m"][ok])), float(np.median(cols["y_m"][ok]))


def hedgehog_start(
    robot: RobotDescription,
    hedge: LiveHedgehog,
    beacons: BeaconMap | None,
    clock: HostClock,
    yaw_rad: float,
) -> tuple[BeaconMap, tuple[float, float, float]]:
    """Where a serial robot stands, before anything moves: the beacon map (``beacons``, else the
    one the hedgehog streams) and the robot's base pose — the hedgehog's median position over
    1 s at rest, moved by the mounting offset at heading ``yaw_rad``.

    Raises:
        LimitError: no position or beacon map from the hedgehog (2 s, or 11 s when the map must
            be streamed, of robot time), or fewer than 3 positions at rest.
    """
    bmap = _wait_for_hedgehog(hedge, beacons, clock, 2.0 if beacons is not None else 11.0)
    bx, by = _base_from_hedge(robot, _hedge_median(hedge, clock, 1.0), yaw_rad)
    return bmap, (bx, by, yaw_rad)


def serial_campaign_bench(
    robot: RobotDescription,
    driver: LiveRobot,
    hedge: LiveHedgehog,
    *,
    beacons: BeaconMap | None = None,
    start_yaw_rad: float = 0.0,
    margin_m: float = 0.3,
    allowed: Area | None = None,
    home: bool = True,
    clock: HostClock | None = None,
    abort_key: bool = True,
    before_run: Callable[[str], None] | None = None,
    on_message: Callable[[str], None] | None = None,
) -> tuple[SerialBench, BeaconMap]:
    """The bench of a campaign on a serial robot, its procedures checked before any motion.

    Waits for the hedgehog (and the streamed beacon map if none is given), takes the home pose
    at rest with ``start_yaw_rad`` and plans the procedures (:func:`plan_procedures`). Nothing
    moves.

    Returns:
        The bench (its ``plan`` says what will run) and the beacon map.

    Raises:
        LimitError: no hedgehog position or beacon map, the controller's stop flag is set, or
            a procedure does not fit.
    """
    host = clock if clock is not None else HostClock()
    state = driver.read_state()
    if getattr(state, "stop_flag", False):
        msg = "the controller reports its motors disabled (stop flag: E-stop or low battery)"
        raise LimitError(msg)
    bmap = _wait_for_hedgehog(hedge, beacons, host, 2.0 if beacons is not None else 11.0)
    hedge_xy = _hedge_median(hedge, host, 1.0)
    bx, by = _base_from_hedge(robot, hedge_xy, start_yaw_rad)
    home_pose = (bx, by, start_yaw_rad)
    plan = plan_procedures(robot, home_pose, bmap, margin_m=margin_m, allowed=allowed)
    bench = SerialBench(
        driver,
        hedge,
        robot_description=robot,
        before_run=before_run,
        plan=plan,
        beacons=bmap,
        homing=_Homing(home_pose, start_yaw_rad, hedge_xy) if home else None,
        clock=host,
        abort_key=abort_key,
        on_message=on_message,
        margin_m=margin_m,
        allowed=allowed,
    )
    return bench, bmap
