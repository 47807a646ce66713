"""Headings at the stand-stills and the real yaw per metre of each translation, from IPS arcs.

Consecutive arcs share their stand-still headings (a chain); one generalised least squares over all
recordings gives κ per direction of travel (``chained=False``: the arcs' own curvatures averaged).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from omnical.calibration.procedures.geometry import arc_length
from omnical.calibration.procedures.tracks import Estimate, MoveArc, SlipPrior, TranslationKind
from omnical.errors import CalibrationError

__all__ = ["HeadingSolution", "solve_headings"]

_Array = NDArray[np.float64]
_KINDS: tuple[TranslationKind, ...] = ("forward", "reverse", "left", "right")


@dataclass(frozen=True)
class HeadingSolution:
    """Real yaw per metre per direction and the body heading at every chained stand-still.

    Attributes:
        kinds: directions of travel with at least one arc, in the order of the parameters.
        params: κ per kind (rad/m), θ₀ of each chain (rad, map), then the slip's heading
            change w_k of each arc (rad) when the slip prior has a random yaw.
        covariance: covariance of ``params``.
        nodes: (recording index, stand-still segment index) → gradient (row) such that the
            body heading there is ``gradient @ params`` (+ its entry in ``offsets``).
        birge_ratio: √(χ²/dof) of the fit (1 when dof = 0).
        chained: whether consecutive arcs were tied at their shared stand-stills.
        offsets: the known part of the heading at each node (rad): the yaw the odometry saw
            along its chain (:attr:`MoveArc.off_track_yaw_rad`); missing = 0.
        odom_yaw_per_m: per kind, the mean of the arcs' odometry yaw per metre (rad/m), added
            back by :meth:`crosstalk`.
    """

    kinds: tuple[TranslationKind, ...]
    params: _Array
    covariance: _Array
    nodes: Mapping[tuple[int, int], _Array]
    birge_ratio: float
    chained: bool
    offsets: Mapping[tuple[int, int], float] = field(default_factory=dict)
    odom_yaw_per_m: Mapping[TranslationKind, float] = field(default_factory=dict)

    def crosstalk(self, kind: TranslationKind) -> Estimate:
        """Real yaw per metre of real travel in direction ``kind`` (CCW +), with its σ.

        The solved yaw per metre beyond the odometry's plus the arcs' mean odometry yaw per
        metre of that kind (the translation analysis takes it off again as κ_odom).

        Raises:
            CalibrationError: no arc of that kind.
        """
        if kind not in self.kinds:
            msg = f"no {kind} translation was analysed"
            raise CalibrationError(msg)
        i = self.kinds.index(kind)
        value = float(self.params[i]) + self.odom_yaw_per_m.get(kind, 0.0)
        return Estimate(value, float(math.sqrt(self.covariance[i, i])))

    def heading(self, recording: int, still: int) -> tuple[float, _Array]:
        """Body heading (rad, map frame, unwrapped along its chain) and its gradient."""
        try:
            g = self.nodes[(recording, still)]
        except KeyError:
            msg = f"stand-still {still} of recording {recording} is on no analysed arc"
            raise CalibrationError(msg) from None
        return float(g @ self.params) + self.offsets.get((recording, still), 0.0), g

    def heading_change(self, recording: int, still_from: int, still_to: int) -> Estimate:
        """Heading at ``still_to`` minus heading at ``still_from`` (not reduced mod 2π), with σ."""
        a, ga = self.heading(recording, still_from)
        b, gb = self.heading(recording, still_to)
        g = gb - ga
        var = float(g @ self.covariance @ g)
        return Estimate(b - a, math.sqrt(max(var, 0.0)))


def _arc_measurement(arc: MoveArc) -> tuple[_Array, _Array]:
    """(θ_start, θ_end) of an arc's body heading and their 2 × 2 covariance."""
    start, _ = arc.body_heading_at("start")
    end, _ = arc.body_heading_at("end")
    grads = []
    for point in (arc.start_xy_m, arc.end_xy_m):
        s = arc_length(arc.fit, arc.fit.point_xy_m, point)
        grads.append(np.array([0.0, 1.0, s]))
    g = np.array(grads)
    cov = g @ arc.fit.covariance @ g.T
    # unwrap the end against the start: an arc turns by far less than π
    end = start + math.remainder(end - start, 2.0 * math.pi)
    return np.array([start, end]), np.asarray(cov, dtype=np.float64)


