"""Multilateration results: positions, covariances, quality figures and a status per fix."""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.ips.solve.noise_model import NoiseModel

__all__ = [
    "CHI2_2DOF_95",
    "Ellipses",
    "FixReason",
    "FixStatus",
    "Fixes",
    "ellipses_from_covariances",
    "fixes_from_positions",
    "mahalanobis_sq",
]

CHI2_2DOF_95 = 5.991464547107979
"""Chi-square quantile, 2 degrees of freedom, 95 %: scale of the 95 % confidence ellipse."""


class FixStatus(enum.IntEnum):
    """How far a fix can be trusted."""

    OK = 0
    """Residuals consistent with the range noise (after leaving out any clearly identified
    NLOS range); covariance is meaningful."""
    DEGRADED = 1
    """Usable, but the residuals are high or the outlier left out was a guess."""
    REJECTED = 2
    """No trustworthy solution (the position, if finite, is a best effort)."""
    DEGENERATE = 3
    """Too few beacons or singular geometry: no position (NaN)."""


class FixReason(enum.IntFlag):
    """Why a fix has its status (bit flags, several may be set)."""

    NONE = 0
    INVALID_DISTANCE = 1
    """A distance was NaN, infinite or negative in the input messages, or negative/inf here."""
    UNKNOWN_BEACON = 2
    """A message named a beacon address that is not in the map (ignored)."""
    TOO_FEW_BEACONS = 4
    """Fewer valid distances than the dimension needs (3 in 2D, 4 in 3D)."""
    SINGULAR_GEOMETRY = 8
    """Beacons collinear (2D) or coplanar (3D), or singular normal equations at the solution."""
    OUTLIER_REJECTED = 16
    """The robust method left out at least one beacon."""
    HIGH_RESIDUAL = 32
    """Residuals fail the chi-square test against the range noise."""
    NOT_CONVERGED = 64
    """The iterations did not converge."""
    UNKNOWN_HEDGE_HEIGHT = 128
    """2D fix of a hedgehog whose height is not known."""
    AMBIGUOUS_OUTLIER = 256
    """After an outlier was left out, another beacon could as well have been the one."""
    OFF_TRACK = 512
    """The fix lies far outside its covariance from the median of its neighbours in time
    (an ok fix becomes degraded: a robot does not jump)."""


@dataclass(frozen=True)
class Ellipses:
    """Confidence ellipses, one per fix (NaN where the covariance is NaN).

    Attributes:
        semi_major_m: Semi-major axis, shape (n,), metres.
        semi_minor_m: Semi-minor axis, shape (n,), metres.
        angle_rad: Angle of the major axis from the map x axis, counter-clockwise, (n,), rad.
    """

    semi_major_m: NDArray[np.float64]
    semi_minor_m: NDArray[np.float64]
    angle_rad: NDArray[np.float64]


def ellipses_from_covariances(covariance_xy_m2: ArrayLike, scale: float = 1.0) -> Ellipses:
    """Return the ellipses ``xᵀ C⁻¹ x = scale`` of 2×2 covariances.

    Args:
        covariance_xy_m2: Covariances, shape (n, 2, 2), m².
        scale: Mahalanobis radius squared: 1 for 1σ, :data:`CHI2_2DOF_95` for 95 %.

    Returns:
        Semi-axes and orientation, see :class:`Ellipses`.
    """
    cov = np.asarray(covariance_xy_m2, dtype=np.float64)
    a, b, c = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    half_trace = 0.5 * (a + c)
    radius = np.hypot(0.5 * (a - c), b)
    major = np.sqrt(np.maximum(half_trace + radius, 0.0) * scale)
    minor = np.sqrt(np.maximum(half_trace - radius, 0.0) * scale)
    return Ellipses(major, minor, 0.5 * np.arctan2(2.0 * b, a - c))


