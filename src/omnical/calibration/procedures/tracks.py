"""What the procedure analyses read from a recording: segments, stand-stills, IPS arcs, odometry.

``/cmd_vel``, ``/odom`` and the Marvelmind topics only: robust stand-still averages, an arc per
translation (:func:`move_arcs`, hedgehog offset corrected), odometry yaw below resolution dropped.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.calibration.procedures.geometry import (
    CircleFit,
    MeanPosition,
    arc_length,
    fit_circle,
    mean_position,
)
from omnical.calibration.procedures.segments import Segment, segment_commands, segment_mask, settled
from omnical.errors import CalibrationError, GeometryError
from omnical.estimation.se2 import rotate_xy
from omnical.ips.beacons import BeaconMap
from omnical.ips.from_recording import locate
from omnical.recording.recording import Recording
from omnical.recording.topics import BEACON_RAW_DISTANCE, CMD_VEL, ODOM

__all__ = [
    "BODY_DIRECTIONS",
    "Estimate",
    "MoveArc",
    "ProcedureTracks",
    "SlipPrior",
    "StandStill",
    "TranslationKind",
    "as_recordings",
    "body_arc_from_hedge",
    "combine_estimates",
    "hedge_offset_xy",
    "move_arcs",
    "procedure_tracks",
    "resolved_odometry",
    "tracks_and_arcs",
    "yaw_deadband_radps",
]

TranslationKind = Literal["forward", "reverse", "left", "right"]
"""Direction of a pure translation."""

BODY_DIRECTIONS: dict[TranslationKind, tuple[float, float]] = {
    "forward": (1.0, 0.0),
    "reverse": (-1.0, 0.0),
    "left": (0.0, 1.0),
    "right": (0.0, -1.0),
}
"""Unit direction of travel in base_link of each translation."""

_Array = NDArray[np.float64]
_NS_PER_S = 1_000_000_000

RATE_WINDOW_S = 1.0
"""The odometry's yaw rate is judged over this long a window centred on each step, s."""

ODOM_YAW_DEADBAND_RADPS = 1.5e-3
"""Largest odometry yaw rate (rad/s) taken as no rotation (docs/DESIGN-NOTES.md): above the ±1
mrad/s flicker of the vehicle controller's status frames, far below any real turn: the dead
band of a robot whose odometry resolves 1 mrad/s (:func:`yaw_deadband_radps`)."""


def yaw_deadband_radps(resolution_radps: float) -> float:
    """The dead band for odometry that reports yaw rates in steps of ``resolution_radps``
    (a robot description's ``odom_yaw_resolution_radps``): 1.5 steps, 0 for none."""
    return 1.5 * resolution_radps


@dataclass(frozen=True)
class Estimate:
    """A measured quantity with its one-sigma uncertainty.

    Attributes:
        value: the estimate.
        sigma: one-sigma standard uncertainty (``inf`` when not measured).
        n: number of independent measurements combined.
    """

    value: float
    sigma: float
    n: int = 1


