"""Discrete single-input plants and closed loops around them: what PID tuning is tried on.

:func:`discretize_plant` turns a continuous transfer function with dead time into a discrete
state-space model (zero-order hold on the input, the dead time as a shift register on the
output, saturation on the input). :func:`motor_speed_plant` is the DC gear-motor speed loop of
seed 003 at its scale (set points 100–200 rpm): PWM counts in, rpm out, a mechanical and an
electrical lag and the measurement delay of an encoder speed estimate. A continuous first-order
lag never oscillates under proportional control (sampled, it does, but only at twice the sample
period); the second pole and the delay give the Ziegler–Nichols experiment a real ultimate gain.

:func:`simulate_p_loop` is the proportional-only step experiment of the closed-loop
Ziegler–Nichols method; :func:`simulate_pid_loop` and :func:`speed_tracking_table` run tuned PID
loops (seed 003 Table II).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from omnical.control.pid import PidParams, pid_batch_state, pid_step_batch
from omnical.errors import ConfigError

__all__ = [
    "DiscretePlant",
    "SpeedTrackingTable",
    "discretize_plant",
    "motor_speed_plant",
    "simulate_p_loop",
    "simulate_pid_loop",
    "speed_tracking_table",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class DiscretePlant:
    """x[k+1] = A x[k] + B sat(u[k]),  y[k] = C x[k]  (strictly proper, sampled every ``dt_s``).

    Attributes:
        a: (n, n) state matrix A.
        b: (n,) input vector B.
        c: (n,) output vector C.
        dt_s: sample period.
        input_min, input_max: input saturation (actuator limits).
    """

    a: FloatArray
    b: FloatArray
    c: FloatArray
    dt_s: float
    input_min: float = -math.inf
    input_max: float = math.inf

    @property
    def dc_gain(self) -> float:
        """Steady-state output per unit of constant input, C (I − A)⁻¹ B."""
        n = self.a.shape[0]
        return float(self.c @ np.linalg.solve(np.eye(n) - self.a, self.b))


def discretize_plant(
    num: ArrayLike,
    den: ArrayLike,
    dt_s: float,
    *,
    dead_time_s: float = 0.0,
    input_min: float = -math.inf,
    input_max: float = math.inf,
) -> DiscretePlant:
    """Zero-order-hold discretisation of num(s)/den(s) · e^(−s L).

    Args:
        num: numerator coefficients, highest power first.
        den: denominator coefficients, highest power first; degree above the numerator's.
        dt_s: sample period.
        dead_time_s: L, a whole number of sample periods.
        input_min, input_max: input saturation.

    Raises:
        ConfigError: a non-strictly-proper plant, a bad period or a dead time that is not a
            multiple of the period.
    """
    if not (math.isfinite(dt_s) and dt_s > 0.0):
        msg = f"sample period must be finite and > 0, got {dt_s}"
        raise ConfigError(msg)
    num_a = np.trim_zeros(np.atleast_1d(np.asarray(num, dtype=np.float64)), "f")
    den_a = np.trim_zeros(np.atleast_1d(np.asarray(den, dtype=np.float64)), "f")
    if den_a.size < 2 or num_a.size >= den_a.size:
        msg = f"plant must be strictly proper (deg num < deg den), got num {num_a}, den {den_a}"
        raise ConfigError(msg)
    delay = round(dead_time_s / dt_s)
    if dead_time_s < 0.0 or abs(delay * dt_s - dead_time_s) > 1e-9 * max(1.0, dead_time_s):
        msg = f"dead time {dead_time_s} s must be >= 0 and a multiple of the period {dt_s} s"
        raise ConfigError(msg)
    numd, dend, _ = signal.cont2discrete((num_a, den_a), dt_s, method="zoh")
    numd = np.ravel(numd)[1:]  # ZOH of a strictly proper plant: the z^n coefficient is 0
    a, b, c, _ = signal.tf2ss(numd, np.ravel(dend))
    n = a.shape[0]
    big_a = np.zeros((n + delay, n + delay))
    big_a[:n, :n] = a
    big_b = np.concatenate([np.ravel(b), np.zeros(delay)])
    big_c = np.zeros(n + delay)
    if delay == 0:
        big_c[:n] = np.ravel(c)
    else:
        big_a[n, :n] = np.ravel(c)
        for i in range(1, delay):
            big_a[n + i, n + i - 1] = 1.0
        big_c[-1] = 1.0
    return DiscretePlant(big_a, big_b, big_c, dt_s, input_min, input_max)


def motor_speed_plant(
    *,
    gain_rpm_per_count: float = 0.64,
    mechanical_time_constant_s: float = 0.12,
    electrical_time_constant_s: float = 0.01,
    measurement_delay_s: float = 0.03,
    dt_s: float = 0.01,
    pwm_limit_counts: float = 1023.0,
) -> DiscretePlant:
    """A DC gear-motor speed plant at seed 003's scale: PWM counts in, wheel speed in rpm out.

    G(s) = K e^(−s L) / ((τm s + 1)(τe s + 1)): τm is the mechanical lag of the motor and its
    wheel load, τe the electrical (armature and driver) pole, L the delay of the speed estimate
    (encoder counts over a window plus one control period). With the defaults the 10-bit PWM
    (±1023 counts) reaches 655 rpm, the loop runs at 100 Hz and the ultimate gain is 8.3
    counts/rpm (period 0.157 s), so that the Ziegler–Nichols proportional gain 0.6 Ku comes out
    at seed 003's Kp = 5; the paper's Ti = 2.8 and Td = 0.6 cannot be seconds for such a motor.

    Args:
        gain_rpm_per_count: K, steady-state rpm per PWM count.
        mechanical_time_constant_s: τm.
        electrical_time_constant_s: τe.
        measurement_delay_s: L, a multiple of ``dt_s``.
        dt_s: control period.
        pwm_limit_counts: |PWM| saturation.

    Raises:
        ConfigError: non-positive constants, or a delay that is not a multiple of the period.
    """
    for name, value in (
        ("gain_rpm_per_count", gain_rpm_per_count),
        ("mechanical_time_constant_s", mechanical_time_constant_s),
        ("electrical_time_constant_s", electrical_time_constant_s),
        ("pwm_limit_counts", pwm_limit_counts),
    ):
        if not (math.isfinite(value) and value > 0.0):
            msg = f"{name} must be finite and > 0, got {value}"
            raise ConfigError(msg)
    den = np.polymul([mechanical_time_constant_s, 1.0], [electrical_time_constant_s, 1.0])
    return discretize_plant(
        [gain_rpm_per_count],
        den,
        dt_s,
        dead_time_s=measurement_delay_s,
        input_min=-pwm_limit_counts,
        input_max=pwm_limit_counts,
    )


def _check_duration(plant: DiscretePlant, duration_s: float) -> int:
    if not (math.isfinite(duration_s) and duration_s > 0.0):
        msg = f"duration must be finite and > 0, got {duration_s}"
        raise ConfigError(msg)
    return max(2, math.ceil(duration_s / plant.dt_s - 1e-9) + 1)


def simulate_p_loop(
    plant: DiscretePlant, kp: float, duration_s: float, *, setpoint: float = 1.0
) -> tuple[FloatArray, FloatArray]:
    """Step response of the proportional-only loop u = kp (r − y), from rest.

    This is the ``simulate(kp, duration_s)`` experiment of the closed-loop Ziegler–Nichols
    method (bind the plant and set point with ``functools.partial``).

    Returns:
        ``(t_s, y)``, both (K,), sampled every ``plant.dt_s``.

    Raises:
        ConfigError: a non-positive duration.
    """
    steps = _check_duration(plant, duration_s)
    a, b, c = plant.a, plant.b, plant.c
    x = np.zeros(a.shape[0])
    y = np.empty(steps)
    for k in range(steps):
        y[k] = c @ x
        u = min(max(kp * (setpoint - y[k]), plant.input_min), plant.input_max)
        x = a @ x + b * u
    return np.arange(steps, dtype=np.float64) * plant.dt_s, y


def simulate_pid_loop(
    plant: DiscretePlant,
    params: PidParams,
    setpoints: ArrayLike,
    duration_s: float,
    *,
    noise_std: float = 0.0,
    rng: np.random.Generator | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Set-point steps from rest under PID control, one loop per set point, run together.

    The controller sees the plant output plus white measurement noise of σ ``noise_std``.

    Args:
        plant: the plant (one copy per set point).
        params: PID gains and limits (sampled at the plant's period).
        setpoints: (M,) set points applied at t = 0.
        duration_s: simulated time.
        noise_std: σ of the measurement noise, output units.
        rng: random generator; required when ``noise_std`` > 0.

    Returns:
        ``(t_s (K,), measured (M, K), outputs (M, K))``.

    Raises:
        ConfigError: a non-positive duration, negative noise, or noise without a generator.
    """
    steps = _check_duration(plant, duration_s)
    r = np.atleast_1d(np.asarray(setpoints, dtype=np.float64))
    if not (math.isfinite(noise_std) and noise_std >= 0.0):
        msg = f"noise_std must be finite and >= 0, got {noise_std}"
        raise ConfigError(msg)
    if noise_std > 0.0 and rng is None:
        msg = "a random generator (rng) is needed for measurement noise"
        raise ConfigError(msg)
    noise = np.zeros((steps, r.size))
    if rng is not None and noise_std > 0.0:
        noise = rng.normal(0.0, noise_std, size=(steps, r.size))
    x = np.zeros((r.size, plant.a.shape[0]))
    state = pid_batch_state(r.size)
    measured = np.empty((r.size, steps))
    outputs = np.empty((r.size, steps))
    for k in range(steps):
        measured[:, k] = x @ plant.c + noise[k]
        u, state = pid_step_batch(params, state, r, measured[:, k], plant.dt_s)
        outputs[:, k] = u
        x = x @ plant.a.T + np.outer(np.clip(u, plant.input_min, plant.input_max), plant.b)
    return np.arange(steps, dtype=np.float64) * plant.dt_s, measured, outputs


