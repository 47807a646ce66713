"""Motion scripts: the scripted environment of seed 000 §3, as YAML ``hold`` and ``move`` steps.

:func:`load_script` / :func:`parse_script` give a :class:`MotionScript`, refusing a step beyond
the robot's limits (:class:`~omnical.errors.LimitError`). Format: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Final, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import (
    Field,
    ValidationError,
    model_validator,
)

from omnical.config_models import StrictModel
from omnical.errors import ConfigError, LimitError
from omnical.robot.description import Limits
from omnical.userfiles import read_yaml

__all__ = [
    "CommandSource",
    "MotionScript",
    "ScheduledCommandSource",
    "Step",
    "TwistSequence",
    "compile_script",
    "load_script",
    "parse_script",
]


MAX_SCRIPT_DURATION_S: Final = 4 * 3600.0
"""Longest run one script may ask for: 4 h of robot time."""
MAX_STEPS: Final = 200_000
"""Most steps in one script."""


class _HoldModel(StrictModel):
    duration_s: float = Field(gt=0.0, le=3600.0)
    marker: str | None = None


class _MoveModel(StrictModel):
    vx_mps: float = Field(default=0.0, ge=-20.0, le=20.0)
    vy_mps: float = Field(default=0.0, ge=-20.0, le=20.0)
    wz_radps: float = Field(default=0.0, ge=-50.0, le=50.0)
    duration_s: float | None = Field(default=None, gt=0.0, le=3600.0)
    distance_m: float | None = Field(default=None, gt=0.0, le=1000.0)
    angle_deg: float | None = Field(default=None, gt=0.0, le=36000.0)
    angle_rad: float | None = Field(default=None, gt=0.0, le=700.0)
    accel_scale: float = Field(default=1.0, ge=0.01, le=1.0)
    ramp: bool = True
    marker: str | None = None

    @model_validator(mode="after")
    def _one_extent(self) -> _MoveModel:
        given = [
            n
            for n in ("duration_s", "distance_m", "angle_deg", "angle_rad")
            if getattr(self, n) is not None
        ]
        if len(given) != 1:
            msg = f"give exactly one of duration_s, distance_m, angle_deg, angle_rad (got {given or 'none'})"
            raise ValueError(msg)
        if self.vx_mps == 0.0 and self.vy_mps == 0.0 and self.wz_radps == 0.0:
            msg = "a move needs a non-zero vx_mps, vy_mps or wz_radps (use hold to stand still)"
            raise ValueError(msg)
        if self.distance_m is not None and self.vx_mps == 0.0 and self.vy_mps == 0.0:
            msg = "distance_m needs a translation (vx_mps or vy_mps)"
            raise ValueError(msg)
        if (self.angle_deg is not None or self.angle_rad is not None) and self.wz_radps == 0.0:
            msg = "an angle needs wz_radps"
            raise ValueError(msg)
        return self


class _StepModel(StrictModel):
    hold: _HoldModel | None = None
    move: _MoveModel | None = None

    @model_validator(mode="after")
    def _one_kind(self) -> _StepModel:
        if (self.hold is None) == (self.move is None):
            msg = "each step is exactly one of 'hold' or 'move'"
            raise ValueError(msg)
        return self


class _ScriptModel(StrictModel):
    name: str = "script"
    rate_hz: float = Field(default=50.0, ge=1.0, le=1000.0)
    steps: list[_StepModel] = Field(min_length=1, max_length=MAX_STEPS)


@dataclass(frozen=True)
class Step:
    """One compiled step: a twist direction with a trapezoidal magnitude profile.

    Attributes:
        index: position in the script.
        kind: "hold" or "move".
        twist: (vx m/s, vy m/s, wz rad/s) at full magnitude.
        start_s: start time from the script's beginning.
        rise_s: ramp duration (0 for a step command).
        peak: peak magnitude fraction (1 unless the move is too short to reach full speed).
        cruise_s: time at the peak.
        marker: the user's label, if any.
    """

    index: int
    kind: str
    twist: tuple[float, float, float]
    start_s: float
    rise_s: float
    peak: float
    cruise_s: float
    marker: str | None

    @property
    def duration_s(self) -> float:
        """Total duration of the step."""
        return 2.0 * self.rise_s + self.cruise_s

    @property
    def end_s(self) -> float:
        """End time from the script's beginning."""
        return self.start_s + self.duration_s

    def fraction_at(self, t_s: float) -> float:
        """Magnitude fraction at script time ``t_s`` (0 outside the step)."""
        tau = t_s - self.start_s
        if tau < 0.0 or tau >= self.duration_s:
            return 0.0
        if self.rise_s <= 0.0:
            return self.peak
        if tau < self.rise_s:
            return self.peak * tau / self.rise_s
        if tau < self.rise_s + self.cruise_s:
            return self.peak
        return self.peak * (self.duration_s - tau) / self.rise_s


