"""Closed-loop (ultimate-gain) Ziegler–Nichols tuning, the "Ziegler–Nichols 2" method of seed 003.

:func:`find_ultimate_gain` bisects Ku on a step experiment, :func:`ziegler_nichols_gains` applies a
rule (:class:`ZnRule`) to Ku and Pu, :func:`step_response_metrics` compares the results.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.control.pid import PidParams
from omnical.errors import CalibrationError, ConfigError

__all__ = [
    "Oscillation",
    "StepMetrics",
    "UltimatePoint",
    "ZnRule",
    "analyse_oscillation",
    "find_ultimate_gain",
    "step_response_metrics",
    "ziegler_nichols_gains",
]

StepExperiment = Callable[[float, float], tuple[ArrayLike, ArrayLike]]


class ZnRule(StrEnum):
    """Controller type of the Ziegler–Nichols table."""

    P = "P"
    PI = "PI"
    PID = "PID"
    PID_SOME_OVERSHOOT = "PID-some-overshoot"
    PID_NO_OVERSHOOT = "PID-no-overshoot"
    TYREUS_LUYBEN = "TL-PID"


@dataclass(frozen=True)
class Oscillation:
    """How a response oscillates.

    Attributes:
        growth_per_period: ratio of a swing to the swing one period earlier (fitted over all
            swings but the first); 1 = sustained, < 1 decaying, > 1 growing, 0 = no oscillation.
        period_s: mean spacing of successive maxima (NaN with fewer than two).
        swings: number of swings (extremum to next extremum) used.
    """

    growth_per_period: float
    period_s: float
    swings: int

    @property
    def growing(self) -> bool:
        """True when the oscillation grows (loop unstable)."""
        return self.growth_per_period > 1.0


def _extrema(y: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """Indices of local extrema (a flat run counts once) and which of them are maxima."""
    dy = np.diff(y)
    keep = np.flatnonzero(dy != 0.0)
    sign = np.sign(dy[keep])
    turns = np.flatnonzero(sign[1:] != sign[:-1])
    return keep[turns] + 1, sign[turns] > 0.0


def analyse_oscillation(t_s: ArrayLike, y: ArrayLike) -> Oscillation:
    """Growth and period of the oscillation in a step response.

    Args:
        t_s: (K,) increasing times.
        y: (K,) response.

    Returns:
        The oscillation; a non-finite response counts as growing without bound.

    Raises:
        ConfigError: shapes that differ.
    """
    t = np.asarray(t_s, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    if t.shape != yy.shape or t.ndim != 1:
        msg = f"expected t_s and y of the same (K,) shape, got {t.shape} and {yy.shape}"
        raise ConfigError(msg)
    if not np.all(np.isfinite(yy)):
        return Oscillation(math.inf, math.nan, 0)
    idx, is_max = _extrema(yy)
    maxima = idx[is_max]
    period = float(np.mean(np.diff(t[maxima]))) if maxima.size >= 2 else math.nan
    swing = np.abs(np.diff(yy[idx]))[1:]
    t_mid = 0.5 * (t[idx[1:]] + t[idx[:-1]])[1:]
    usable = swing > 1e-9 * (swing.max() if swing.size else 0.0)
    swing, t_mid = swing[usable], t_mid[usable]
    if swing.size < 2 or not math.isfinite(period):
        return Oscillation(0.0, period, int(swing.size))
    rate_per_s = np.polyfit(t_mid, np.log(swing), 1)[0]
    return Oscillation(float(np.exp(rate_per_s * period)), period, int(swing.size))


@dataclass(frozen=True)
class UltimatePoint:
    """The ultimate gain and period found by :func:`find_ultimate_gain`.

    Attributes:
        ku: ultimate proportional gain Ku.
        pu_s: ultimate period Pu.
        experiments: number of step experiments run.
    """

    ku: float
    pu_s: float
    experiments: int


def find_ultimate_gain(
    simulate: StepExperiment,
    duration_s: float,
    *,
    kp_start: float = 1.0,
    rtol: float = 1e-3,
    max_doublings: int = 40,
) -> UltimatePoint:
    """Find Ku (sustained oscillation) by bisection on the oscillation growth, and Pu.

    Doubles the gain from ``kp_start`` until the oscillation grows, then bisects to ``rtol``; Pu
    is the maxima's mean spacing at the upper (growing) gain. The response must be noise-free
    (every local extremum counts as a swing).

    Args:
        simulate: ``(kp, duration_s) -> (t_s, y)``, the P-only closed-loop step response.
        duration_s: length of each experiment; a dozen periods or more.
        kp_start: first gain tried (> 0).
        rtol: relative width of the final bracket.
        max_doublings: give up after this many doublings.

    Raises:
        ConfigError: non-positive ``kp_start``, ``rtol`` or ``duration_s``.
        CalibrationError: the loop never oscillates (a first-order plant, say).
    """
    if not (kp_start > 0.0 and rtol > 0.0 and duration_s > 0.0):
        msg = f"kp_start, rtol and duration_s must be > 0, got {kp_start}, {rtol}, {duration_s}"
        raise ConfigError(msg)
    runs = 0

    def trial(kp: float) -> Oscillation:
        nonlocal runs
        runs += 1
        t, y = simulate(kp, duration_s)
        return analyse_oscillation(t, y)

    low, high = 0.0, kp_start
    upper = trial(high)
    while not upper.growing:
        if runs > max_doublings:
            msg = f"no sustained oscillation up to kp = {high:.4g}: the loop has no ultimate gain"
            raise CalibrationError(msg)
        low, high = high, 2.0 * high
        upper = trial(high)
    while high - low > rtol * high:
        mid = 0.5 * (low + high)
        osc = trial(mid)
        if osc.growing:
            high, upper = mid, osc
        else:
            low = mid
    if not math.isfinite(upper.period_s):
        msg = f"the oscillation at kp = {high:.4g} has no measurable period; lengthen duration_s"
        raise CalibrationError(msg)
    return UltimatePoint(0.5 * (low + high), upper.period_s, runs)


def ziegler_nichols_gains(
    ku: float, pu_s: float, rule: ZnRule = ZnRule.PID, *, template: PidParams | None = None
) -> PidParams:
    """Controller settings from Ku and Pu by the classic closed-loop rules.

    Args:
        ku: ultimate gain.
        pu_s: ultimate period.
        rule: P, PI or PID.
        template: limits, filter and anti-windup to keep (gains replaced); default none.

    Raises:
        ConfigError: non-positive Ku or Pu, or an unknown rule.
    """
    if not (math.isfinite(ku) and ku > 0.0 and math.isfinite(pu_s) and pu_s > 0.0):
        msg = f"Ku and Pu must be finite and > 0, got {ku}, {pu_s}"
        raise ConfigError(msg)
    table = {
        ZnRule.P: (0.5 * ku, math.inf, 0.0),
        ZnRule.PI: (0.45 * ku, pu_s / 1.2, 0.0),
        ZnRule.PID: (0.6 * ku, pu_s / 2.0, pu_s / 8.0),
        ZnRule.PID_SOME_OVERSHOOT: (ku / 3.0, pu_s / 2.0, pu_s / 3.0),
        ZnRule.PID_NO_OVERSHOOT: (0.2 * ku, pu_s / 2.0, pu_s / 3.0),
        ZnRule.TYREUS_LUYBEN: (ku / 2.2, 2.2 * pu_s, pu_s / 6.3),
    }
    try:
        kp, ti, td = table[ZnRule(rule)]
    except ValueError as err:
        msg = f"unknown Ziegler–Nichols rule {rule!r}; use one of {[r.value for r in ZnRule]}"
        raise ConfigError(msg) from err
    base = template if template is not None else PidParams(kp=kp)
    return dataclasses.replace(base, kp=kp, ti_s=ti, td_s=td)


@dataclass(frozen=True)
class StepMetrics:
    """How a step response reaches its set point.

    Attributes:
        overshoot: (peak − set point) / set point, ≥ 0 (0.61 = 61 %).
        settling_time_s: first time after which the response stays within ``band`` of the set
            point (NaN if it never does).
        rise_time_s: time from 10 % to 90 % of the set point (NaN if not reached).
        band: the relative settling band used.
    """

    overshoot: float
    settling_time_s: float
    rise_time_s: float
    band: float


def step_response_metrics(
    t_s: ArrayLike, y: ArrayLike, setpoint: float, *, band: float = 0.02
) -> StepMetrics:
    """Overshoot, settling time (within ``band`` of the set point) and 10–90 % rise time.

    Raises:
        ConfigError: shapes that differ, a zero set point or a non-positive band.
    """
    t = np.asarray(t_s, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    if t.shape != yy.shape or t.ndim != 1 or t.size == 0:
        msg = f"expected t_s and y of the same (K,) shape, got {t.shape} and {yy.shape}"
        raise ConfigError(msg)
    if setpoint == 0.0 or not band > 0.0:
        msg = f"a step response needs a non-zero set point and band > 0, got {setpoint}, {band}"
        raise ConfigError(msg)
    rel = yy / setpoint
    overshoot = max(float(rel.max()) - 1.0, 0.0)
    outside = np.flatnonzero(np.abs(rel - 1.0) > band)
    if outside.size == 0:
        settling = float(t[0])
    elif outside[-1] == t.size - 1:
        settling = math.nan
    else:
        settling = float(t[outside[-1] + 1])
    above10 = np.flatnonzero(rel >= 0.1)
    above90 = np.flatnonzero(rel >= 0.9)
    rise = float(t[above90[0]] - t[above10[0]]) if above90.size else math.nan
    return StepMetrics(overshoot, settling, rise, band)
