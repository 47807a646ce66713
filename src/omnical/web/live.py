"""What the monitor derives from a run's frames: the fused pose and the odometry − IPS error.

:class:`LiveView` puts the odometry in the map (the origin a run latched, else its start at the
first valid fix) and runs the library's IPS + odometry filter (``estimation.fusion``) on it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from omnical.estimation.fusion import FusionParams, FusionState, fusion_predict, fusion_update
from omnical.estimation.se2 import Pose2, between, compose, invert, transform_point

__all__ = ["LiveView"]

_UNAVAILABLE = 0x01  # PositionFlag.COORDINATES_UNAVAILABLE
_START_SIGMA = (0.3, 0.3, 0.1)
_RESET_JUMP_M = 0.2  # odometry jumping back to zero by more than this: a restart


class LiveView:
    """The derived streams of one live run (or of a replay, fed in time order).

    Attributes:
        origin: the odometry frame's pose in the map (None until known).
        offset_m: the hedgehog's (x, y) in base_link.
    """

    def __init__(self, offset_m: tuple[float, float] = (0.0, 0.0)) -> None:
        self.offset_m = offset_m
        self.origin: Pose2 | None = None
        self._params = FusionParams(hedge_offset_m=offset_m)
        self._state: FusionState | None = None
        self._odom: Pose2 | None = None
        self._odom_t: float | None = None

    def reset(self) -> None:
        """A new run: forget the origin, the filter and the last odometry."""
        self.__init__(self.offset_m)  # type: ignore[misc]

    def set_origin(self, data: Mapping[str, Any]) -> None:
        """A latched ``origin`` ({x, y, yaw}; ``offset`` [ox, oy] optional)."""
        if "offset" in data and data["offset"] is not None:
            ox, oy = (float(v) for v in data["offset"][:2])
            self.offset_m = (ox, oy)
            self._params = FusionParams(hedge_offset_m=self.offset_m)
        self.origin = (float(data["x"]), float(data["y"]), float(data["yaw"]))
        self._state = None

    def on_frame(self, stream: str, data: Mapping[str, Any]) -> list[tuple[str, dict[str, Any]]]:
        """The derived frames a ``stream`` frame leads to (maybe none)."""
        if stream == "origin":
            self.set_origin(data)
        elif stream == "odom":
            return self._odometry(data)
        elif stream == "fix":
            return self._fixes(data)
        return []

    def _odometry(self, data: Mapping[str, Any]) -> list[tuple[str, dict[str, Any]]]:
        ts, xs, ys, yaws = data["t"], data["x"], data["y"], data["yaw"]
        if not ts:
            return []
        frames: list[tuple[str, dict[str, Any]]] = []
        for t, x, y, yaw in zip(ts, xs, ys, yaws, strict=True):
            pose = (float(x), float(y), float(yaw))
            if self._reset(pose) and self._state is not None:
                # the odometry restarted at zero (a campaign's next run): the new odometry
                # frame is where the filter has the robot now
                self.origin = compose(self._state.pose, invert(pose))
                ox, oy, oyaw = self.origin
                frames.append(("origin", {"x": ox, "y": oy, "yaw": oyaw, "from": "odometry reset"}))
            elif self._state is not None and self._odom is not None and self.origin is not None:
                dt = max(0.0, float(t) - (self._odom_t or float(t)))
                self._state = fusion_predict(
                    self._params, self._state, between(self._odom, pose), dt
                )
            elif self.origin is not None:
                self._state = FusionState.initial(compose(self.origin, pose), _START_SIGMA)
            self._odom, self._odom_t = pose, float(t)
        return frames + self._fused(float(ts[-1]))

    def _reset(self, pose: Pose2) -> bool:
        """``pose`` is a restart of the odometry at zero, away from where it was."""
        if self._odom is None:
            return False
        jump = math.hypot(pose[0] - self._odom[0], pose[1] - self._odom[1])
        return jump > _RESET_JUMP_M and math.hypot(pose[0], pose[1]) < 0.02

    def _fused(self, t: float) -> list[tuple[str, dict[str, Any]]]:
        if self._state is None:
            return []
        x, y, yaw = self._state.pose
        c = self._state.cov
        cov = [float(c[0, 0]), float(c[0, 1]), float(c[1, 1])]
        return [("fused", {"t": t, "x": x, "y": y, "yaw": yaw, "cov": cov})]

    def _fixes(self, data: Mapping[str, Any]) -> list[tuple[str, dict[str, Any]]]:
        out_t: list[float] = []
        out_e: list[float] = []
        accepted = 0
        frames: list[tuple[str, dict[str, Any]]] = []
        for t, x, y, flags in zip(data["t"], data["x"], data["y"], data["flags"], strict=True):
            if int(flags) & _UNAVAILABLE or not (math.isfinite(x) and math.isfinite(y)):
                continue
            if self.origin is None and self._odom is not None:
                # the odometry's start at the first fix (hedgehog offset and heading 0)
                hx, hy = transform_point((0.0, 0.0, self._odom[2]), *self.offset_m)
                ox, oy = float(x) - hx - self._odom[0], float(y) - hy - self._odom[1]
                self.origin = (ox, oy, 0.0)
                frames.append(("origin", {"x": ox, "y": oy, "yaw": 0.0, "from": "first fix"}))
            if self._odom is None or self.origin is None:
                continue
            base = compose(self.origin, self._odom)
            hx, hy = transform_point(base, *self.offset_m)
            out_t.append(float(t))
            out_e.append(math.hypot(float(x) - hx, float(y) - hy))
            if self._state is None:
                self._state = FusionState.initial(base, _START_SIGMA)
            self._state, ok = fusion_update(self._params, self._state, (float(x), float(y)))
            accepted += int(ok)
        if out_t:
            frames.append(("error", {"t": out_t, "e": out_e}))
            if accepted:
                frames.extend(self._fused(out_t[-1]))
        return frames
