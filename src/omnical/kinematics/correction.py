"""The seven correction factors of seed 000 (Table 2) and the compensation they drive.

Signs as in docs/CONVENTIONS.md: compensation injects −c·|v|, then scales; counter-compensation
undoes it in reverse order. The ``*_scalar`` forms serve the twin's per-step loop.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.paper import SEED000_TABLE2

__all__ = [
    "CorrectionFactors",
    "compensate_twist",
    "compensate_twist_scalar",
    "counter_compensate_twist",
    "counter_compensate_twist_scalar",
    "crosstalk_yaw_rate",
    "crosstalk_yaw_rate_scalar",
]


@dataclass(frozen=True)
class CorrectionFactors:
    """Three scalings (dimensionless) and four translation→rotation cross-talks (rad/m)."""

    scale_longitudinal: float = 1.0
    scale_lateral: float = 1.0
    scale_rotational: float = 1.0
    crosstalk_forward_rad_per_m: float = 0.0
    crosstalk_reverse_rad_per_m: float = 0.0
    crosstalk_left_rad_per_m: float = 0.0
    crosstalk_right_rad_per_m: float = 0.0

    @classmethod
    def identity(cls) -> CorrectionFactors:
        """No correction."""
        return cls()

    @classmethod
    def seed000_table2(cls) -> CorrectionFactors:
        """The factors of seed 000 Table 2, all cross-talks taken as counter-clockwise positive."""
        return cls(*SEED000_TABLE2)

    @property
    def scales(self) -> NDArray[np.float64]:
        """(3,) longitudinal, lateral, rotational scaling."""
        return np.array([self.scale_longitudinal, self.scale_lateral, self.scale_rotational])

    @property
    def crosstalks_rad_per_m(self) -> NDArray[np.float64]:
        """(4,) forward, reverse, left, right cross-talk."""
        return np.array(
            [
                self.crosstalk_forward_rad_per_m,
                self.crosstalk_reverse_rad_per_m,
                self.crosstalk_left_rad_per_m,
                self.crosstalk_right_rad_per_m,
            ]
        )

    @classmethod
    def from_vector(cls, values: ArrayLike) -> CorrectionFactors:
        """Build from the 7-vector (scales then cross-talks, in field order)."""
        v = np.asarray(values, dtype=np.float64).ravel()
        if v.shape != (7,):
            msg = f"correction factors need 7 values, got {v.shape[0]}"
            raise ValueError(msg)
        return cls(*(float(x) for x in v))

    def as_vector(self) -> NDArray[np.float64]:
        """The 7-vector in field order."""
        return np.array([getattr(self, f.name) for f in fields(self)], dtype=np.float64)

    def as_dict(self) -> dict[str, float]:
        """Field name → value."""
        return {k: float(v) for k, v in asdict(self).items()}

    def composed_with(self, later: CorrectionFactors) -> CorrectionFactors:
        """Factors after applying ``later`` on top of these (seed 000 §3.2.1: scalings multiply).

        A later iteration measures residual factors on a robot already compensated by ``self``;
        the total scaling is the product of the iterations and the residual cross-talks add
        (exact for the scalings, first order for the cross-talks).
        """
        s = self.scales * later.scales
        c = self.crosstalks_rad_per_m + later.crosstalks_rad_per_m
        return CorrectionFactors.from_vector(np.concatenate([s, c]))

    def with_values(self, **changes: float) -> CorrectionFactors:
        """A copy with some fields replaced."""
        return replace(self, **changes)


def crosstalk_yaw_rate(
    factors: CorrectionFactors, vx: ArrayLike, vy: ArrayLike
) -> NDArray[np.float64]:
    """Yaw rate (rad/s, CCW positive) the cross-talk makes at real body speeds vx, vy (m/s)."""
    vx_a = np.asarray(vx, dtype=np.float64)
    vy_a = np.asarray(vy, dtype=np.float64)
    result: NDArray[np.float64] = (
        factors.crosstalk_forward_rad_per_m * np.maximum(vx_a, 0.0)
        + factors.crosstalk_reverse_rad_per_m * np.maximum(-vx_a, 0.0)
        + factors.crosstalk_left_rad_per_m * np.maximum(vy_a, 0.0)
        + factors.crosstalk_right_rad_per_m * np.maximum(-vy_a, 0.0)
    )
    return result


def compensate_twist(twist: ArrayLike, factors: CorrectionFactors) -> NDArray[np.float64]:
    """Desired body twist (..., 3) → twist to feed the nominal inverse kinematics.

    Injects −c·|v| into the yaw rate, then multiplies by the scalings.
    """
    t = np.array(twist, dtype=np.float64)
    t[..., 2] -= crosstalk_yaw_rate(factors, t[..., 0], t[..., 1])
    result: NDArray[np.float64] = t * factors.scales
    return result


def counter_compensate_twist(twist: ArrayLike, factors: CorrectionFactors) -> NDArray[np.float64]:
    """Twist from the nominal forward kinematics (..., 3) → compensated odometry twist.

    The reverse of :func:`compensate_twist`: divide by the scalings, then remove the injected
    cross-talk correction, so the odometry reports the motion the robot was asked for.
    """
    t = np.array(twist, dtype=np.float64) / factors.scales
    t[..., 2] += crosstalk_yaw_rate(factors, t[..., 0], t[..., 1])
    return t


def crosstalk_yaw_rate_scalar(factors: CorrectionFactors, vx_mps: float, vy_mps: float) -> float:
    """:func:`crosstalk_yaw_rate` for one body speed (rad/s), on floats.

    The same terms in the same order as the vectorised function.
    """
    return (
        factors.crosstalk_forward_rad_per_m * max(vx_mps, 0.0)
        + factors.crosstalk_reverse_rad_per_m * max(-vx_mps, 0.0)
        + factors.crosstalk_left_rad_per_m * max(vy_mps, 0.0)
        + factors.crosstalk_right_rad_per_m * max(-vy_mps, 0.0)
    )


def compensate_twist_scalar(
    vx_mps: float, vy_mps: float, wz_radps: float, factors: CorrectionFactors
) -> tuple[float, float, float]:
    """:func:`compensate_twist` for one twist, on floats: (vx, vy, wz) for the inverse kinematics.

    Args:
        vx_mps, vy_mps, wz_radps: desired body twist.
        factors: the correction factors the vehicle controller applies.

    Returns:
        The twist to feed the nominal inverse kinematics (cross-talk injected, then scaled).
    """
    wz = wz_radps - crosstalk_yaw_rate_scalar(factors, vx_mps, vy_mps)
    return (
        vx_mps * factors.scale_longitudinal,
        vy_mps * factors.scale_lateral,
        wz * factors.scale_rotational,
    )


def counter_compensate_twist_scalar(
    vx_mps: float, vy_mps: float, wz_radps: float, factors: CorrectionFactors
) -> tuple[float, float, float]:
    """:func:`counter_compensate_twist` for one twist, on floats.

    With the installed factors: the nominal forward-kinematics twist → the compensated odometry
    twist. With the true factors: the twist the wheels say → the twist the robot really makes
    (the seven-factor truth of the digital twin).

    Args:
        vx_mps, vy_mps, wz_radps: twist from the nominal forward kinematics.
        factors: installed (odometry side) or true (plant) factors.

    Returns:
        The twist divided by the scalings, plus the cross-talk yaw rate of its translation.
    """
    vx = vx_mps / factors.scale_longitudinal
    vy = vy_mps / factors.scale_lateral
    wz = wz_radps / factors.scale_rotational
    return (vx, vy, wz + crosstalk_yaw_rate_scalar(factors, vx, vy))