@dataclass(frozen=True, eq=False)
class SpeedTrackingTable:
    """Mean speed per set point and motor after settling (seed 003 Table II).

    Attributes:
        setpoint_rpm: (S,) set points.
        mean_rpm: (S, M) mean measured speed over the averaging window, per motor.
        error_pct: (S, M) 100 (mean − set point) / set point.
    """

    setpoint_rpm: FloatArray
    mean_rpm: FloatArray
    error_pct: FloatArray

    def rows(self) -> list[tuple[float, ...]]:
        """(set point, mean motor 1, ..., mean motor M) per set point, like Table II."""
        return [(float(s), *map(float, m)) for s, m in zip(self.setpoint_rpm, self.mean_rpm, strict=True)]


def speed_tracking_table(
    plants: Sequence[DiscretePlant],
    params: PidParams,
    *,
    setpoints_rpm: ArrayLike = tuple(range(110, 201, 10)),
    settle_s: float = 3.0,
    samples: int = 100,
    repeats: int = 1,
    noise_rpm: float = 0.0,
    rng: np.random.Generator | None = None,
) -> SpeedTrackingTable:
    """Seed 003 Table II on simulated motors: mean of ``samples`` readings after ``settle_s``.

    As in the paper, each motor is stepped to each set point, the last ``samples`` speed
    readings are averaged and the averages of ``repeats`` runs are averaged again.

    Args:
        plants: one plant per motor (M).
        params: the PID shared by all motors.
        setpoints_rpm: (S,) set points (default 110, 120, ..., 200 rpm).
        settle_s: time before averaging starts.
        samples: readings averaged per run.
        repeats: runs per set point and motor.
        noise_rpm: σ of the speed-reading noise.
        rng: random generator; required when ``noise_rpm`` > 0.

    Raises:
        ConfigError: no plants, fewer than one sample or repeat, or bad simulation settings.
    """
    if not plants or samples < 1 or repeats < 1:
        msg = f"need at least one plant, sample and repeat (got {len(plants)}, {samples}, {repeats})"
        raise ConfigError(msg)
    sp = np.atleast_1d(np.asarray(setpoints_rpm, dtype=np.float64))
    means = np.empty((sp.size, len(plants)))
    for m, plant in enumerate(plants):
        duration = settle_s + samples * plant.dt_s
        _, measured, _ = simulate_pid_loop(
            plant, params, np.repeat(sp, repeats), duration, noise_std=noise_rpm, rng=rng
        )
        means[:, m] = measured[:, -samples:].mean(axis=1).reshape(sp.size, repeats).mean(axis=1)
    return SpeedTrackingTable(sp, means, 100.0 * (means - sp[:, None]) / sp[:, None])
