"""The calibration campaign of seed 000 Figure 7: procedures, iterations, validation, measures.

:func:`run_campaign` runs it on a :class:`Bench` (records a script with factors installed) and
writes nothing; :func:`estimate_factors` analyses recordings offline. Design: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from omnical.calibration.measures import Measures, measure_scripts, measures_from_recordings
from omnical.calibration.procedures.analysis import FACTOR_NAMES, analyse_procedures
from omnical.calibration.procedures.scripts import (
    lateral_procedure,
    longitudinal_procedure,
    rotation_procedure,
)
from omnical.calibration.procedures.tracks import (
    ODOM_YAW_DEADBAND_RADPS,
    hedge_offset_xy,
    yaw_deadband_radps,
)
from omnical.choices import EstimationMethod as MethodChoice
from omnical.choices import parse_choice
from omnical.errors import CalibrationError, ConfigError
from omnical.experiment.script import MotionScript, parse_script
from omnical.ips.beacons import BeaconMap
from omnical.ips.solve.fixes import Fixes, fixes_from_positions
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import FACTORS
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import EVENTS
from omnical.robot.description import RobotDescription

if TYPE_CHECKING:
    from omnical.calibration.joint.estimate import JointEstimate

__all__ = [
    "INSTALLED_EVENT",
    "REFERENCE_RATE_HZ",
    "REFERENCE_SIGMA_M",
    "Bench",
    "CampaignProgress",
    "CampaignResult",
    "EstimationMethod",
    "ExternalReference",
    "FactorEstimate",
    "Iteration",
    "ProgressFn",
    "Tolerance",
    "Validation",
    "estimate_factors",
    "installed_from_recordings",
    "reference_fixes",
    "run_campaign",
    "with_installed_event",
]

EstimationMethod = MethodChoice | Literal["procedures", "joint"]
"""An estimation method (:class:`omnical.choices.EstimationMethod` or its plain string):
``procedures``, seed 000's per-move analysis; ``joint``, all factors in one least squares."""

INSTALLED_EVENT = "installed_factors"
"""``omnical`` key of the ``/omnical/events`` JSON that records the installed factors."""

_ROTATION_STAGE = ("scale_rotational",)


# ----------------------------------------------------------------------------- options, progress


