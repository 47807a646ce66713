"""Online IPS fixes on the digital twin, generated from its true pose while a loop runs.

:class:`TwinIpsSource` is a simple fix source (Gaussian noise, ≈ 25 Hz, a fixed latency): the
full simulated IPS (:mod:`omnical.twin.ips_model`) is computed post hoc, not in a live loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from omnical.errors import ConfigError
from omnical.estimation.fusion import IpsFix
from omnical.estimation.se2 import Pose2, transform_point, wrap_angle
from omnical.twin.ips_params import IpsParams
from omnical.twin.simulator import DigitalTwin

__all__ = ["OnlineIpsParams", "TwinIpsSource"]


def _finite_nonneg(name: str, value: float) -> None:
    if not (math.isfinite(value) and value >= 0.0):
        msg = f"{name} must be finite and >= 0, got {value}"
        raise ConfigError(msg)


@dataclass(frozen=True)
class OnlineIpsParams:
    """The simple online IPS of the twin.

    Attributes:
        rate_hz: fix rate (seed 000 §2.1: around 25 Hz with beacons ≤ 5 m apart).
        sigma_m: Gaussian noise per axis, m.
        latency_s: measurement to arrival, s.
        drop_probability: chance a fix is lost.

    Raises:
        ConfigError: on construction, for a non-positive rate or a bad σ, latency or probability.
    """

    rate_hz: float = 25.0
    sigma_m: float = 0.02
    latency_s: float = 0.05
    drop_probability: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.rate_hz) and self.rate_hz > 0.0):
            msg = f"rate_hz must be finite and > 0, got {self.rate_hz}"
            raise ConfigError(msg)
        _finite_nonneg("sigma_m", self.sigma_m)
        _finite_nonneg("latency_s", self.latency_s)
        if not 0.0 <= self.drop_probability < 1.0:
            msg = f"drop_probability must be in [0, 1), got {self.drop_probability}"
            raise ConfigError(msg)

    @classmethod
    def from_ips_params(cls, ips: IpsParams) -> OnlineIpsParams:
        """Rate, latency, noise and drops roughly matching a full simulated IPS configuration.

        Rate: the fastest rate knot shared among the hedgehogs; latency: ``latency_s`` plus
        ``latency_periods`` periods; noise: the distance σ at 3 m plus the vendor jitter (a
        position σ per axis of about the distance σ for a well-spread beacon set, HDOP ≈ 1).
        """
        rate = ips.rate_max_hz / ips.hedgehog_count
        return cls(
            rate_hz=rate,
            sigma_m=ips.distance_noise_m + 3.0 * ips.distance_noise_fraction + ips.vendor_jitter_m,
            latency_s=ips.latency_s + ips.latency_periods / rate,
            drop_probability=min(ips.measurement_drop_probability, 0.99),
        )


class TwinIpsSource:
    """Online IPS fixes on the digital twin, generated from its true pose as the loop runs.

    Each poll observes the twin's true pose; fixes are measured on a fixed grid of ``rate_hz``
    between the previous observation and now (true pose interpolated linearly between the two),
    get Gaussian noise, and are handed over once their latency has elapsed.
    """

    def __init__(
        self,
        twin: DigitalTwin,
        params: OnlineIpsParams,
        *,
        hedge_offset_m: tuple[float, float] | None = None,
        seed: int = 0,
    ) -> None:
        self._twin = twin
        self._params = params
        if hedge_offset_m is None:
            true_offset = twin.params.hedge_offset_m or twin.robot.hedge_offset_m
            hedge_offset_m = (true_offset[0], true_offset[1])
        self._offset = hedge_offset_m
        self._rng = np.random.default_rng([seed, 0x0F1C5])
        self._period = 1.0 / params.rate_hz
        self._last: tuple[float, Pose2] | None = None
        self._next_k = 0
        self._t0 = 0.0
        self._queue: list[IpsFix] = []

    def poll(self) -> list[IpsFix]:
        """Fixes arrived by the twin's current time, oldest first."""
        t = self._twin.t_s
        pose = self._twin.ground_truth_pose
        if self._last is None:
            self._t0 = t
            self._measure(t, pose)
            self._next_k = 1
        else:
            t_a, pose_a = self._last
            while self._t0 + self._next_k * self._period <= t + 1e-12:
                t_m = self._t0 + self._next_k * self._period
                a = (t_m - t_a) / (t - t_a) if t > t_a else 1.0
                between_pose: Pose2 = (
                    pose_a[0] + a * (pose[0] - pose_a[0]),
                    pose_a[1] + a * (pose[1] - pose_a[1]),
                    pose_a[2] + a * wrap_angle(pose[2] - pose_a[2]),
                )
                self._measure(t_m, between_pose)
                self._next_k += 1
        self._last = (t, pose)
        ready = [f for f in self._queue if f.t_arrival_s <= t + 1e-12]
        self._queue = [f for f in self._queue if f.t_arrival_s > t + 1e-12]
        return ready

    def _measure(self, t_m: float, pose: Pose2) -> None:
        p = self._params
        if p.drop_probability > 0.0 and self._rng.random() < p.drop_probability:
            return
        hx, hy = transform_point(pose, *self._offset)
        nx, ny = self._rng.standard_normal(2) * p.sigma_m
        self._queue.append(IpsFix(t_m, t_m + p.latency_s, hx + float(nx), hy + float(ny)))
