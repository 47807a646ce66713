"""A controller in closed loop on any rig, recorded: :func:`run_controller_on`.

The same loop runs seed 003's tasks and seed 001's legs on the twin, on a serial robot and on
any later rig; the rig's session supplies the pose sources it has (:class:`ControlSession`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Literal, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray

from omnical.control.limits import CommandLimits
from omnical.control.loop import Controller, ControlLog, ControlOutput, PoseSource, run_controller
from omnical.errors import ConfigError, RunStop, SafetyStopError
from omnical.estimation.fusion import FixSource, FusedPoseSource, FusionParams, IpsFix
from omnical.estimation.fusion import initial_pose_from_fixes as fixes_start
from omnical.estimation.se2 import Pose2, between_poses
from omnical.experiment.rig import LEAD_IN_S, RigSession, RowSink
from omnical.recording.topics import ODOM

if TYPE_CHECKING:
    from omnical.kinematics.correction import CorrectionFactors


__all__ = [
    "TASK_TAIL_S",
    "ControlRig",
    "ControlSession",
    "PoseChoice",
    "RigControlRun",
    "fused_start",
    "lead_in_fixes",
    "path_in_frame",
    "run_controller_on",
]

StateT = TypeVar("StateT")

PoseChoice = Literal["odometry", "fused", "ground_truth", "seed003"]
"""What closes the loop: wheel odometry, odometry fused with the positioning system's fixes, the
true pose (a twin), or seed 003's dead wheels + IMU + magnetometer (a twin with dead wheels)."""

TASK_TAIL_S = 2.0
"""Standing time recorded after a controller stops."""


class ControlSession(RigSession, Protocol):
    """A rig session a controller can close its loop in."""

    @property
    def origin_ns(self) -> int:
        """Bag time of clock time 0, ns."""
        ...

    def fixes(self) -> FixSource:
        """The positioning system's fixes as they arrive (ConfigError: the rig has none)."""
        ...

    def own_pose_source(self, choice: str) -> PoseSource:
        """A pose source only this rig has ("ground_truth", "seed003"), path frame = pose now."""
        ...

    def lidar_params(self) -> Any:
        """The LiDAR's mounting and beams, a ``LidarParams`` (ConfigError: the rig has none)."""
        ...

    def scan_now(self) -> NDArray[np.float64]:
        """The LiDAR's ranges now, m (ConfigError: the rig has none)."""
        ...

    def alarm(self) -> str:
        """Why the robot must stop at once ("" : no reason), e.g. the controller's stop flag."""
        ...

    def ground_truth(self) -> NDArray[np.float64] | None:
        """(N, 4) t_s, x, y, yaw of the true pose in the map so far; None off a twin."""
        ...

    def estimates(self) -> NDArray[np.float64] | None:
        """(N, 4) t_s, x, y, yaw of the rig's own pose source so far, map frame (seed 003)."""
        ...


class ControlRig(Protocol):
    """A rig whose sessions are :class:`ControlSession`."""

    @property
    def sources(self) -> frozenset[str]:
        """The :data:`PoseChoice` values its sessions can close a loop on."""
        ...

    def session(
        self,
        sink: RowSink,
        *,
        installed: CorrectionFactors | None = None,
        require_positions: bool = False,
    ) -> Any:
        """See :meth:`omnical.experiment.rig.Rig.session` (yields a :class:`ControlSession`)."""
        ...


@dataclass(frozen=True, eq=False)
class RigControlRun:
    """What :func:`run_controller_on` produced.

    Attributes:
        control: the loop's log (clock seconds since the session's start).
        odometry_path: (N, 4) t_s, x, y, yaw of the recorded odometry in the path frame, over
            the loop's span (empty if the rig records no ``/odom``).
        estimates: (M, 4) t_s, x, y, yaw of the fused or seed 003 estimate, map frame, or None.
        ground_truth: (K, 4) the true pose in the map (a twin), or None.
        origin_ns: bag time of clock time 0.
        odom_origin: the odometry pose at the loop's start (the path frame in the odom frame).
        session: the rig's session, after it ended (what only that rig has, e.g. the twin).
        stopped_because: why the rig stopped the loop ("" unless ``emergency_stop``).
        accepted, rejected: fixes the fused filter used and gated out.
    """

    control: ControlLog
    odometry_path: NDArray[np.float64]
    estimates: NDArray[np.float64] | None
    ground_truth: NDArray[np.float64] | None
    origin_ns: int
    odom_origin: Pose2
    session: ControlSession
    stopped_because: str = ""
    accepted: int = 0
    rejected: int = 0

    @property
    def interrupted(self) -> bool:
        """Ctrl-C, SIGTERM, an abort key or a safety stop ended the run."""
        return self.control.reason == "interrupted"


