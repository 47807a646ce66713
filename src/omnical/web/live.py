"""What the monitor derives from a run's frames: the fused pose and the odometry − IPS error.

:class:`LiveView` puts the odometry in the map (the origin a run latched, else its start at the
first fix), pairs each fix with the odometry at the fix's stamp and runs ``estimation.fusion``.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping
from typing import Any

from omnical.estimation.fusion import FusionParams, FusionState, fusion_predict, fusion_update
from omnical.estimation.se2 import (
    Pose2,
    between,
    compose,
    interpolate_pose,
    invert,
    transform_point,
)

__all__ = ["LiveView"]

_UNAVAILABLE = 0x01  # PositionFlag.COORDINATES_UNAVAILABLE
_START_SIGMA = (0.3, 0.3, 0.1)
_RESET_JUMP_M = 0.2  # odometry jumping back to zero by more than this: a restart
_KEEP_S = 30.0  # odometry kept behind the filter's time (for fixes that come late)
_AHEAD_S = 0.0  # a fix past the last odometry by more than this waits for it
_PENDING_MAX = 512  # fixes waiting for their odometry, at most


class LiveView:
    """The derived streams of one live run (or of a replay, fed in time order).

    Odometry and fixes may come in any interleaving (an in-process run sends its whole
    odometry first, a live robot a fix a little before the odometry of its time): each fix is
    paired with the odometry at its own stamp, waiting for that odometry if need be.

    Attributes:
        origin: the odometry frame's pose in the map (None until known).
        offset_m: the hedgehog's (x, y) in base_link.
    """

    def __init__(self, offset_m: tuple[float, float] = (0.0, 0.0)) -> None:
        self.offset_m = offset_m
        self.origin: Pose2 | None = None
        self._params = FusionParams(hedge_offset_m=offset_m)
        self._state: FusionState | None = None
        self._state_t = -math.inf  # the filter's time (s) and the odometry pose then
        self._state_odom: Pose2 = (0.0, 0.0, 0.0)
        self._ts: list[float] = []  # the odometry, in stamp order
        self._poses: list[Pose2] = []
        self._pending: list[tuple[float, float, float]] = []
        # the state carried forward from the filter's to the last odometry: reused, so that a
        # run without fixes costs one prediction per odometry row, not one per row since start
        self._cursor: tuple[FusionState, float, Pose2] | None = None

    def reset(self) -> None:
        """A new run: forget the origin, the filter and the odometry."""
        self.__init__(self.offset_m)  # type: ignore[misc]

    def set_origin(self, data: Mapping[str, Any]) -> None:
        """A latched ``origin`` ({x, y, yaw}; ``offset`` [ox, oy] optional)."""
        if "offset" in data and data["offset"] is not None:
            ox, oy = (float(v) for v in data["offset"][:2])
            self.offset_m = (ox, oy)
            self._params = FusionParams(hedge_offset_m=self.offset_m)
        self.origin = (float(data["x"]), float(data["y"]), float(data["yaw"]))
        self._state, self._cursor = None, None
        self._state_t = -math.inf

    def on_frame(self, stream: str, data: Mapping[str, Any]) -> list[tuple[str, dict[str, Any]]]:
        """The derived frames a ``stream`` frame leads to (maybe none)."""
        if stream == "origin":
            self.set_origin(data)
        elif stream == "odom":
            return self._odometry(data)
        elif stream == "fix":
            return self._fixes(data)
        return []

    # ------------------------------------------------------------------ odometry
    def _odometry(self, data: Mapping[str, Any]) -> list[tuple[str, dict[str, Any]]]:
        ts, xs, ys, yaws = data["t"], data["x"], data["y"], data["yaw"]
        if not ts:
            return []
        frames: list[tuple[str, dict[str, Any]]] = []
        for t, x, y, yaw in zip(ts, xs, ys, yaws, strict=True):
            pose, t_s = (float(x), float(y), float(yaw)), float(t)
            if self._ts and t_s < self._ts[-1]:
                continue  # a stale or repeated row
            if self._reset(pose) and self._state is not None:
                # the odometry restarted at zero (a campaign's next run): the new odometry
                # frame is where the filter has the robot now
                now = self._predicted(self._ts[-1])
                self.origin = compose(now.pose, invert(pose))
                ox, oy, oyaw = self.origin
                frames.append(("origin", {"x": ox, "y": oy, "yaw": oyaw, "from": "odometry reset"}))
                self._set_state(now, t_s, pose)
                self._ts, self._poses = [], []
            elif self._state is None and self.origin is not None:
                self._set_state(FusionState.initial(compose(self.origin, pose), _START_SIGMA),
                                t_s, pose)  # fmt: skip
            self._ts.append(t_s)
            self._poses.append(pose)
        self._trim()
        if self._pending and self._ts:
            waiting, self._pending = self._pending, []
            frames += self._pair(waiting)
        return frames + self._fused()

    def _reset(self, pose: Pose2) -> bool:
        """``pose`` is a restart of the odometry at zero, away from where it was."""
        if not self._poses:
            return False
        last = self._poses[-1]
        jump = math.hypot(pose[0] - last[0], pose[1] - last[1])
        return jump > _RESET_JUMP_M and math.hypot(pose[0], pose[1]) < 0.02

    def _trim(self) -> None:
        """Forget odometry more than :data:`_KEEP_S` behind the filter (in chunks); without
        fixes for that long, the filter moves on to the carried-forward state."""
        if len(self._ts) < 4096 or not math.isfinite(self._state_t):
            return
        cursor = self._cursor
        if cursor is not None and cursor[1] - self._state_t > 2 * _KEEP_S:
            self._set_state(*cursor)
            self._cursor = cursor
        k = bisect.bisect_left(self._ts, self._state_t - _KEEP_S)
        if k > 1024:
            del self._ts[:k]
            del self._poses[:k]

    def _set_state(self, state: FusionState, t: float, odom: Pose2) -> None:
        self._state, self._state_t, self._state_odom, self._cursor = state, t, odom, None

    def _predicted(self, t: float) -> FusionState:
        """The filter's state carried by the odometry from its time to ``t`` (not kept)."""
        assert self._state is not None
        state, odom, last_t = self._state, self._state_odom, self._state_t
        if self._cursor is not None and self._cursor[1] <= t:
            state, last_t, odom = self._cursor
        i = bisect.bisect_right(self._ts, last_t)
        j = bisect.bisect_right(self._ts, t)
        steps = [(self._ts[k], self._poses[k]) for k in range(i, j)]
        if not steps or steps[-1][0] < t:
            steps.append((t, interpolate_pose(self._ts, self._poses, t)))
        for tk, pose in steps:
            state = fusion_predict(self._params, state, between(odom, pose), max(0.0, tk - last_t))
            odom, last_t = pose, tk
        self._cursor = (state, last_t, odom)
        return state

    def _fused(self) -> list[tuple[str, dict[str, Any]]]:
        """The fused pose at the last odometry (or the filter's own time if later)."""
        if self._state is None:
            return []
        t = self._ts[-1] if self._ts else self._state_t
        state = self._predicted(t) if self._ts and t > self._state_t else self._state
        t = max(t, self._state_t)
        x, y, yaw = state.pose
        c = state.cov
        cov = [float(c[0, 0]), float(c[0, 1]), float(c[1, 1])]
        return [("fused", {"t": t, "x": x, "y": y, "yaw": yaw, "cov": cov})]

    # ------------------------------------------------------------------ fixes
    def _fixes(self, data: Mapping[str, Any]) -> list[tuple[str, dict[str, Any]]]:
        fixes = [
            (float(t), float(x), float(y))
            for t, x, y, flags in zip(data["t"], data["x"], data["y"], data["flags"], strict=True)
            if not int(flags) & _UNAVAILABLE and math.isfinite(x) and math.isfinite(y)
        ]
        frames = self._pair(fixes)
        return frames + (self._fused() if any(s == "error" for s, _ in frames) else [])

    def _pair(self, fixes: list[tuple[float, float, float]]) -> list[tuple[str, dict[str, Any]]]:
        """Each fix against the odometry at its stamp; fixes past the odometry wait."""
        out_t: list[float] = []
        out_e: list[float] = []
        frames: list[tuple[str, dict[str, Any]]] = []
        for t, x, y in sorted(fixes):
            if not self._ts or t > self._ts[-1] + _AHEAD_S:
                self._pending.append((t, x, y))
                continue
            odom = interpolate_pose(self._ts, self._poses, t)
            if self.origin is None:
                # the odometry's start at the first fix (hedgehog offset and heading 0)
                hx, hy = transform_point((0.0, 0.0, odom[2]), *self.offset_m)
                ox, oy = x - hx - odom[0], y - hy - odom[1]
                self.origin = (ox, oy, 0.0)
                frames.append(("origin", {"x": ox, "y": oy, "yaw": 0.0, "from": "first fix"}))
            base = compose(self.origin, odom)
            hx, hy = transform_point(base, *self.offset_m)
            out_t.append(t)
            out_e.append(math.hypot(x - hx, y - hy))
            if self._state is None:
                self._set_state(FusionState.initial(base, _START_SIGMA), t, odom)
            if t >= self._state_t:  # a fix older than the filter's time only shows its error
                state, _ = fusion_update(self._params, self._predicted(t), (x, y))
                self._set_state(state, t, odom)
        if len(self._pending) > _PENDING_MAX:
            del self._pending[: len(self._pending) - _PENDING_MAX]
        if out_t:
            frames.append(("error", {"t": out_t, "e": out_e}))
        return frames