@dataclass(frozen=True)
class SlipPrior:
    """Random wheel slip the IPS cannot see, as a prior on what each move measures.

    Relative speed errors of σ ``fraction`` and a random yaw of σ ``crosstalk_rad_per_m`` per
    metre, correlated over τ = ``correlation_s`` (Ornstein–Uhlenbeck, as in the twin). Over a
    move of duration T: a scaling error ``fraction``·√(2τ/T), added in quadrature to every
    scaling's σ, and a heading change ``crosstalk_rad_per_m``·L·√(2τ/T) over length L, carried
    by the heading solution as process noise. ``SlipPrior(0.0, 0.0)`` leaves both out.

    Attributes:
        fraction: relative σ of the speed slip (≥ 0).
        crosstalk_rad_per_m: σ of the random yaw per metre (≥ 0).
        correlation_s: correlation time τ (> 0).
    """

    fraction: float = 0.003
    crosstalk_rad_per_m: float = 3e-4
    correlation_s: float = 0.5

    def __post_init__(self) -> None:
        for name in ("fraction", "crosstalk_rad_per_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                msg = f"slip {name} must be ≥ 0, got {value}"
                raise CalibrationError(msg)
        if not (math.isfinite(self.correlation_s) and self.correlation_s > 0.0):
            msg = f"slip correlation_s must be > 0, got {self.correlation_s}"
            raise CalibrationError(msg)

    def _averaging(self, duration_s: float) -> float:
        if duration_s <= 0.0:
            return 1.0
        return min(1.0, math.sqrt(2.0 * self.correlation_s / duration_s))

    def relative_sigma(self, duration_s: float) -> float:
        """Relative σ of a move's scaling from slip, for a move of ``duration_s``."""
        return self.fraction * self._averaging(duration_s)

    def heading_sigma_rad(self, length_m: float, duration_s: float) -> float:
        """σ of the random heading change over a translation of ``length_m`` in ``duration_s``."""
        return self.crosstalk_rad_per_m * abs(length_m) * self._averaging(duration_s)


def combine_estimates(values: ArrayLike, sigmas: ArrayLike) -> Estimate:
    """Inverse-variance weighted mean, its σ inflated by the Birge ratio when the scatter is larger.

    Args:
        values: (n,) measurements.
        sigmas: (n,) their one-sigma uncertainties (> 0).

    Returns:
        The combined estimate; σ = max(1, √(χ²/(n − 1))) / √(Σ 1/σ²).

    Raises:
        CalibrationError: nothing to combine, shapes differ, or a σ is not > 0.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    s = np.asarray(sigmas, dtype=np.float64).ravel()
    if v.size == 0 or v.shape != s.shape:
        msg = f"need as many values as sigmas (≥ 1), got {v.size} and {s.size}"
        raise CalibrationError(msg)
    if not (np.all(np.isfinite(v)) and np.all(s > 0.0)):
        msg = "values must be finite and sigmas > 0 to combine"
        raise CalibrationError(msg)
    finite = np.isfinite(s)
    if not np.any(finite):  # nothing has a known uncertainty
        return Estimate(float(np.mean(v)), math.inf, int(v.size))
    v, s = v[finite], s[finite]
    w = 1.0 / s**2
    mean = float(np.sum(w * v) / np.sum(w))
    sigma = float(1.0 / np.sqrt(np.sum(w)))
    if v.size > 1:
        chi2 = float(np.sum(w * (v - mean) ** 2))
        sigma *= max(1.0, math.sqrt(chi2 / (v.size - 1)))
    return Estimate(mean, sigma, int(v.size))


@dataclass(frozen=True)
class StandStill:
    """A settled stand-still: averaged IPS position and odometry pose.

    Attributes:
        index: position of the segment in :attr:`ProcedureTracks.segments`.
        t_start_s: start of the averaging window (the segment start + ``settle_s``), s.
        t_end_s: end of the window (the end of the stand-still), s.
        ips: robust mean of the ``ok`` fixes in the window (map frame, hedgehog position).
        odom_pose: (3,) mean odometry pose x m, y m, yaw rad (yaw unwrapped over the run).
    """

    index: int
    t_start_s: float
    t_end_s: float
    ips: MeanPosition
    odom_pose: _Array


@dataclass(frozen=True)
class ProcedureTracks:
    """A recording reduced to what the analyses use; times in s from ``t0_ns``.

    Attributes:
        t0_ns: time origin (the first ``/cmd_vel`` sample), bag ns.
        segments: stand-stills and moves from ``/cmd_vel``.
        stills: the usable stand-stills by segment index (settled, with enough fixes).
        fix_t_s: (N,) times of the ``ok`` IPS fixes.
        fix_xy_m: (N, 2) their map positions (hedgehog).
        odom_t_s: (M,) odometry times.
        odom_pose: (M, 3) odometry x, y, unwrapped yaw.
        settle_s: time dropped at the start of each stand-still.
    """

    t0_ns: int
    segments: tuple[Segment, ...]
    stills: Mapping[int, StandStill]
    fix_t_s: _Array
    fix_xy_m: _Array
    odom_t_s: _Array
    odom_pose: _Array
    settle_s: float


def _require(recording: Recording, topic: str) -> None:
    if not recording.has(topic):
        msg = f"recording has no {topic} messages: the procedure analysis needs it"
        raise CalibrationError(msg)


def procedure_tracks(
    recording: Recording,
    *,
    beacons: BeaconMap | None = None,
    settle_s: float = 1.0,
    min_still_fixes: int = 10,
    odom_yaw_deadband_radps: float = ODOM_YAW_DEADBAND_RADPS,
) -> ProcedureTracks:
    """Segment a recording and attach its IPS fixes and odometry.

    Args:
        recording: a run with ``/cmd_vel``, ``/odom`` and ``/beacon_raw_distance`` (and
            ``/beacons_pos_a`` unless ``beacons`` is given).
        beacons: beacon map to multilaterate against (default: the recording's own).
        settle_s: time dropped at the start of each stand-still before averaging.
        min_still_fixes: fewest ``ok`` fixes a stand-still needs to be used.
        odom_yaw_deadband_radps: odometry yaw rates up to this are taken as no rotation
            (:func:`resolved_odometry`; 0 keeps the odometry as recorded).

    Returns:
        The tracks; stand-stills too short to settle or with too few fixes are left out of
        :attr:`ProcedureTracks.stills`.

    Raises:
        CalibrationError: a topic is missing, or no stand-still is usable.
    """
    for topic in (CMD_VEL, ODOM, BEACON_RAW_DISTANCE):
        _require(recording, topic)
    cmd = recording.topic(CMD_VEL)
    t0 = int(cmd.t_ns[0])
    segments = tuple(segment_commands(cmd.t_s(t0), cmd["vx_mps"], cmd["vy_mps"], cmd["wz_radps"]))
    fixes, _ = locate(recording, beacons=beacons)
    if fixes.t_ns is None:  # pragma: no cover - locate stamps every fix from the recording
        msg = "the fixes carry no times"
        raise CalibrationError(msg)
    ok = fixes.ok & np.all(np.isfinite(fixes.positions_map_m[:, :2]), axis=1)
    fix_t = (fixes.t_ns[ok] - np.int64(t0)).astype(np.float64) / _NS_PER_S
    fix_xy = np.asarray(fixes.positions_map_m[ok, :2], dtype=np.float64)
    odom = recording.topic(ODOM)
    odom_t = odom.t_s(t0)
    odom_pose = resolved_odometry(
        odom_t,
        np.column_stack(
            [odom["x_m"], odom["y_m"], np.unwrap(np.asarray(odom["yaw_rad"], dtype=np.float64))]
        ).astype(np.float64),
        odom_yaw_deadband_radps,
    )
    stills: dict[int, StandStill] = {}
    for i, seg in enumerate(segments):
        if seg.kind != "still" or seg.duration_s <= settle_s:
            continue
        window = settled(seg, settle_s)
        in_fix = segment_mask(fix_t, window)
        in_odom = segment_mask(odom_t, window)
        if np.count_nonzero(in_fix) < min_still_fixes or not np.any(in_odom):
            continue
        stills[i] = StandStill(
            i,
            window.t_start_s,
            window.t_end_s,
            mean_position(fix_xy[in_fix]),
            odom_pose[in_odom].mean(axis=0),
        )
    if not stills:
        msg = (
            f"no usable stand-still in the recording (each needs > {settle_s} s and "
            f"{min_still_fixes} ok IPS fixes after settling)"
        )
        raise CalibrationError(msg)
    return ProcedureTracks(t0, segments, stills, fix_t, fix_xy, odom_t, odom_pose, settle_s)


def resolved_odometry(t_s: ArrayLike, pose: ArrayLike, deadband_radps: float) -> _Array:
    """The odometry with its unresolved yaw taken out (docs/DESIGN-NOTES.md).

    Each step keeps its body-frame translation, and its yaw change only when the yaw rate over
    :data:`RATE_WINDOW_S` centred on it exceeds ``deadband_radps``; the poses are integrated
    again from the first. Samples sharing one time keep their yaw change.

    Args:
        t_s: (M,) odometry times, s, non-decreasing.
        pose: (M, 3) x m, y m, yaw rad (unwrapped).
        deadband_radps: largest |yaw rate| taken as no rotation, rad/s (≥ 0; 0: unchanged).

    Returns:
        (M, 3) the poses again.

    Raises:
        CalibrationError: a negative or non-finite dead band, or shapes that do not match.
    """
    if not (math.isfinite(deadband_radps) and deadband_radps >= 0.0):
        msg = f"odom_yaw_deadband_radps must be ≥ 0, got {deadband_radps}"
        raise CalibrationError(msg)
    t = np.asarray(t_s, dtype=np.float64)
    p = np.array(pose, dtype=np.float64)
    if p.ndim != 2 or p.shape != (len(t), 3):
        msg = f"odometry times {t.shape} and poses {p.shape} do not match"
        raise CalibrationError(msg)
    if deadband_radps == 0.0 or len(t) < 2:
        return p
    dt = np.diff(t)
    dyaw = np.diff(p[:, 2])
    body = rotate_xy(-(p[:-1, 2] + 0.5 * dyaw), np.diff(p[:, :2], axis=0))
    # the rate over a second centred on each step: the status frames' flicker averages out
    mid_s = 0.5 * (t[:-1] + t[1:])
    lo_s = np.maximum(mid_s - 0.5 * RATE_WINDOW_S, t[0])
    hi_s = np.minimum(mid_s + 0.5 * RATE_WINDOW_S, t[-1])
    span_s = hi_s - lo_s
    turned = np.interp(hi_s, t, p[:, 2]) - np.interp(lo_s, t, p[:, 2])
    slow = np.abs(turned) <= deadband_radps * np.where(span_s > 0.0, span_s, np.inf)
    dyaw = np.where((dt > 0.0) & (span_s > 0.0) & slow, 0.0, dyaw)
    yaw = p[0, 2] + np.concatenate([[0.0], np.cumsum(dyaw)])
    steps = rotate_xy(yaw[:-1] + 0.5 * dyaw, body)
    xy = p[0, :2] + np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])
    return np.column_stack([xy, yaw])


def _hedge_ratio(kappa: float, u: _Array, o: _Array) -> float:
    """|κ·o − J·u|: hedgehog arc length per metre of the centre's arc."""
    ju = np.array([-u[1], u[0]])
    return float(np.hypot(*(kappa * o - ju)))


def body_arc_from_hedge(
    curvature_hedge_per_m: float,
    direction_body: ArrayLike,
    hedge_offset_xy_m: ArrayLike,
) -> tuple[float, float, float]:
    """Turn the hedgehog's arc of a translation into the robot centre's (docs/DESIGN-NOTES.md).

    Args:
        curvature_hedge_per_m: signed curvature of the hedgehog's path (CCW +, along travel).
        direction_body: (2,) unit direction of travel in base_link.
        hedge_offset_xy_m: (2,) hedgehog position in base_link.

    Returns:
        (κ of the centre's path in rad/m, r = hedgehog length / centre length, δ = hedgehog
        tangent minus the centre's direction of travel in rad).
    """
    u = np.asarray(direction_body, dtype=np.float64)
    o = np.asarray(hedge_offset_xy_m, dtype=np.float64)
    kappa = curvature_hedge_per_m
    for _ in range(6):  # fixed point κ = κ_h·r(κ); r − 1 is O(κ|o|) ≈ 1e-3
        kappa = curvature_hedge_per_m * _hedge_ratio(kappa, u, o)
    ratio = _hedge_ratio(kappa, u, o)
    jo = np.array([-o[1], o[0]])
    delta = math.atan2(kappa * float(u @ o), 1.0 + kappa * float(u @ jo))
    return kappa, ratio, delta


@dataclass(frozen=True)
class MoveArc:
    """The IPS arc and odometry of one translation between two stand-stills (geometry only).

    Attributes:
        index: position of the move in :attr:`ProcedureTracks.segments`.
        kind: forward, reverse, left or right.
        segment: the move.
        before: the stand-still before it.
        after: the stand-still after it.
        fit: the arc fitted to the hedgehog's fixes (map frame).
        hedge_length_m: length along the fitted arc between the two stand-still averages.
        hedge_length_std_m: its σ from the stand-still averages.
        length_m: the robot centre's path length (hedge length / r).
        length_std_m: its σ.
        curvature_per_m: signed curvature of the centre's path = real yaw per metre (CCW +).
        curvature_std_per_m: its σ (from the fit).
        tangent_offset_rad: δ, hedgehog tangent minus direction of travel.
        odom_length_m: odometry path length between the stand-stills (from the chord and the
            odometry's own heading change, an exact arc).
        odom_yaw_change_rad: odometry yaw change between the stand-stills.
        n_fixes: number of fixes in the fit.
        start_xy_m: (2,) where the stand-still before sits on the straightened track (its IPS
            average less the odometry's off-track motion there; see :func:`move_arcs`).
        end_xy_m: (2,) the same for the stand-still after.
        off_track_yaw_rad: the odometry's heading change between the stand-stills, taken out
            of the track before the fit and added back to the heading at the end.
    """

    index: int
    kind: TranslationKind
    segment: Segment
    before: StandStill
    after: StandStill
    fit: CircleFit
    hedge_length_m: float
    hedge_length_std_m: float
    length_m: float
    length_std_m: float
    curvature_per_m: float
    curvature_std_per_m: float
    tangent_offset_rad: float
    odom_length_m: float
    odom_yaw_change_rad: float
    n_fixes: int
    start_xy_m: _Array
    end_xy_m: _Array
    off_track_yaw_rad: float = 0.0

    @property
    def direction_body(self) -> tuple[float, float]:
        """Unit direction of travel in base_link."""
        return BODY_DIRECTIONS[self.kind]

    def tangent_at(self, which: Literal["start", "end"]) -> tuple[float, float]:
        """Direction of the hedgehog's path (map frame) at a stand-still, with its σ.

        Args:
            which: ``"start"`` (the stand-still before) or ``"end"`` (the one after).

        Returns:
            (angle in rad, σ in rad): the fit's heading carried along the arc by κ·s.
        """
        point = self.start_xy_m if which == "start" else self.end_xy_m
        s = arc_length(self.fit, self.fit.point_xy_m, point)
        angle = self.fit.heading_rad + self.fit.curvature_per_m * s
        grad = np.array([0.0, 1.0, s])
        var = float(grad @ self.fit.covariance @ grad)
        return angle, math.sqrt(var) if var >= 0.0 else math.inf

    def body_heading_at(self, which: Literal["start", "end"]) -> tuple[float, float]:
        """Heading of base_link (map frame) at a stand-still, with its σ.

        The direction of travel is the hedgehog tangent − δ; the heading is that minus the
        direction of travel in base_link (0 forward, π reverse, ±π/2 left/right). At the end,
        the heading change the odometry saw (taken out of the straightened track) is added back.
        """
        tangent, sigma = self.tangent_at(which)
        u = self.direction_body
        heading = tangent - self.tangent_offset_rad - math.atan2(u[1], u[0])
        if which == "end":
            heading += self.off_track_yaw_rad
        return heading, sigma


def _odom_arc(before: StandStill, after: StandStill) -> tuple[float, float]:
    chord = float(np.hypot(*(after.odom_pose[:2] - before.odom_pose[:2])))
    phi = float(after.odom_pose[2] - before.odom_pose[2])
    return chord / float(np.sinc(phi / (2.0 * np.pi))), phi


def _along_sigma(still: StandStill, direction: _Array) -> float:
    return float(np.sqrt(np.sum((direction * still.ips.std_error_m) ** 2)))


@dataclass(frozen=True)
class _Straightening:
    """What the odometry says about a move beyond a pure arc (see :func:`move_arcs`)."""

    ratios: _Array  # (2,) real / odometry length of body x and y travel
    heading_rad: float  # body heading at the stand-still before (map frame), approximately
    curvature_per_m: float  # real yaw per metre, approximately


def off_track(
    tracks: ProcedureTracks,
    before: StandStill,
    after: StandStill,
    u: _Array,
    o: _Array,
    how: _Straightening,
) -> tuple[_Array, _Array]:
    """Map-frame hedgehog displacement that a pure arc along ``u`` would not make (from /odom).

    Returns:
        (K,) odometry times from the stand-still before to the one after, and (K, 2) the
        accumulated off-track displacement at those times (0 at the first).
    """
    m = (tracks.odom_t_s >= before.t_start_s) & (tracks.odom_t_s <= after.t_end_s)
    t, pose = tracks.odom_t_s[m], tracks.odom_pose[m]
    if len(t) < 2:
        return t, np.zeros((len(t), 2))
    dyaw = np.diff(pose[:, 2])
    step = rotate_xy(-(pose[:-1, 2] + 0.5 * dyaw), np.diff(pose[:, :2], axis=0)) * how.ratios
    along = step @ u
    psi = pose[:, 2] - before.odom_pose[2]
    s = np.concatenate([[0.0], np.cumsum(along)])
    theta = how.heading_rad + how.curvature_per_m * s
    theta_mid = theta[:-1] + 0.5 * how.curvature_per_m * along
    real = rotate_xy(theta_mid + psi[:-1] + 0.5 * dyaw, step)
    pure = rotate_xy(theta_mid, along[:, None] * u[None, :])
    off = np.vstack([np.zeros(2), np.cumsum(real - pure, axis=0)])
    lever = np.broadcast_to(o, (len(t), 2))
    off += rotate_xy(theta + psi, lever) - rotate_xy(theta, lever)
    return t, off


def _window_mean(t: _Array, values: _Array, still: StandStill) -> _Array:
    m = (t >= still.t_start_s) & (t <= still.t_end_s)
    return values[m].mean(axis=0) if np.any(m) else np.zeros(values.shape[1])


def _fit_move(
    tracks: ProcedureTracks,
    index: int,
    before: StandStill,
    after: StandStill,
    o: _Array,
    f_scale_m: float,
    how: _Straightening | None,
) -> MoveArc | str:
    """Fit one move (straightened by the odometry when ``how`` is given); a note on failure."""
    seg = tracks.segments[index]
    kind: TranslationKind = seg.kind  # type: ignore[assignment]
    u = np.array(BODY_DIRECTIONS[kind])
    inside = (tracks.fix_t_s >= before.t_start_s) & (tracks.fix_t_s <= after.t_end_s)
    xy = tracks.fix_xy_m[inside]
    start, end = before.ips.mean_xy_m, after.ips.mean_xy_m
    odom_len, odom_phi = _odom_arc(before, after)
    off_yaw = 0.0
    if how is not None:
        t_off, off = off_track(tracks, before, after, u, o, how)
        if len(t_off) >= 2:
            shift = np.column_stack(
                [np.interp(tracks.fix_t_s[inside], t_off, off[:, k]) for k in (0, 1)]
            )
            xy = xy - shift
            start = start - _window_mean(t_off, off, before)
            end = end - _window_mean(t_off, off, after)
            off_yaw = odom_phi
    try:
        fit = fit_circle(xy, loss="cauchy", f_scale_m=f_scale_m)
        hedge_len = arc_length(fit, start, end)
    except GeometryError as err:
        return f"arc fit failed ({err})"
    if not (hedge_len > 0.0 and odom_len > 0.0):
        return f"no displacement (IPS {hedge_len:.3f} m, odometry {odom_len:.3f} m)"
    kappa, ratio, delta = body_arc_from_hedge(fit.curvature_per_m, u, o)
    chord = end - start
    t_hat = chord / max(float(np.hypot(*chord)), 1e-12)
    hedge_std = math.hypot(_along_sigma(before, t_hat), _along_sigma(after, t_hat))
    length = hedge_len / ratio
    return MoveArc(
        index=index,
        kind=kind,
        segment=seg,
        before=before,
        after=after,
        fit=fit,
        hedge_length_m=hedge_len,
        hedge_length_std_m=hedge_std,
        length_m=length,
        length_std_m=hedge_std / ratio,
        curvature_per_m=kappa + off_yaw / length,
        curvature_std_per_m=fit.curvature_std_per_m * ratio,
        tangent_offset_rad=delta,
        odom_length_m=odom_len,
        odom_yaw_change_rad=odom_phi,
        n_fixes=int(np.count_nonzero(inside)),
        start_xy_m=np.asarray(start, dtype=np.float64),
        end_xy_m=np.asarray(end, dtype=np.float64),
        off_track_yaw_rad=off_yaw,
    )


def _length_ratios(arcs: Sequence[MoveArc]) -> _Array:
    """Real / odometry length of body x and y travel from the arcs (1 where none)."""
    ratios = np.ones(2)
    for axis, kinds in enumerate((("forward", "reverse"), ("left", "right"))):
        r = [a.length_m / a.odom_length_m for a in arcs if a.kind in kinds]
        if r:
            ratios[axis] = float(np.median(r))
    return ratios


def move_arcs(
    tracks: ProcedureTracks,
    *,
    hedge_offset_xy_m: ArrayLike = (0.0, 0.0),
    min_fixes: int = 20,
    f_scale_m: float = 0.05,
    straighten: bool = True,
) -> tuple[list[MoveArc], list[str]]:
    """Fit every pure translation that has a usable stand-still right before and after it.

    With ``straighten`` (default) the odometry's motion off the first fit's arc (scaled by its
    length ratios, lever arm included) is taken out of the fixes and stand-still averages, the
    arc refitted, and the odometry's yaw change added back to the heading at the end.

    Args:
        tracks: from :func:`procedure_tracks`.
        hedge_offset_xy_m: (2,) hedgehog position in base_link (corrects length and curvature).
        min_fixes: fewest fixes (stand-stills included) an arc fit needs.
        f_scale_m: residual beyond which the Cauchy loss discounts a fix.
        straighten: take the odometry's off-track motion out before the fit.

    Returns:
        The arcs in time order, and a note per translation that could not be used.
    """
    o = np.asarray(hedge_offset_xy_m, dtype=np.float64).ravel()[:2]
    notes: list[str] = []
    moves: list[tuple[int, StandStill, StandStill]] = []
    for i, seg in enumerate(tracks.segments):
        if seg.kind not in BODY_DIRECTIONS:
            continue
        before, after = tracks.stills.get(i - 1), tracks.stills.get(i + 1)
        where = f"{seg.kind} move at {seg.t_start_s:.2f}–{seg.t_end_s:.2f} s"
        if before is None or after is None:
            notes.append(f"{where}: no usable stand-still on both sides")
            continue
        inside = (tracks.fix_t_s >= before.t_start_s) & (tracks.fix_t_s <= after.t_end_s)
        n = int(np.count_nonzero(inside))
        if n < min_fixes:
            notes.append(f"{where}: only {n} ok IPS fixes")
            continue
        moves.append((i, before, after))
    raw: list[MoveArc] = []
    for i, before, after in moves:
        fitted = _fit_move(tracks, i, before, after, o, f_scale_m, None)
        if isinstance(fitted, str):
            seg = tracks.segments[i]
            notes.append(f"{seg.kind} move at {seg.t_start_s:.2f}–{seg.t_end_s:.2f} s: {fitted}")
        else:
            raw.append(fitted)
    if not straighten:
        return raw, notes
    ratios = _length_ratios(raw)
    arcs: list[MoveArc] = []
    for arc in raw:
        how = _Straightening(ratios, arc.body_heading_at("start")[0], arc.curvature_per_m)
        fitted = _fit_move(tracks, arc.index, arc.before, arc.after, o, f_scale_m, how)
        if isinstance(fitted, str):  # pragma: no cover - the raw fit of the same fixes worked
            seg = arc.segment
            notes.append(f"{seg.kind} move at {seg.t_start_s:.2f}–{seg.t_end_s:.2f} s: {fitted}")
        else:
            arcs.append(fitted)
    return arcs, notes


def tracks_and_arcs(
    recordings: Recording | Sequence[Recording],
    hedge_offset_m: Sequence[float] | None,
    *,
    beacons: BeaconMap | None,
    settle_s: float,
    odom_yaw_deadband_radps: float,
) -> tuple[list[ProcedureTracks], list[list[MoveArc]], list[str]]:
    """Each recording's tracks (:func:`procedure_tracks`) and move arcs (:func:`move_arcs`),
    with the notes prefixed by the recording's index.

    Raises:
        CalibrationError: no recordings, a topic missing, a bad hedgehog offset.
    """
    o = hedge_offset_xy(hedge_offset_m)
    tracks: list[ProcedureTracks] = []
    arcs_all: list[list[MoveArc]] = []
    notes: list[str] = []
    for k, rec in enumerate(as_recordings(recordings)):
        tr = procedure_tracks(
            rec, beacons=beacons, settle_s=settle_s,
            odom_yaw_deadband_radps=odom_yaw_deadband_radps,
        )  # fmt: skip
        arcs, n = move_arcs(tr, hedge_offset_xy_m=o)
        tracks.append(tr)
        arcs_all.append(arcs)
        notes += [f"recording {k}: {text}" for text in n]
    return tracks, arcs_all, notes


def as_recordings(recordings: Recording | Sequence[Recording]) -> list[Recording]:
    """One recording or several, as a list.

    Raises:
        CalibrationError: an empty sequence.
    """
    if isinstance(recordings, Recording):
        return [recordings]
    out = list(recordings)
    if not out:
        msg = "no recordings to analyse"
        raise CalibrationError(msg)
    return out


def hedge_offset_xy(hedge_offset_m: Sequence[float] | None) -> _Array:
    """(2,) hedgehog x, y in base_link from an (x, y) or (x, y, z) offset; zeros for None.

    Raises:
        CalibrationError: not 2 or 3 finite numbers.
    """
    if hedge_offset_m is None:
        return np.zeros(2)
    o = np.asarray(hedge_offset_m, dtype=np.float64).ravel()
    if o.size not in (2, 3) or not np.all(np.isfinite(o)):
        msg = f"hedge_offset_m must be 2 or 3 finite numbers, got {hedge_offset_m!r}"
        raise CalibrationError(msg)
    return o[:2].copy()