class _OdomTee:
    """Passes rows on and keeps the ``/odom`` poses (the run's odometry path)."""

    def __init__(self, inner: RowSink) -> None:
        self.inner = inner
        self.rows: list[tuple[NDArray[np.int64], NDArray[np.float64]]] = []

    def write_rows(self, topic: str, t_ns: Any, **columns: Any) -> None:
        self.inner.write_rows(topic, t_ns, **columns)
        if topic == ODOM:
            pose = np.column_stack([columns["x_m"], columns["y_m"], columns["yaw_rad"]])
            self.rows.append((np.asarray(t_ns, dtype=np.int64), pose.astype(np.float64)))

    def path(self, origin_ns: int, origin: Pose2, t_from: float, t_to: float) -> NDArray[Any]:
        if not self.rows:
            return np.zeros((0, 4))
        t = (np.concatenate([t for t, _ in self.rows]) - origin_ns) / 1e9
        pose = np.concatenate([p for _, p in self.rows])
        keep = (t >= t_from - 0.1) & (t <= t_to + 1e-9)
        return np.column_stack([t[keep], between_poses(np.asarray(origin), pose[keep])])


def lead_in_fixes(
    run: ControlSession, source: FixSource, duration_s: float, steps: int
) -> list[IpsFix]:
    """Stand still ``duration_s`` in ``steps`` holds, collecting the fixes that arrive."""
    fixes = source.poll()
    for _ in range(steps):
        run.hold(duration_s / steps)
        fixes += source.poll()
    return fixes


def _inliers(fixes: list[IpsFix], radius_m: float = 0.1) -> list[IpsFix]:
    """The fixes within ``radius_m`` of their median (an IPS outlier must not move the start)."""
    if not fixes:
        return []
    mx = float(np.median([f.x_m for f in fixes]))
    my = float(np.median([f.y_m for f in fixes]))
    return [f for f in fixes if math.hypot(f.x_m - mx, f.y_m - my) <= radius_m]


def fused_start(
    run: ControlSession,
    fusion: FusionParams,
    start_yaw_rad: float,
    lead_in_s: float,
    *,
    steps: int,
    path_origin_map: Pose2 = (0.0, 0.0, 0.0),
) -> FusedPoseSource | str:
    """The fused filter started from the fixes of the lead-in at rest (their inliers, with the
    heading ``start_yaw_rad`` and the hedgehog offset of ``fusion``), or why it cannot start."""
    source = run.fixes()
    at_rest = _inliers(lead_in_fixes(run, source, lead_in_s, steps))
    if len(at_rest) < 3:
        return f"{len(at_rest)} positioning fixes in {lead_in_s:.1f} s at rest (need 3)"
    start = fixes_start(at_rest, start_yaw_rad, fusion.hedge_offset_m)
    sigma = fusion.ips_sigma_m / math.sqrt(len(at_rest)) + 0.005
    return FusedPoseSource(
        fusion,
        source,
        start,
        path_origin_map=path_origin_map,
        initial_sigma=(sigma, sigma, fusion.initial_yaw_sigma_rad),
    )


