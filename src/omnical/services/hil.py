"""Hardware in the loop: a motion script on a serial base with a live hedgehog, recorded.

:func:`run_serial` runs a script in wall-clock time on a :class:`~omnical.experiment.ports.Robot`
over serial (optionally wrapped in :class:`~omnical.drivers.compensation.CompensatingRobot`),
records the topics the in-process twin records (``/cmd_vel``, ``/omnical/events``, ``/odom``,
``/imu`` from the controller's status frames; ``/hedge_pos_ang``, ``/beacon_raw_distance``,
``/hedge_quality``, ``/beacons_pos_a`` from the hedgehog) into any row sink — a
:class:`~omnical.recording.BagRecorder` for long runs, or an in-memory builder for the campaign
(:class:`SerialBench`). ``/ground_truth`` exists only on a twin (the device server records it).

Bag times are the host's wall clock (``time.time_ns`` at start + monotonic elapsed time), so the
bag lines up with the device server's truth recording on the same machine.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from omnical.drivers.compensation import CompensatingRobot
from omnical.drivers.hedgehog import SerialHedgehog
from omnical.drivers.wheeltec_serial import WheeltecRobot
from omnical.errors import ProtocolError
from omnical.experiment.runner import RunLog, run_script
from omnical.experiment.script import CommandSource, MotionScript
from omnical.kinematics.correction import CorrectionFactors
from omnical.recording.recording import Recording, RecordingBuilder

__all__ = ["HilRun", "RowSink", "SerialBench", "run_serial", "wait_for_status"]

LEAD_IN_S = 1.0
TAIL_S = 1.0
_FLUSH_EVERY_S = 0.5


class RowSink(Protocol):
    """Where rows go: ``BagRecorder`` or :class:`_BuilderSink`."""

    def write_rows(self, topic: str, t_ns: Any, **columns: Any) -> None: ...


class _BuilderSink:
    def __init__(self) -> None:
        self.builder = RecordingBuilder()

    def write_rows(self, topic: str, t_ns: Any, **columns: Any) -> None:
        self.builder.add_many(topic, t_ns, **columns)


class _MonoClock:
    """Wall-clock time for the Runner, seconds since ``t0`` on the monotonic clock."""

    def __init__(self, t0: float) -> None:
        self.t0 = t0

    def now_s(self) -> float:
        return time.monotonic() - self.t0

    def sleep_until(self, t_s: float) -> None:
        delay = t_s - self.now_s()
        if delay > 0:
            time.sleep(delay)


@dataclass
class HilRun:
    """What a serial run produced: the runner's log and counts of what was recorded."""

    log: RunLog
    messages: dict[str, int] = field(default_factory=dict)
    t0_wall_ns: int = 0

    @property
    def interrupted(self) -> bool:
        return self.log.interrupted


def wait_for_status(robot: WheeltecRobot, timeout_s: float = 2.0) -> None:
    """Wait for the first valid status frame.

    Raises:
        ProtocolError: none within ``timeout_s`` (wrong port or baud rate, controller off).
    """
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if not robot.read_state().stale:
            return
        time.sleep(0.01)
    msg = (
        f"no valid status frame from the vehicle controller within {timeout_s:.1f} s "
        "(wrong port or baud rate, controller off, or still in its 10-s power-on delay)"
    )
    raise ProtocolError(msg)


class _Recorder:
    """Drains the driver and the hedgehog into a sink, stamped from one time base."""

    def __init__(
        self, sink: RowSink, robot: WheeltecRobot, hedge: SerialHedgehog | None, t0: float
    ) -> None:
        self.sink, self.robot, self.hedge, self.t0 = sink, robot, hedge, t0
        self.wall0_ns = time.time_ns() - round((time.monotonic() - t0) * 1e9)
        self.counts: dict[str, int] = {}
        self._last = time.monotonic()

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
        if time.monotonic() - self._last >= _FLUSH_EVERY_S:
            self.drain()

    def drain(self) -> None:
        self._last = time.monotonic()
        samples = self.robot.drain_log()
        if samples:
            t = np.array([s.t_s - self.t0 for s in samples])
            pose = np.array([s.pose for s in samples])
            twist = np.array([self.robot.odometry_twist(s.status) for s in samples])
            self._write(
                "/odom",
                t,
                x_m=pose[:, 0],
                y_m=pose[:, 1],
                yaw_rad=pose[:, 2],
                vx_mps=twist[:, 0],
                vy_mps=twist[:, 1],
                wz_radps=twist[:, 2],
            )
            gyro = np.array([s.status.gyro_radps for s in samples])
            acc = np.array([s.status.accel_mps2 for s in samples])
            self._write(
                "/imu",
                t,
                gyro_x_radps=gyro[:, 0],
                gyro_y_radps=gyro[:, 1],
                gyro_z_radps=gyro[:, 2],
                acc_x_mps2=acc[:, 0],
                acc_y_mps2=acc[:, 1],
                acc_z_mps2=acc[:, 2],
            )
        if self.hedge is not None:
            for topic, (times, cols) in self.hedge.drain().items():
                self._write(topic, times - self.t0, **cols)

    def write_run(self, log: RunLog, installed: CorrectionFactors | None) -> None:
        cmd = log.cmd_vel
        self._write("/cmd_vel", cmd[:, 0], vx_mps=cmd[:, 1], vy_mps=cmd[:, 2], wz_radps=cmd[:, 3])
        events = list(log.events)
        if installed is not None:
            text = json.dumps({"omnical": "installed_factors", "factors": installed.as_dict()})
            events.insert(0, (0.0, text))
        if events:
            self._write(
                "/omnical/events",
                np.array([t for t, _ in events]),
                text=np.array([e for _, e in events], dtype=object),
            )


