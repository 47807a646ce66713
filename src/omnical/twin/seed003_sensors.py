"""Seed 003's sensor samples from the twin: dead-wheel counts with the IMU and magnetometer.

:class:`TwinSeed003Samples` hands a running twin's new rows to the seed 003 estimator;
:func:`seed003_samples` takes them from a twin log.
"""

from __future__ import annotations

from omnical.errors import ConfigError
from omnical.estimation.seed003_estimator import Seed003Samples, align_samples
from omnical.twin.simulator import DigitalTwin, TwinLog

__all__ = ["TwinSeed003Samples", "seed003_samples"]


class TwinSeed003Samples:
    """Seed 003's sensor samples from a running twin: dead-wheel counts with the IMU and
    magnetometer readings of the same step (:func:`~omnical.estimation.seed003_estimator.align_samples`),
    the rows logged since the previous poll, from ``since_s`` on."""

    def __init__(self, twin: DigitalTwin, *, since_s: float = 0.0) -> None:
        self._twin = twin
        self._since = since_s
        self._next = 0

    def poll(self) -> Seed003Samples:
        """The samples logged since the previous call."""
        log = self._twin.log()
        first, self._next = self._next, log.dead_wheel_counts.shape[0]
        return seed003_samples(log, since_s=self._since, first_row=first)


def seed003_samples(log: TwinLog, *, since_s: float = 0.0, first_row: int = 0) -> Seed003Samples:
    """The twin log's seed 003 samples (dead-wheel rows from ``first_row``, at or after ``since_s``).

    Raises:
        ConfigError: a twin without dead wheels or magnetometer.
    """
    if log.dead_wheel_counts.shape[1] < 2 or log.magnetometer.shape[0] == 0:
        msg = "the seed 003 estimator needs dead wheels and a magnetometer (the omni-x robot)"
        raise ConfigError(msg)
    samples = align_samples(
        log.dead_wheel_t_s[first_row:],
        log.dead_wheel_cumulative_counts[first_row:],
        log.imu_t_s,
        log.gyro_radps[:, 2],
        log.accel_mps2,
        log.magnetometer_t_s,
        log.magnetic_field_g,
    )
    return samples.since(since_s)