def run_controller_on(
    rig: ControlRig,
    controller: Controller[StateT],
    sink: RowSink,
    *,
    limits: CommandLimits,
    pose: PoseChoice = "odometry",
    installed: CorrectionFactors | None = None,
    fusion: FusionParams | None = None,
    start_pose_map: Pose2 = (0.0, 0.0, 0.0),
    rate_hz: float = 20.0,
    max_duration_s: float = 600.0,
    lead_in_s: float = LEAD_IN_S,
    tail_s: float = TASK_TAIL_S,
    pause: Callable[[float], bool] | None = None,
    emergency_stop: Callable[[float], bool] | None = None,
    on_tick: Callable[[float, ControlOutput], None] | None = None,
) -> RigControlRun:
    """Run ``controller`` in closed loop on ``rig``, recorded into ``sink``.

    Stand ``lead_in_s`` (a fused loop starts from those fixes, at least 3, and the heading of
    ``start_pose_map``, the path frame's origin), run the loop, stand ``tail_s``. ``installed``
    is compensated by the rig and recorded as an ``installed_factors`` event. The rig's alarm
    and ``emergency_stop`` stop the loop at once; Ctrl-C, SIGTERM or a safety stop end it with
    what was recorded (reason ``interrupted``, ``interruption`` for the caller to re-raise).

    Raises:
        ConfigError: a pose source this rig does not have, a bad rate or duration.
    """
    if pose not in rig.sources:
        have = ", ".join(sorted(rig.sources))
        msg = f"this robot cannot close a loop on {pose!r} (it has: {have})"
        raise ConfigError(msg)
    tee = _OdomTee(sink)
    why: list[str] = []
    fused: FusedPoseSource | None = None
    control: ControlLog | None = None
    with rig.session(tee, installed=installed, require_positions=pose == "fused") as run:

        def stop_now(t_s: float) -> bool:
            if not why:
                alarm = run.alarm()
                if alarm:
                    why.append(alarm)
            return bool(why) or (emergency_stop is not None and emergency_stop(t_s))

        def tick(t_s: float, output: ControlOutput) -> None:
            run.poll()
            if on_tick is not None:
                on_tick(t_s, output)

        steps = max(1, round(lead_in_s * rate_hz))
        source: Literal["odometry"] | PoseSource = "odometry"
        odom_origin: Pose2 = (0.0, 0.0, 0.0)
        try:
            try:
                if pose == "fused":
                    if fusion is None:
                        msg = "a fused loop needs the fusion parameters (the hedgehog offset)"
                        raise ConfigError(msg)
                    start = fused_start(
                        run, fusion, start_pose_map[2], lead_in_s,
                        steps=steps, path_origin_map=start_pose_map,
                    )  # fmt: skip
                    if isinstance(start, str):
                        why.append(start)
                        control = _stopped_at_rest(run.clock.now_s(), None)
                    else:
                        source = fused = start
                else:
                    run.hold(lead_in_s)
                    if pose != "odometry":
                        source = run.own_pose_source(pose)
                odom_origin = run.robot.read_state().odom_pose
            except (KeyboardInterrupt, SafetyStopError) as stop:
                control = _stopped_at_rest(run.clock.now_s(), stop)
            if control is None:
                control = run_controller(
                    controller,
                    run.robot,
                    run.clock,
                    rate_hz=rate_hz,
                    pose_source=source,
                    max_duration_s=max_duration_s,
                    limits=limits,
                    pause=pause,
                    emergency_stop=stop_now,
                    on_tick=tick,
                )
            if control.reason != "interrupted":
                try:
                    run.hold(tail_s)
                except (KeyboardInterrupt, SafetyStopError) as stop:
                    control = replace(control, reason="interrupted", interruption=stop)
        finally:  # whatever ended the run, what it commanded is recorded with what it sensed
            cmd = control.cmd_vel if control is not None else np.zeros((0, 4))
            events = list(control.events) if control is not None else []
            if installed is not None:
                text = json.dumps({"omnical": "installed_factors", "factors": installed.as_dict()})
                events.insert(0, (0.0, text))
            run.finish(cmd, events)
        truth = run.ground_truth()
        own = run.estimates()
        origin_ns = run.origin_ns
    t_from, t_to = float(control.t_s[0]), float(control.t_s[-1])
    return RigControlRun(
        control,
        tee.path(origin_ns, odom_origin, t_from, t_to),
        fused.estimates() if fused is not None else own,
        truth,
        origin_ns,
        odom_origin,
        run,
        "; ".join(why[:1]),
        fused.accepted if fused is not None else 0,
        fused.rejected if fused is not None else 0,
    )


def _stopped_at_rest(t_s: float, stop: RunStop | None) -> ControlLog:
    """The log of a loop that never started: a stop at rest, or (``stop`` None) a start the
    rig refused (its reason in ``stopped_because``)."""
    zero = np.zeros((1, 3))
    return ControlLog(
        np.array([t_s]), np.full((1, 3), np.nan), zero, zero, np.array([-1]), ("stop",),
        "interrupted" if stop is not None else "emergency_stop", interruption=stop,
    )  # fmt: skip


def path_in_frame(origin: Pose2, rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N, 4) t_s, x, y, yaw rows (map frame) expressed in the frame of ``origin``."""
    return np.column_stack([rows[:, 0], between_poses(np.asarray(origin), rows[:, 1:])])
