"""The ports between experiments and hardware (the hardware-in-the-loop seam of seed 001).

Experiments talk to a :class:`Robot` and a :class:`Clock` only, so the same code runs on the twin
and on a real base; a simulated :class:`BatchClock` plays a block of timed commands per call.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

__all__ = ["BatchClock", "Clock", "Robot", "RobotState"]


@dataclass(frozen=True)
class RobotState:
    """The latest state a base reports.

    Attributes:
        t_s: time of the state (clock time).
        odom_pose: (x m, y m, yaw rad) of base_link in the odom frame, from wheel odometry.
        odom_twist: (vx m/s, vy m/s, wz rad/s) in base_link, from wheel odometry.
        wheel_speeds_radps: measured wheel speeds, in the robot description's wheel order.
        gyro_z_radps: latest IMU yaw rate.
    """

    t_s: float
    odom_pose: tuple[float, float, float]
    odom_twist: tuple[float, float, float]
    wheel_speeds_radps: tuple[float, ...]
    gyro_z_radps: float


@runtime_checkable
class Robot(Protocol):
    """A base that takes body-twist commands and reports its state."""

    def send_twist(self, vx_mps: float, vy_mps: float, wz_radps: float) -> None:
        """Command a body twist in base_link (held until the next command)."""

    def read_state(self) -> RobotState:
        """The latest reported state."""

    def stop(self) -> None:
        """Command zero twist at once."""


@runtime_checkable
class Clock(Protocol):
    """Time as the experiment sees it: simulated (as fast as possible) or wall time."""

    def now_s(self) -> float:
        """Seconds since the experiment started."""

    def sleep_until(self, t_s: float) -> None:
        """Return when the clock reads ``t_s`` (a simulated clock advances the twin to it)."""


@runtime_checkable
class BatchClock(Clock, Protocol):
    """A simulated clock that runs a block of timed commands in one call."""

    def run_commands(
        self, robot: Robot, twists: NDArray[np.float64], wake_s: NDArray[np.float64]
    ) -> None:
        """The same as, for each i in order, ``robot.send_twist(*twists[i])`` and then
        ``self.sleep_until(wake_s[i])``; ``twists`` is (N, 3), ``wake_s`` (N,)."""