def run_serial(
    script: CommandSource,
    robot: WheeltecRobot,
    hedge: SerialHedgehog | None,
    sink: RowSink,
    *,
    compensation: CorrectionFactors | None = None,
    record_installed: bool = True,
    on_tick: Callable[[float, float], None] | None = None,
    lead_in_s: float = LEAD_IN_S,
    tail_s: float = TAIL_S,
) -> HilRun:
    """Run ``script`` on a serial base in wall-clock time and write every topic to ``sink``.

    The robot stands still ``lead_in_s`` before and ``tail_s`` after the script, as in
    :func:`~omnical.twin.session.simulate_run`. With ``compensation`` the factors are applied
    host-side (:class:`CompensatingRobot`) and an ``installed_factors`` event is recorded.
    A ``KeyboardInterrupt`` during the script stops the robot (the Runner sends zero), the rows
    so far are written, and the result says ``interrupted``; the caller closes the bag.
    """
    t0 = time.monotonic()
    clock = _MonoClock(t0)
    rec = _Recorder(sink, robot, hedge, t0)
    port: Any = robot if compensation is None else CompensatingRobot(robot, compensation)

    def tick(elapsed: float, total: float) -> None:
        rec.maybe_drain()
        if on_tick is not None:
            on_tick(elapsed, total)

    log: RunLog | None = None
    try:
        _hold(robot, clock, lead_in_s, rec)
        log = run_script(script, port, clock, on_tick=tick)
        if not log.interrupted:
            _hold(robot, clock, tail_s, rec)
    finally:
        robot.stop()
        rec.drain()
        if isinstance(port, CompensatingRobot):
            port.release()
        if log is not None:
            rec.write_run(log, compensation if record_installed else None)
    return HilRun(log, rec.counts, rec.wall0_ns)


def _hold(robot: WheeltecRobot, clock: _MonoClock, duration_s: float, rec: _Recorder) -> None:
    end = clock.now_s() + duration_s
    while clock.now_s() < end:
        robot.send_twist(0.0, 0.0, 0.0)  # keeps the host watchdog fed
        rec.maybe_drain()
        clock.sleep_until(min(end, clock.now_s() + 0.05))


@dataclass
class SerialBench:
    """The campaign's ``Bench`` on a serial base: factors applied host-side, runs in wall time.

    Stock firmware cannot install factors, so every run goes through
    :class:`CompensatingRobot` with the run's factors. Between runs ``before_run(name)`` is
    called (e.g. to ask the user to bring the robot back to the start pose, and to confirm).

    Attributes:
        robot: the open driver.
        hedge: the open hedgehog.
        before_run: called with the run's name before it moves (None: nothing).
    """

    robot: WheeltecRobot
    hedge: SerialHedgehog | None
    before_run: Callable[[str], None] | None = None

    def run(
        self,
        script: MotionScript,
        installed: CorrectionFactors,
        *,
        name: str,
        on_tick: Callable[[float, float], None] | None = None,
    ) -> Recording:
        """Run ``script`` with ``installed`` compensating host-side; the recording in memory."""
        if self.before_run is not None:
            self.before_run(name)
        self.robot.reset_odometry()
        if self.hedge is not None:
            self.hedge.drain()
        self.robot.drain_log()
        sink = _BuilderSink()
        result = run_serial(
            script,
            self.robot,
            self.hedge,
            sink,
            compensation=installed,
            record_installed=False,  # the campaign adds the installed_factors event itself
            on_tick=on_tick,
        )
        if result.interrupted:
            raise result.log.interruption or KeyboardInterrupt()
        return sink.builder.build()