def mahalanobis_sq(covariance_xy_m2: ArrayLike, delta_xy_m: ArrayLike) -> NDArray[np.float64]:
    """Return ``δᵀ C⁻¹ δ`` per fix for covariances (n, 2, 2) and offsets (n, 2) in metres."""
    cov = np.asarray(covariance_xy_m2, dtype=np.float64)
    delta = np.asarray(delta_xy_m, dtype=np.float64)
    a, b, c = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    dx, dy = delta[:, 0], delta[:, 1]
    det = a * c - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        result: NDArray[np.float64] = (c * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / det
    return result


@dataclass(frozen=True, eq=False)
class Fixes:
    """Multilateration result for n fixes against a map of m beacons.

    Attributes:
        positions_map_m: Position in the ``map`` frame, shape (n, 3), metres; in 2D z is the
            known hedgehog height. NaN for degenerate fixes.
        covariance_xy_m2: Horizontal covariance, shape (n, 2, 2), m²; ``σ̂² (JᵀWJ)⁻¹`` with
            the Jacobian J of the beacons used at the solution, W their relative weights
            (identity unless per-beacon σ were given) and σ̂ = max(prior σ, sqrt(rᵀWr/dof)),
            dof = beacons used − unknowns. The 95 % ellipse is ``scale=CHI2_2DOF_95``.
        sigma_z_m: Standard deviation of z, shape (n,), metres (NaN in 2D).
        range_sigma_m: σ̂ used for the covariance, shape (n,), metres.
        hdop: Horizontal dilution of precision of the beacons used, shape (n,).
        residual_rms_m: RMS of the range residuals of the beacons used, shape (n,), metres.
        error_eq4_m: Seed 000 Eq. 4, ``(1/n_b²) sqrt(Σ (‖b_i − p‖ − d_i)²)`` over the
            beacons used, shape (n,), metres.
        used: Which map beacons the solution uses, shape (n, m), bool.
        status: :class:`FixStatus` code per fix, shape (n,), uint8.
        reason: :class:`FixReason` bit flags per fix, shape (n,), uint16.
        beacon_addresses: Column order of :attr:`used`, shape (m,).
        method: Solver name (``lsq``, ``robust``, ``grid``).
        dims: 2 (known height) or 3.
        t_ns: Time of each fix, shape (n,), int64 ns, when built from a recording.
        address_hedge: Hedgehog address of each fix, shape (n,), when known.
        noise: The range noise model of each hedgehog the fixes were solved with (σ per link
            and, when self-calibrated, bias and scale), when built from a recording.
        notes: What the solver decided on its own (geometry, windows), one sentence each.
    """

    positions_map_m: NDArray[np.float64]
    covariance_xy_m2: NDArray[np.float64]
    sigma_z_m: NDArray[np.float64]
    range_sigma_m: NDArray[np.float64]
    hdop: NDArray[np.float64]
    residual_rms_m: NDArray[np.float64]
    error_eq4_m: NDArray[np.float64]
    used: NDArray[np.bool_]
    status: NDArray[np.uint8]
    reason: NDArray[np.uint16]
    beacon_addresses: NDArray[np.int64]
    method: str
    dims: int
    t_ns: NDArray[np.int64] | None = None
    address_hedge: NDArray[np.int64] | None = None
    noise: tuple[NoiseModel, ...] = ()
    notes: tuple[str, ...] = ()

    def __len__(self) -> int:
        """Return the number of fixes."""
        return int(self.status.size)

    @property
    def n_used(self) -> NDArray[np.int64]:
        """Number of beacons each solution uses, shape (n,)."""
        counts: NDArray[np.int64] = np.count_nonzero(self.used, axis=1).astype(np.int64)
        return counts

    @property
    def ok(self) -> NDArray[np.bool_]:
        """Mask of fixes with status OK, shape (n,)."""
        mask: NDArray[np.bool_] = self.status == FixStatus.OK
        return mask

    def has_reason(self, reason: FixReason) -> NDArray[np.bool_]:
        """Mask of fixes whose reason flags include ``reason``, shape (n,)."""
        mask: NDArray[np.bool_] = (self.reason & np.uint16(reason)) != 0
        return mask

    def ellipses(self, scale: float = 1.0) -> Ellipses:
        """Return the confidence ellipses (1σ by default; :data:`CHI2_2DOF_95` for 95 %)."""
        return ellipses_from_covariances(self.covariance_xy_m2, scale)

    def contains(self, truth_xy_m: ArrayLike, scale: float = CHI2_2DOF_95) -> NDArray[np.bool_]:
        """Whether each true position (n, 2) lies inside the fix's confidence ellipse."""
        delta = np.asarray(truth_xy_m, dtype=np.float64) - self.positions_map_m[:, :2]
        inside: NDArray[np.bool_] = mahalanobis_sq(self.covariance_xy_m2, delta) <= scale
        return inside


def fixes_from_positions(t_ns: ArrayLike, xy_m: ArrayLike, sigma_m: float, method: str) -> Fixes:
    """Planar positions measured by something else (motion capture, a synthetic run) as fixes
    of status OK with an isotropic σ (m): no ranges behind them (no beacons used, σ_z NaN).

    ``t_ns`` (n,) bag times, ``xy_m`` (n, 2); ``method`` names their source.
    """
    t = np.asarray(t_ns, dtype=np.int64).reshape(-1)
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    n = t.size
    return Fixes(
        positions_map_m=np.column_stack([xy, np.zeros(n)]),
        covariance_xy_m2=np.broadcast_to(np.eye(2) * sigma_m**2, (n, 2, 2)).copy(),
        sigma_z_m=np.full(n, np.nan),
        range_sigma_m=np.full(n, sigma_m),
        hdop=np.ones(n),
        residual_rms_m=np.zeros(n),
        error_eq4_m=np.zeros(n),
        used=np.zeros((n, 0), dtype=bool),
        status=np.full(n, FixStatus.OK, dtype=np.uint8),
        reason=np.zeros(n, dtype=np.uint16),
        beacon_addresses=np.zeros(0, dtype=np.int64),
        method=method,
        dims=2,
        t_ns=t,
    )