@dataclass(frozen=True)
class _Timeline:
    """The steps of a script as sorted arrays, for bisection (``ordered``: steps in time order,
    none overlapping the next, so at most one step holds any time and bisection finds it)."""

    starts: list[float]
    ends: list[float]
    ordered: bool
    start_s: NDArray[np.float64]
    end_s: NDArray[np.float64]
    duration_s: NDArray[np.float64]
    rise_s: NDArray[np.float64]
    peak: NDArray[np.float64]
    cruise_s: NDArray[np.float64]
    twist: NDArray[np.float64]
    index: NDArray[np.int64]

    @classmethod
    def of(cls, steps: Sequence[Step]) -> _Timeline:
        starts = [s.start_s for s in steps]
        ends = [s.end_s for s in steps]
        ordered = all(a <= b and e <= b for a, b, e in zip(starts, starts[1:], ends, strict=False))
        return cls(
            starts=starts,
            ends=ends,
            ordered=ordered,
            start_s=np.array(starts, dtype=np.float64),
            end_s=np.array(ends, dtype=np.float64),
            duration_s=np.array([s.duration_s for s in steps], dtype=np.float64),
            rise_s=np.array([s.rise_s for s in steps], dtype=np.float64),
            peak=np.array([s.peak for s in steps], dtype=np.float64),
            cruise_s=np.array([s.cruise_s for s in steps], dtype=np.float64),
            twist=np.array([s.twist for s in steps], dtype=np.float64).reshape(-1, 3),
            index=np.array([s.index for s in steps], dtype=np.int64),
        )

    def position(self, t_s: float) -> int:
        """Position in the steps of the step holding ``t_s``, −1 if none (needs ``ordered``)."""
        i = bisect.bisect_right(self.starts, t_s) - 1
        return i if i >= 0 and t_s < self.ends[i] else -1

    def positions(self, t_s: NDArray[np.float64]) -> NDArray[np.int64]:
        """:meth:`position` of every time (needs ``ordered``)."""
        i = np.searchsorted(self.start_s, t_s, side="right").astype(np.int64) - 1
        safe = np.maximum(i, 0)
        inside = (i >= 0) & (t_s < self.end_s[safe]) if len(self.starts) else i >= 0
        return np.where(inside, i, -1)