def _chains(arcs: Sequence[MoveArc], chained: bool) -> list[list[MoveArc]]:
    chains: list[list[MoveArc]] = []
    for arc in arcs:
        if chained and chains and chains[-1][-1].after.index == arc.before.index:
            chains[-1].append(arc)
        else:
            chains.append([arc])
    return chains


def solve_headings(
    arcs_per_recording: Sequence[Sequence[MoveArc]],
    *,
    chained: bool = True,
    slip: SlipPrior = SlipPrior(),  # noqa: B008 - frozen dataclass
) -> HeadingSolution:
    """Solve for the yaw per metre of each direction and the headings (docs/DESIGN-NOTES.md).

    Args:
        arcs_per_recording: the arcs of each recording, in time order.
        chained: tie consecutive arcs at their shared stand-still; False treats every arc
            alone (each arc's curvature, inverse-variance averaged per direction).
        slip: random yaw of the slip: each arc's turning angle gets a process noise w_k of
            σ = ``slip.heading_sigma_rad(L, T)`` (a nuisance parameter with that prior).

    Returns:
        The solution.

    Raises:
        CalibrationError: no arcs, or an arc without a finite, regular covariance.
    """
    kinds = tuple(
        k for k in _KINDS if any(a.kind == k for arcs in arcs_per_recording for a in arcs)
    )
    if not kinds:
        msg = "no translation arcs to solve headings from"
        raise CalibrationError(msg)
    chains = [
        (r, chain)
        for r, arcs in enumerate(arcs_per_recording)
        for chain in _chains(sorted(arcs, key=lambda a: a.index), chained)
    ]
    n_k, n_c = len(kinds), len(chains)
    n_arcs = sum(len(chain) for _, chain in chains)
    noisy = slip.crosstalk_rad_per_m > 0.0
    n_p = n_k + n_c + (n_arcs if noisy else 0)
    rows: list[_Array] = []
    values: list[float] = []
    nodes: dict[tuple[int, int], _Array] = {}
    offsets: dict[tuple[int, int], float] = {}
    k_arc = 0
    for c, (r, chain) in enumerate(chains):
        g = np.zeros(n_p)
        g[n_k + c] = 1.0
        offset = 0.0
        known = 0.0  # the odometry's yaw along the chain so far
        for arc in chain:
            where = f"the arc of the {arc.kind} move at {arc.segment.t_start_s:.2f} s"
            m, cov = _arc_measurement(arc)
            if arc is not chain[0]:  # keep the chain continuous: follow the previous end
                m = m + 2.0 * math.pi * round((offset - m[0]) / (2.0 * math.pi))
            g_start = g.copy()
            g_end = g.copy()
            g_end[kinds.index(arc.kind)] += arc.length_m
            if noisy:
                q = slip.heading_sigma_rad(arc.length_m, arc.segment.duration_s)
                g_end[n_k + n_c + k_arc] = 1.0
                prior = np.zeros(n_p)
                prior[n_k + n_c + k_arc] = 1.0 / q if q > 0.0 else 1e12
                rows.append(prior)
                values.append(0.0)
            k_arc += 1
            nodes[(r, arc.before.index)] = g_start
            nodes[(r, arc.after.index)] = g_end
            offsets[(r, arc.before.index)] = known
            offsets[(r, arc.after.index)] = known + arc.off_track_yaw_rad
            try:
                whiten = np.linalg.inv(np.linalg.cholesky(cov))
            except np.linalg.LinAlgError as err:
                msg = f"{where} has no regular covariance"
                raise CalibrationError(msg) from err
            rows.extend(whiten @ np.vstack([g_start, g_end]))
            values.extend(whiten @ (m - np.array([known, known + arc.off_track_yaw_rad])))
            offset = float(m[1])
            known += arc.off_track_yaw_rad
            g = g_end
    a = np.array(rows, dtype=np.float64)
    b = np.array(values, dtype=np.float64)
    params = np.asarray(np.linalg.lstsq(a, b, rcond=None)[0], dtype=np.float64)
    normal_inv = np.asarray(np.linalg.inv(a.T @ a), dtype=np.float64)
    dof = a.shape[0] - n_p
    chi2 = float(np.sum((a @ params - b) ** 2))
    birge = math.sqrt(chi2 / dof) if dof > 0 else 1.0
    cov_params = normal_inv * max(1.0, birge) ** 2
    odom_yaw = {
        k: float(
            np.mean(
                [a.off_track_yaw_rad / a.length_m for _, ch in chains for a in ch if a.kind == k]
            )
        )
        for k in kinds
    }
    return HeadingSolution(kinds, params, cov_params, nodes, birge, chained, offsets, odom_yaw)