@dataclass(frozen=True)
class Tolerance:
    """When the iterations stop: no factor changed by more than this in the last iteration.

    Attributes:
        scale_relative: largest relative change of a scaling (0.003 = 0.3 %).
        crosstalk_rad_per_m: largest change of a cross-talk, rad/m.
    """

    scale_relative: float = 0.003
    crosstalk_rad_per_m: float = 0.001

    def __post_init__(self) -> None:
        for name in ("scale_relative", "crosstalk_rad_per_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                msg = f"tolerance {name} must be a finite number > 0, got {value}"
                raise ConfigError(msg)

    def changes(self, old: CorrectionFactors, new: CorrectionFactors) -> dict[str, float]:
        """Change per factor: relative for the scalings, rad/m for the cross-talks."""
        return {f.field: f.change(getattr(old, f.field), getattr(new, f.field)) for f in FACTORS}

    def met(self, old: CorrectionFactors, new: CorrectionFactors) -> bool:
        """No factor changed by more than the tolerance from ``old`` to ``new``."""
        changes = self.changes(old, new)
        for f in FACTORS:
            limit = self.scale_relative if f.is_scale else self.crosstalk_rad_per_m
            if not abs(changes[f.field]) <= limit:
                return False
        return True


@dataclass(frozen=True)
class CampaignProgress:
    """What the campaign is doing, for a progress display.

    Attributes:
        step: one line, e.g. ``iteration 1: rotation procedure``.
        done_s: robot time run so far in this step (runs), s.
        total_s: robot time of the step; 0 for a step that is not a run (analysis, files).
    """

    step: str
    done_s: float = 0.0
    total_s: float = 0.0


ProgressFn = Callable[[CampaignProgress], None]
"""Receives a :class:`CampaignProgress` at every step and every tick of a run."""


# ----------------------------------------------------------------------------- benches


class Bench(Protocol):
    """Runs motion scripts on a robot with correction factors installed in its controller."""

    def run(
        self,
        script: MotionScript,
        installed: CorrectionFactors,
        *,
        name: str,
        on_tick: Callable[[float, float], None] | None = None,
    ) -> Recording:
        """Install ``installed`` in the vehicle controller, run ``script``, return the recording.

        Args:
            script: the compiled motion script.
            installed: the factors the vehicle controller compensates with for this run.
            name: a short name for the run (unique within a campaign).
            on_tick: progress callback ``(elapsed_s, total_s)`` of robot time.
        """
        ...


# ----------------------------------------------------------------------------- installed factors


def with_installed_event(recording: Recording, installed: CorrectionFactors) -> Recording:
    """The recording with an ``installed_factors`` event at its start on ``/omnical/events``.

    Args:
        recording: any recording.
        installed: the factors the vehicle controller compensated with.

    Returns:
        A new recording; the event's text is
        ``{"omnical": "installed_factors", "factors": {<field>: <value>, ...}}``.
    """
    text = json.dumps({"omnical": INSTALLED_EVENT, "factors": installed.as_dict()})
    t = np.array([recording.start_ns], dtype=np.int64)
    texts = np.array([text], dtype=object)
    if recording.has(EVENTS):
        old = recording.topic(EVENTS)
        t = np.concatenate([t, old.t_ns])
        texts = np.concatenate([texts, np.asarray(old["text"], dtype=object)])
    order = np.argsort(t, kind="stable")
    return recording.with_table(EVENTS, Table(t[order], {"text": texts[order]}))


def _installed_of(recording: Recording, index: int) -> CorrectionFactors | None:
    if not recording.has(EVENTS):
        return None
    for text in recording.topic(EVENTS)["text"]:
        try:
            data = json.loads(str(text))
        except json.JSONDecodeError:
            continue
        if isinstance(data, dict) and data.get("omnical") == INSTALLED_EVENT:
            values = data.get("factors")
            if not isinstance(values, dict):
                msg = f"recording {index}: malformed installed_factors event: {text}"
                raise CalibrationError(msg)
            try:
                return CorrectionFactors(**{k: float(values[k]) for k in FACTOR_NAMES})
            except (KeyError, TypeError, ValueError):
                msg = f"recording {index}: malformed installed_factors event: {text}"
                raise CalibrationError(msg) from None
    return None


def installed_from_recordings(recordings: Sequence[Recording]) -> CorrectionFactors | None:
    """The factors the recordings were made with, from their ``installed_factors`` events.

    Returns:
        The common factors, or None when no recording carries the event.

    Raises:
        CalibrationError: the recordings were made with different factors, or only some of
            them say which (they cannot be analysed together).
    """
    found = [_installed_of(rec, i) for i, rec in enumerate(recordings)]
    known = [f for f in found if f is not None]
    if not known:
        return None
    if len(known) != len(found) or any(f != known[0] for f in known[1:]):
        msg = (
            "the recordings were made with different installed factors (or only some say "
            "which): analyse each group separately, or give --installed"
        )
        raise CalibrationError(msg)
    return known[0]


# ----------------------------------------------------------------------------- estimation


@dataclass(frozen=True)
class FactorEstimate:
    """Total factors from some recordings, with uncertainties.

    Attributes:
        factors: the totals (what to install).
        sigma: factor field name → one-sigma uncertainty; ``inf`` for a factor not estimated
            (it keeps its installed value).
        installed: what the recordings ran with.
        method: how they were estimated.
        notes: moves that could not be used, observability warnings.
        hedge_offset_xy_m: the hedgehog offset used (joint: estimated when observable).
        held: factor field name → why the recordings do not support it (``not observable: …``,
            ``not separable: …``, ``inconsistent: …``); it keeps its installed value, σ ``inf``.
    """

    factors: CorrectionFactors
    sigma: Mapping[str, float]
    installed: CorrectionFactors
    method: EstimationMethod
    notes: tuple[str, ...] = ()
    hedge_offset_xy_m: tuple[float, float] = (0.0, 0.0)
    held: Mapping[str, str] = field(default_factory=dict)

    @property
    def estimated(self) -> tuple[str, ...]:
        """Field names of the factors the recordings determined (not held)."""
        return tuple(n for n in FACTOR_NAMES if n not in self.held)

    @property
    def residual(self) -> CorrectionFactors:
        """What the recordings measured on top of the installed factors."""
        scales = self.factors.scales / self.installed.scales
        cross = self.factors.crosstalks_rad_per_m - self.installed.crosstalks_rad_per_m
        return CorrectionFactors.from_vector([*scales, *cross])

    def uncertainty(self) -> CorrectionFactors:
        """σ as CorrectionFactors, NaN for a factor not estimated (``factors.yaml``'s layout)."""
        return CorrectionFactors(
            *(s if math.isfinite(s) else math.nan for s in (self.sigma[n] for n in FACTOR_NAMES))
        )


REFERENCE_SIGMA_M = 0.002
"""Default one-sigma noise of an external reference position, m (motion capture: ≈ 1 mm)."""
REFERENCE_RATE_HZ = 20.0
"""Rate (Hz) an external reference is thinned to for the joint estimate."""


@dataclass(frozen=True, eq=False)
class ExternalReference:
    """Positions of a point on the robot from an external system (motion capture), in place of
    the IPS fixes for the joint estimate.

    Attributes:
        t_ns: (N,) bag times, ns (the recording's clock).
        xy_m: (N, 2) positions in the system's own frame (the estimate aligns each recording).
        sigma_m: one-sigma noise per axis of a position, m.
        latency_s: delay from the motion to the sample's bag time, s.
        label: where it came from (a topic, a file), for notes.
    """

    t_ns: NDArray[np.int64]
    xy_m: NDArray[np.float64]
    sigma_m: float = REFERENCE_SIGMA_M
    latency_s: float = 0.0
    label: str = "reference"


def reference_fixes(reference: ExternalReference, rate_hz: float = REFERENCE_RATE_HZ) -> Fixes:
    """An external reference as fixes for the joint estimate (status ok, covariance σ² I).

    Samples closer than 0.9 / ``rate_hz`` to the previous one kept are left out.

    Raises:
        CalibrationError: shapes differ, a value is not finite, times do not increase, or σ
            is not positive.
    """
    t = np.asarray(reference.t_ns, dtype=np.int64).reshape(-1)
    xy = np.asarray(reference.xy_m, dtype=np.float64)
    if xy.shape != (t.size, 2):
        msg = f"{reference.label}: positions must be (N, 2) for N times, got {xy.shape}"
        raise CalibrationError(msg)
    if not np.all(np.isfinite(xy)) or np.any(np.diff(t) <= 0):
        msg = f"{reference.label}: positions must be finite and their times increasing"
        raise CalibrationError(msg)
    if not (math.isfinite(reference.sigma_m) and reference.sigma_m > 0.0):
        msg = f"{reference.label}: σ must be positive, got {reference.sigma_m}"
        raise CalibrationError(msg)
    keep = np.zeros(t.size, dtype=bool)
    step = round(0.9e9 / rate_hz) if rate_hz > 0 else 0  # 10 %: clock jitter keeps the pick
    last = None
    for i, ti in enumerate(t.tolist()):  # a greedy pass: keeps gaps, thins bursts
        if last is None or ti - last >= step:
            keep[i], last = True, ti
    return fixes_from_positions(t[keep], xy[keep], reference.sigma_m, "reference")


def estimate_factors(
    recordings: Sequence[Recording],
    *,
    installed: CorrectionFactors | None = None,
    method: EstimationMethod = "procedures",
    hedge_offset_m: Sequence[float] | None = None,
    beacons: BeaconMap | None = None,
    references: Sequence[ExternalReference] | None = None,
    odom_yaw_deadband_radps: float = ODOM_YAW_DEADBAND_RADPS,
) -> FactorEstimate:
    """The seven factors from recordings that share their installed factors.

    Args:
        recordings: one or more runs (``/cmd_vel``, ``/odom``, Marvelmind raw distances).
        installed: the factors they ran with (default: their ``installed_factors`` events,
            else identity).
        method: ``procedures`` (:func:`~omnical.calibration.procedures.analysis.analyse_procedures`) or
            ``joint`` (:func:`~omnical.calibration.joint.estimate.estimate_joint`).
        hedge_offset_m: the hedgehog in base_link (x, y[, z]); the robot description's.
        beacons: beacon map (default: each recording's own).
        references: one external reference per recording, in place of the IPS (joint only;
            the tracked point's offset starts at zero, the latency is the reference's own).
        odom_yaw_deadband_radps: odometry yaw rates up to this are no rotation (the robot's
            :func:`~omnical.calibration.procedures.tracks.yaw_deadband_radps`).

    Returns:
        The totals with their uncertainties; a factor the recordings do not support keeps its
        installed value, σ ``inf``, and is listed in ``held`` with the reason.

    Raises:
        CalibrationError: nothing to estimate from, mixed installed factors, a failed
            analysis (missing topics, no usable move), or no factor determined at all.
        RecordingError: a recording lacks a topic the joint estimate needs.
    """
    if not recordings:
        msg = "no recordings to estimate the factors from"
        raise CalibrationError(msg)
    if installed is None:
        installed = installed_from_recordings(recordings) or CorrectionFactors()
    if references is not None:
        return _estimate_against_references(
            recordings, installed, method, references, beacons, odom_yaw_deadband_radps
        )
    offset = hedge_offset_xy(hedge_offset_m)
    offset_xy = (float(offset[0]), float(offset[1]))
    if parse_choice(MethodChoice, method, "estimation method") is MethodChoice.PROCEDURES:
        est = analyse_procedures(
            list(recordings),
            installed,
            hedge_offset_m=offset_xy,
            beacons=beacons,
            odom_yaw_deadband_radps=odom_yaw_deadband_radps,
        )
        held = {
            n: est.held.get(n, "not observable: not measured")
            for n in FACTOR_NAMES
            if n in est.held or not math.isfinite(est.sigma[n])
        }
        return _supported(
            FactorEstimate(
                est.factors,
                dict(est.sigma),
                installed,
                "procedures",
                est.notes,
                offset_xy,
                held,
            )
        )
    if beacons is not None:
        msg = "the joint estimate reads the beacon map from the recordings; drop --beacons"
        raise CalibrationError(msg)
    return _joint_factors(
        recordings,
        installed,
        lambda j: (
            *j.warnings,
            _latency_note(j.latency_s, j.sigma.get("latency_s"), j.latency_from_fixes),
        ),
        hedge_offset_m=offset_xy,
        estimate_latency=sum(r.duration_s for r in recordings) >= LATENCY_ESTIMATED_FROM_S,
        odom_yaw_deadband_radps=odom_yaw_deadband_radps,
    )


def _joint_factors(
    recordings: Sequence[Recording],
    installed: CorrectionFactors,
    notes: Callable[[JointEstimate], tuple[str, ...]],
    **options: Any,
) -> FactorEstimate:
    """:func:`~omnical.calibration.joint.estimate.estimate_joint` with ``options``, as a
    :class:`FactorEstimate` whose notes are ``notes`` of it (its warnings among them)."""
    from omnical.calibration.joint.estimate import (  # a slow import
        ObservabilityWarning,
        estimate_joint,
    )

    with warnings.catch_warnings():  # they are in joint.warnings, reported as notes
        warnings.simplefilter("ignore", ObservabilityWarning)
        joint = estimate_joint(list(recordings), installed=installed, **options)
    sigma = {n: joint.sigma[n] if math.isfinite(joint.sigma[n]) else math.inf for n in FACTOR_NAMES}
    held = {
        n: joint.held_reasons.get(n, "not observable")
        for n in FACTOR_NAMES
        if n in joint.held or not math.isfinite(sigma[n])
    }
    return _supported(
        FactorEstimate(
            joint.factors, sigma, installed, "joint", notes(joint), joint.hedge_offset_m, held
        )
    )


LATENCY_ESTIMATED_FROM_S = 600.0
"""Recordings this long in total (s) have the joint estimate find the IPS latency too."""


def _latency_note(
    latency_s: float, sigma_s: float | None, preferred: tuple[float, float] | None
) -> str:
    """One line on the IPS latency: estimated (with its σ), or held and what the fixes prefer."""
    if preferred is None:
        if sigma_s is None or not math.isfinite(sigma_s):
            return f"IPS latency held at {latency_s * 1e3:.0f} ms (not observable in these runs)"
        return f"IPS latency estimated: {latency_s * 1e3:.1f} ± {sigma_s * 1e3:.1f} ms"
    value, sd_s = preferred
    return (
        f"IPS latency held at {latency_s * 1e3:.0f} ms (the fixes prefer {value * 1e3:.1f} ± "
        f"{sd_s * 1e3:.1f} ms; the factors' σ include the difference; recordings of "
        f"{LATENCY_ESTIMATED_FROM_S / 60:.0f} minutes or more estimate it)"
    )


def _estimate_against_references(
    recordings: Sequence[Recording],
    installed: CorrectionFactors,
    method: EstimationMethod,
    references: Sequence[ExternalReference],
    beacons: BeaconMap | None,
    odom_yaw_deadband_radps: float,
) -> FactorEstimate:
    """The joint estimate with an external reference per recording instead of the IPS."""
    if parse_choice(MethodChoice, method, "estimation method") is not MethodChoice.JOINT:
        msg = (
            "the procedures analysis measures each move with the IPS; calibrate against an "
            "external reference with the joint method"
        )
        raise CalibrationError(msg)
    if beacons is not None:
        msg = "an external reference needs no beacon map; drop --beacons"
        raise CalibrationError(msg)
    if len(references) != len(recordings):
        msg = f"got {len(references)} references for {len(recordings)} recordings"
        raise CalibrationError(msg)
    latencies = {r.latency_s for r in references}
    if len(latencies) != 1:
        msg = "the references of one estimate must share their latency"
        raise CalibrationError(msg)
    fixes = [reference_fixes(r) for r in references]
    labels = ", ".join(sorted({r.label for r in references}))
    used = sum(len(f) for f in fixes)
    first = (
        f"reference: {labels} ({used} positions used); the offset printed as the hedgehog's is "
        "the reference's tracked point in base_link"
    )
    return _joint_factors(
        recordings,
        installed,
        lambda j: (first, *j.warnings),
        fixes=fixes,
        latency_s=latencies.pop(),
        hedge_offset_m=(0.0, 0.0),
        odom_yaw_deadband_radps=odom_yaw_deadband_radps,
    )


def _supported(estimate: FactorEstimate) -> FactorEstimate:
    """The estimate if the recordings determined at least one factor.

    Raises:
        CalibrationError: every factor was held (one line with the reasons).
    """
    if estimate.estimated:
        return estimate
    reasons = "; ".join(f"{n}: {r}" for n, r in estimate.held.items())
    msg = f"the recordings determine no correction factor ({reasons})"
    raise CalibrationError(msg)


# ----------------------------------------------------------------------------- results


@dataclass(frozen=True)
class Iteration:
    """One pass of the flowchart.

    Attributes:
        index: 1, 2, ...
        installed: the factors installed at its start.
        rotation: the rotation procedure's estimate (run with ``installed``).
        translation: the translation procedures' estimate (run with the rotation corrected).
        factors: the totals of the iteration (installed for the next one).
        sigma: their one-sigma uncertainties (``inf``: not estimated).
        change: per factor, the change from ``installed`` (relative for scalings, rad/m).
        converged: every change was within the tolerance.
        recordings: names of its runs.
    """

    index: int
    installed: CorrectionFactors
    rotation: FactorEstimate
    translation: FactorEstimate
    factors: CorrectionFactors
    sigma: Mapping[str, float]
    change: Mapping[str, float]
    converged: bool
    recordings: tuple[str, ...]


@dataclass(frozen=True)
class Validation:
    """The procedures run once more with the final factors installed.

    Attributes:
        estimate: their analysis (installed = the final factors).
        recordings: names of the runs.
    """

    estimate: FactorEstimate
    recordings: tuple[str, ...]

    @property
    def residual(self) -> CorrectionFactors:
        """What is left to correct (identity when the calibration is right)."""
        return self.estimate.residual

    def z_scores(self) -> dict[str, float]:
        """Residual over its σ per factor (relative to 1 for the scalings); NaN if unmeasured."""
        res = self.residual
        out = {}
        for f in FACTORS:
            value = getattr(res, f.field) - f.neutral
            sigma = self.estimate.sigma[f.field]
            if f.is_scale and math.isfinite(sigma):
                sigma /= getattr(self.estimate.installed, f.field)
            out[f.field] = value / sigma if math.isfinite(sigma) and sigma > 0.0 else math.nan
        return out


@dataclass(frozen=True)
class CampaignResult:
    """Everything a campaign found and wrote.

    Attributes:
        robot_name: the robot description's name.
        factors: the final factors (installed after the last iteration).
        sigma: their one-sigma uncertainties (``inf``: not estimated).
        iterations: the passes of the flowchart.
        converged: the last iteration met the tolerance.
        tolerance: the tolerance used.
        method: the estimation method.
        initial: the factors installed before the campaign.
        validation: the validation run's analysis (None if skipped).
        measures_before: the paper's measures uncalibrated (twin only, else None).
        measures_after: the same calibrated.
        truth: the twin's true factors when known.
        robot_time_s: robot time of all runs, s.
        wall_time_s: wall time of the campaign, s.
        seed: the campaign seed.
        runs: every recording by run name (``iter1-rotation`` … ``validation-lateral``,
            ``measure-before-turns`` …), each stamped with the factors it ran with.
    """

    robot_name: str
    factors: CorrectionFactors
    sigma: Mapping[str, float]
    iterations: tuple[Iteration, ...]
    converged: bool
    tolerance: Tolerance
    method: EstimationMethod
    initial: CorrectionFactors
    validation: Validation | None
    measures_before: Measures | None
    measures_after: Measures | None
    truth: CorrectionFactors | None
    robot_time_s: float
    wall_time_s: float
    seed: int = 0
    runs: Mapping[str, Recording] = field(default_factory=dict)

    @property
    def procedure_runs(self) -> dict[str, Recording]:
        """The iteration and validation runs (not the measures), for the offline analysis."""
        return {name: rec for name, rec in self.runs.items() if not name.startswith("measure-")}

    def uncertainty(self) -> CorrectionFactors:
        """σ as CorrectionFactors, NaN for a factor not estimated."""
        return CorrectionFactors(
            *(s if math.isfinite(s) else math.nan for s in (self.sigma[n] for n in FACTOR_NAMES))
        )


# ----------------------------------------------------------------------------- the campaign


class _Session:
    """Runs and bookkeeping of one campaign (mutable, private to :func:`run_campaign`)."""

    def __init__(
        self,
        robot: RobotDescription,
        bench: Bench,
        on_progress: ProgressFn | None,
        method: EstimationMethod,
        beacons: BeaconMap | None,
        procedures: Mapping[str, Mapping[str, Any]] | None = None,
    ) -> None:
        self.procedures = procedures or {}
        self.robot = robot
        self.bench = bench
        self.on_progress = on_progress
        self.method: EstimationMethod = method
        self.beacons = beacons
        self.runs: dict[str, Recording] = {}
        self.robot_time_s = 0.0

    def procedure(self, kind: str) -> dict[str, Any]:
        """The script of the ``rotation``, ``longitudinal`` or ``lateral`` procedure, sized by
        the campaign's ``procedures`` options."""
        make: dict[str, Callable[..., dict[str, Any]]] = {
            "rotation": rotation_procedure,
            "longitudinal": longitudinal_procedure,
            "lateral": lateral_procedure,
        }
        try:
            return make[kind](**dict(self.procedures.get(kind, {})))
        except TypeError as err:  # an option the procedure does not take
            raise ConfigError(f"{kind} procedure: {err}") from None

    def report(self, step: str, done_s: float = 0.0, total_s: float = 0.0) -> None:
        if self.on_progress is not None:
            self.on_progress(CampaignProgress(step, done_s, total_s))

    def run(
        self, data: Mapping[str, object], installed: CorrectionFactors, name: str, step: str
    ) -> Recording:
        script = parse_script(dict(data), self.robot.limits)
        total = float(script.duration_s) + 2.0
        self.report(step, 0.0, total)

        def tick(done_s: float, _total_s: float) -> None:
            self.report(step, done_s, total)

        recording = self.bench.run(script, installed, name=name, on_tick=tick)
        self.report(step, total, total)
        recording = with_installed_event(recording, installed)
        self.runs[name] = recording
        self.robot_time_s += recording.duration_s
        return recording

    def estimate(
        self, recordings: Sequence[Recording], installed: CorrectionFactors, step: str
    ) -> FactorEstimate:
        self.report(step)
        return estimate_factors(
            recordings,
            installed=installed,
            method=self.method,
            hedge_offset_m=self.robot.hedge_offset_m,
            beacons=self.beacons,
            odom_yaw_deadband_radps=yaw_deadband_radps(self.robot.odom_yaw_resolution_radps),
        )


def _iteration(
    session: _Session, index: int, installed: CorrectionFactors, tolerance: Tolerance
) -> Iteration:
    label = f"iteration {index}"
    rot_name, lon_name, lat_name = (
        f"iter{index}-{p}" for p in ("rotation", "longitudinal", "lateral")
    )
    rot_rec = session.run(
        session.procedure("rotation"), installed, rot_name, f"{label}: rotation procedure"
    )
    rotation = session.estimate([rot_rec], installed, f"{label}: rotation analysis")
    scale_rot = rotation.factors.scale_rotational
    if not math.isfinite(rotation.sigma["scale_rotational"]):
        scale_rot = installed.scale_rotational
    corrected = installed.with_values(scale_rotational=scale_rot)
    lon_rec = session.run(
        session.procedure("longitudinal"), corrected, lon_name, f"{label}: longitudinal procedure"
    )
    lat_rec = session.run(
        session.procedure("lateral"), corrected, lat_name, f"{label}: lateral procedure"
    )
    translation = session.estimate([lon_rec, lat_rec], corrected, f"{label}: translation analysis")
    sigma = dict(translation.sigma)
    for name in _ROTATION_STAGE:
        sigma[name] = rotation.sigma[name]
    totals = translation.factors.with_values(scale_rotational=scale_rot)
    return Iteration(
        index=index,
        installed=installed,
        rotation=rotation,
        translation=translation,
        factors=totals,
        sigma=sigma,
        change=tolerance.changes(installed, totals),
        converged=tolerance.met(installed, totals),
        recordings=(rot_name, lon_name, lat_name),
    )


def _validation(session: _Session, final: CorrectionFactors) -> Validation:
    names = ("validation-rotation", "validation-longitudinal", "validation-lateral")
    scripts = tuple(session.procedure(k) for k in ("rotation", "longitudinal", "lateral"))
    recs = [
        session.run(data, final, name, f"validation: {name.split('-')[1]} procedure")
        for name, data in zip(names, scripts, strict=True)
    ]
    return Validation(session.estimate(recs, final, "validation: analysis"), names)


def _measures(session: _Session, installed: CorrectionFactors, when: str) -> Measures:
    scripts = measure_scripts()
    recs = {
        key: session.run(data, installed, f"measure-{when}-{key}", f"measures {when}: {key}")
        for key, data in scripts.items()
    }
    return measures_from_recordings(recs["turns"], recs["longitudinal"], recs["lateral"])


def _check_options(max_iterations: int, method: str) -> None:
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, int):
        msg = f"max_iterations must be an integer ≥ 1, got {max_iterations!r}"
        raise ConfigError(msg)
    if max_iterations < 1:
        msg = f"max_iterations must be an integer ≥ 1, got {max_iterations}"
        raise ConfigError(msg)
    parse_choice(MethodChoice, method, "estimation method")