@dataclass(frozen=True)
class MotionScript:
    """A compiled script: steps on a timeline, checked against a robot's limits."""

    name: str
    rate_hz: float
    steps: tuple[Step, ...]

    @property
    def duration_s(self) -> float:
        """Total duration."""
        return self.steps[-1].end_s if self.steps else 0.0

    @cached_property
    def _timeline(self) -> _Timeline:
        return _Timeline.of(self.steps)

    def _position(self, t_s: float) -> int:
        timeline = self._timeline
        if timeline.ordered:
            return timeline.position(t_s)
        for i, step in enumerate(self.steps):  # steps out of order: the first that holds t_s
            if step.start_s <= t_s < step.end_s:
                return i
        return -1

    def twist_at(self, t_s: float) -> tuple[float, float, float]:
        """Commanded body twist at script time ``t_s``."""
        i = self._position(t_s)
        if i < 0:
            return (0.0, 0.0, 0.0)
        step = self.steps[i]
        f = step.fraction_at(t_s)
        return (step.twist[0] * f, step.twist[1] * f, step.twist[2] * f)

    def step_at(self, t_s: float) -> Step | None:
        """The step active at ``t_s``."""
        i = self._position(t_s)
        return self.steps[i] if i >= 0 else None

    def _positions(self, t_s: NDArray[np.float64]) -> NDArray[np.int64]:
        timeline = self._timeline
        if timeline.ordered:
            return timeline.positions(t_s)
        return np.array([self._position(float(t)) for t in t_s], dtype=np.int64)

    def twists_at(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """:meth:`twist_at` of every time, (N, 3); the same numbers, bit for bit."""
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        pos = self._positions(t)
        tl = self._timeline
        if not len(self.steps):
            return np.zeros((len(t), 3))
        i = np.maximum(pos, 0)
        tau = t - tl.start_s[i]
        rise, peak, cruise, dur = tl.rise_s[i], tl.peak[i], tl.cruise_s[i], tl.duration_s[i]
        # Step.fraction_at, branch by branch, in the same operation order
        with np.errstate(divide="ignore", invalid="ignore"):
            f = np.where(
                rise <= 0.0,
                peak,
                np.where(
                    tau < rise,
                    peak * tau / rise,
                    np.where(tau < rise + cruise, peak, peak * (dur - tau) / rise),
                ),
            )
        f = np.where((tau < 0.0) | (tau >= dur), 0.0, f)
        out = np.where((pos >= 0)[:, None], tl.twist[i] * f[:, None], 0.0)
        return np.asarray(out, dtype=np.float64)

    def step_index_at(self, t_s: ArrayLike) -> NDArray[np.int64]:
        """The ``index`` of the step active at every time, −1 where none, (N,)."""
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        pos = self._positions(t)
        if not len(self.steps):
            return pos
        return np.where(pos >= 0, self._timeline.index[np.maximum(pos, 0)], -1)


class CommandSource(Protocol):
    """What the Runner plays: a named, timed twist command with optional steps."""

    @property
    def name(self) -> str:
        """Name used in step markers."""

    @property
    def rate_hz(self) -> float:
        """Command rate."""

    @property
    def steps(self) -> tuple[Step, ...]:
        """Steps, for markers (may be empty)."""

    @property
    def duration_s(self) -> float:
        """Total duration."""

    def twist_at(self, t_s: float) -> tuple[float, float, float]:
        """Commanded twist at ``t_s`` from the start."""

    def step_at(self, t_s: float) -> Step | None:
        """The step active at ``t_s``, if any."""


@runtime_checkable
class ScheduledCommandSource(CommandSource, Protocol):
    """A command source that also answers for many times at once (what the Runner prefers)."""

    def twists_at(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """(N, 3) commanded twists at the times ``t_s``: ``twist_at`` of each, bit for bit."""

    def step_index_at(self, t_s: ArrayLike) -> NDArray[np.int64]:
        """(N,) ``index`` of the step active at each time, −1 where none."""


@dataclass(frozen=True)
class TwistSequence:
    """A sampled twist command (zero-order hold), e.g. a reference's feed-forward commands.

    Attributes:
        name: label for markers.
        t_s: (N,) command times from the start, increasing, t_s[0] = 0.
        twists: (N, 3) body twists (vx m/s, vy m/s, wz rad/s), each held until the next time;
            the last one is held for one command period.
        rate_hz: rate the Runner sends commands at.
    """

    name: str
    t_s: NDArray[np.float64]
    twists: NDArray[np.float64]
    rate_hz: float = 50.0

    @classmethod
    def from_arrays(
        cls, name: str, t_s: ArrayLike, twists: ArrayLike, rate_hz: float = 50.0
    ) -> TwistSequence:
        """Build and check a sequence."""
        t = np.asarray(t_s, dtype=np.float64)
        tw = np.asarray(twists, dtype=np.float64)
        if t.ndim != 1 or tw.shape != (t.shape[0], 3) or t.size == 0 or np.any(np.diff(t) <= 0):
            msg = f"{name}: need increasing times (N,) and twists (N, 3), got {t.shape} and {tw.shape}"
            raise ConfigError(msg)
        return cls(name, t - t[0], tw, rate_hz)

    @property
    def steps(self) -> tuple[Step, ...]:
        """A sequence has one implicit step."""
        return (Step(0, "move", (0.0, 0.0, 0.0), 0.0, 0.0, 1.0, self.duration_s, self.name),)

    @property
    def duration_s(self) -> float:
        """Last command time plus one period."""
        return float(self.t_s[-1]) + 1.0 / self.rate_hz

    def twist_at(self, t_s: float) -> tuple[float, float, float]:
        """Zero-order hold of the sampled commands; zero outside."""
        if t_s < 0.0 or t_s >= self.duration_s:
            return (0.0, 0.0, 0.0)
        i = int(np.searchsorted(self.t_s, t_s, side="right")) - 1
        row = self.twists[max(i, 0)]
        return (float(row[0]), float(row[1]), float(row[2]))

    def step_at(self, t_s: float) -> Step | None:
        """The implicit step while the sequence plays."""
        return self.steps[0] if 0.0 <= t_s < self.duration_s else None

    def twists_at(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """:meth:`twist_at` of every time, (N, 3)."""
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        i = np.searchsorted(self.t_s, t, side="right") - 1
        rows = self.twists[np.maximum(i, 0)]
        inside = (t >= 0.0) & (t < self.duration_s)
        return np.asarray(np.where(inside[:, None], rows, 0.0), dtype=np.float64)

    def step_index_at(self, t_s: ArrayLike) -> NDArray[np.int64]:
        """0 while the sequence plays, −1 outside, (N,)."""
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        return np.where((t >= 0.0) & (t < self.duration_s), 0, -1).astype(np.int64)


def _compile_move(index: int, m: _MoveModel, start_s: float, limits: Limits, where: str) -> Step:
    twist = (m.vx_mps, m.vy_mps, m.wz_radps)
    for value, vmax, name in zip(
        twist, limits.max_twist, ("vx_mps", "vy_mps", "wz_radps"), strict=True
    ):
        if abs(value) > vmax + 1e-12:
            msg = f"{where}: step {index + 1} (move): {name} = {value} exceeds the robot's limit {vmax}"
            raise LimitError(msg)
    accel = limits.max_accel * m.accel_scale
    rise = max(abs(v) / a for v, a in zip(twist, accel, strict=True)) if m.ramp else 0.0
    if m.duration_s is not None:
        if m.duration_s < 2.0 * rise:
            msg = (
                f"{where}: step {index + 1} (move): duration_s {m.duration_s} is shorter "
                f"than its ramps ({2 * rise:.3f} s)"
            )
            raise LimitError(msg)
        integral_s = m.duration_s - rise
    elif m.distance_m is not None:
        integral_s = m.distance_m / math.hypot(m.vx_mps, m.vy_mps)
    else:
        angle = m.angle_rad if m.angle_rad is not None else math.radians(m.angle_deg or 0.0)
        integral_s = angle / abs(m.wz_radps)
    if rise > 0.0 and integral_s < rise:
        peak = math.sqrt(integral_s / rise)
        return Step(index, "move", twist, start_s, rise * peak, peak, 0.0, m.marker)
    return Step(index, "move", twist, start_s, rise, 1.0, integral_s - rise, m.marker)


def compile_script(model: _ScriptModel, limits: Limits, where: str) -> MotionScript:
    """Lay the steps on a timeline against the robot's limits."""
    steps: list[Step] = []
    t = 0.0
    for i, s in enumerate(model.steps):
        if s.hold is not None:
            step = Step(i, "hold", (0.0, 0.0, 0.0), t, 0.0, 0.0, s.hold.duration_s, s.hold.marker)
        else:
            assert s.move is not None
            step = _compile_move(i, s.move, t, limits, where)
        steps.append(step)
        t = step.end_s
        if t > MAX_SCRIPT_DURATION_S + 1e-6:
            msg = (
                f"{where}: field 'steps.{i}': the script reaches {t:.0f} s, more than "
                f"{MAX_SCRIPT_DURATION_S:.0f} s ({MAX_SCRIPT_DURATION_S / 3600:.0f} h) of robot "
                "time in one run; split it into several runs"
            )
            raise ConfigError(msg)
    return MotionScript(model.name, model.rate_hz, tuple(steps))


def parse_script(data: Any, limits: Limits, source: str = "<script>") -> MotionScript:
    """Validate a parsed YAML mapping into a compiled MotionScript."""
    if not isinstance(data, dict):
        msg = f"{source}: a motion script must be a mapping with 'steps', got {type(data).__name__}"
        raise ConfigError(msg)
    try:
        model = _ScriptModel.model_validate(data)
    except ValidationError as err:
        first = err.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "(top level)"
        reason = str(first["msg"]).removeprefix("Value error, ")
        msg = f"{source}: field '{where}': {reason}"
        raise ConfigError(msg) from None
    return compile_script(model, limits, source)


def load_script(path: str | Path, limits: Limits) -> MotionScript:
    """Load a motion script YAML file, or a built-in script by name (see :mod:`omnical.experiment.library`)."""
    from omnical.experiment.library import builtin_script_data, builtin_script_names

    text = str(path)
    if text in builtin_script_names():
        return parse_script(builtin_script_data(text), limits, f"built-in script {text}")
    p = Path(text)
    if not p.exists() and not p.suffix:
        names = ", ".join(builtin_script_names())
        msg = f"{text}: no such script file, and not a built-in script ({names})"
        raise ConfigError(msg)
    return parse_script(read_yaml(p, "motion script"), limits, str(p))