def run_campaign(
    robot: RobotDescription,
    bench: Bench,
    *,
    seed: int = 0,
    tolerance: Tolerance = Tolerance(),
    max_iterations: int = 4,
    on_progress: ProgressFn | None = None,
    method: EstimationMethod = "procedures",
    installed: CorrectionFactors | None = None,
    beacons: BeaconMap | None = None,
    validate: bool = True,
    measure: bool = True,
    truth: CorrectionFactors | None = None,
    procedures: Mapping[str, Mapping[str, Any]] | None = None,
    on_iteration: Callable[[Iteration], None] | None = None,
) -> CampaignResult:
    """Run the calibration flowchart of seed 000 Figure 7 on ``bench`` (docs/DESIGN-NOTES.md).

    Args:
        robot: the robot description (limits for the scripts, hedgehog offset).
        bench: the robot to run on (the twin: :class:`omnical.twin.bench.TwinBench`).
        seed: campaign seed, recorded in the result (a twin bench derives its runs' seeds).
        tolerance: when to stop iterating.
        max_iterations: most iterations.
        on_progress: receives a :class:`CampaignProgress` at every step and tick.
        method: ``procedures`` (seed 000) or ``joint`` estimation of each stage.
        installed: the factors installed before the campaign (default: identity).
        beacons: beacon map (default: each recording's ``/beacons_pos_a``).
        validate: run and analyse the validation procedures.
        measure: run the before/after measures (needs ``/ground_truth``: twin only).
        truth: the robot's true factors when known (a twin), for the report.
        procedures: keyword options of the procedures' scripts by ``rotation``,
            ``longitudinal``, ``lateral`` (sizes: ``distance_m``, ``turns``, ``repeats`` ...;
            default: seed 000's).
        on_iteration: receives each iteration as it ends (a live view of the factors).

    Returns:
        The final factors, the iterations, the validation, the measures and every recording.

    Raises:
        ConfigError: bad options.
        CalibrationError: a procedure could not be analysed.
    """
    t_start = time.perf_counter()
    _check_options(max_iterations, method)
    initial = installed if installed is not None else CorrectionFactors()
    session = _Session(robot, bench, on_progress, method, beacons, procedures)

    iterations: list[Iteration] = []
    current = initial
    for index in range(1, max_iterations + 1):
        it = _iteration(session, index, current, tolerance)
        iterations.append(it)
        if on_iteration is not None:
            on_iteration(it)
        current = it.factors
        if it.converged:
            break
    last = iterations[-1]
    validation = _validation(session, current) if validate else None
    before = after = None
    if measure:
        before = _measures(session, initial, "before")
        after = _measures(session, current, "after")
    return CampaignResult(
        robot_name=robot.name,
        factors=current,
        sigma=dict(last.sigma),
        iterations=tuple(iterations),
        converged=last.converged,
        tolerance=tolerance,
        method=method,
        initial=initial,
        validation=validation,
        measures_before=before,
        measures_after=after,
        truth=truth,
        robot_time_s=session.robot_time_s,
        wall_time_s=time.perf_counter() - t_start,
        seed=seed,
        runs=dict(session.runs),
    )
