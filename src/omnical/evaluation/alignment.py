"""Alignment of an estimated trajectory onto its reference: none, origin or least-squares SE(2).

Rigid only (a scale would hide distance errors); defaults ``se2`` for map-frame estimates
(:data:`DEFAULT_ALIGN_IPS`) and ``origin`` for wheel odometry (:data:`DEFAULT_ALIGN_ODOMETRY`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.choices import AlignMode as AlignChoice
from omnical.choices import parse_choice
from omnical.errors import GeometryError
from omnical.estimation.se2 import Pose2, rotate_xy, transform_points, wrap_angle
from omnical.evaluation.association import Association, paired_xy

__all__ = [
    "ALIGN_MODES",
    "DEFAULT_ALIGN_IPS",
    "DEFAULT_ALIGN_ODOMETRY",
    "AlignMode",
    "Alignment",
    "Transform2D",
    "align",
    "align_positions",
    "fit_se2",
    "origin_transform",
]

FloatArray = NDArray[np.float64]
AlignMode = AlignChoice | Literal["none", "origin", "se2"]
"""An alignment mode: a :class:`omnical.choices.AlignMode` or its plain string."""
ALIGN_MODES: Final[tuple[str, ...]] = tuple(m.value for m in AlignChoice)
DEFAULT_ALIGN_IPS: Final[AlignMode] = "se2"
DEFAULT_ALIGN_ODOMETRY: Final[AlignMode] = "origin"

_MIN_SPREAD_M = 1e-9


@dataclass(frozen=True)
class Transform2D:
    """A planar rigid transform p ↦ R(rotation_rad) p + translation_m.

    Attributes:
        rotation_rad: rotation angle, counter-clockwise positive, in [−π, π].
        translation_m: (x, y) translation in metres, in the target frame.
    """

    rotation_rad: float = 0.0
    translation_m: tuple[float, float] = (0.0, 0.0)

    @property
    def pose(self) -> Pose2:
        """The transform as the pose (x m, y m, yaw rad) of the estimate frame in the target."""
        return (self.translation_m[0], self.translation_m[1], self.rotation_rad)

    @property
    def rotation_matrix(self) -> FloatArray:
        """The 2×2 rotation matrix."""
        c, s = np.cos(self.rotation_rad), np.sin(self.rotation_rad)
        return np.array([[c, -s], [s, c]])

    def apply(self, xy_m: ArrayLike) -> FloatArray:
        """Transform (N, 2) positions."""
        return transform_points(self.pose, xy_m)

    def apply_yaw(self, yaw_rad: ArrayLike) -> FloatArray:
        """Transform (N,) headings (adds the rotation, no wrapping)."""
        return np.asarray(yaw_rad, dtype=np.float64) + self.rotation_rad


def _onto(source_xy_m: FloatArray, target_xy_m: FloatArray, rotation_rad: float) -> Transform2D:
    """The transform turning by ``rotation_rad`` that carries the source point onto the target."""
    t = target_xy_m - rotate_xy(rotation_rad, source_xy_m)
    return Transform2D(rotation_rad, (float(t[0]), float(t[1])))


def fit_se2(source_xy_m: ArrayLike, target_xy_m: ArrayLike) -> Transform2D:
    """Least-squares rotation and translation carrying ``source`` onto ``target`` (no scale).

    Umeyama 1991 in 2D: θ = atan2(Σ a'×b', Σ a'·b') over the centred sets, t = b̄ − R ā; a
    proper rotation, never a reflection.

    Args:
        source_xy_m: (N, 2) positions to move (the estimate).
        target_xy_m: (N, 2) positions to reach (the reference), paired row by row.

    Raises:
        GeometryError: shapes differ, or either set lies within 1 nm of its centroid.
    """
    a, b = paired_xy(source_xy_m, target_xy_m, "alignment")
    a_mean, b_mean = a.mean(axis=0), b.mean(axis=0)
    ac, bc = a - a_mean, b - b_mean
    spread_a = float(np.sqrt(np.mean(np.sum(ac**2, axis=1))))
    spread_b = float(np.sqrt(np.mean(np.sum(bc**2, axis=1))))
    if min(spread_a, spread_b) < _MIN_SPREAD_M:
        raise GeometryError(
            "SE(2) alignment needs positions that spread: the trajectory stands still "
            f"(spread {spread_a:.3g} m and {spread_b:.3g} m), the rotation is undetermined"
        )
    cross = float(np.sum(ac[:, 0] * bc[:, 1] - ac[:, 1] * bc[:, 0]))
    dot = float(np.sum(ac[:, 0] * bc[:, 0] + ac[:, 1] * bc[:, 1]))
    return _onto(a_mean, b_mean, float(np.arctan2(cross, dot)))


def origin_transform(
    source_xy_m: ArrayLike,
    target_xy_m: ArrayLike,
    source_yaw_rad: float | None = None,
    target_yaw_rad: float | None = None,
) -> Transform2D:
    """The transform that puts the source pose onto the target pose.

    Args:
        source_xy_m: (2,) first estimated position.
        target_xy_m: (2,) reference position at the same time.
        source_yaw_rad: first estimated heading; with ``target_yaw_rad`` the rotation is their
            difference, else the transform is a pure translation.
        target_yaw_rad: reference heading at the same time.
    """
    a = np.asarray(source_xy_m, dtype=np.float64).reshape(2)
    b = np.asarray(target_xy_m, dtype=np.float64).reshape(2)
    theta = 0.0
    if source_yaw_rad is not None and target_yaw_rad is not None:
        theta = wrap_angle(float(target_yaw_rad) - float(source_yaw_rad))
    return _onto(a, b, theta)


@dataclass(frozen=True, eq=False)
class Alignment:
    """An estimate carried into the reference frame.

    Attributes:
        mode: the alignment mode used.
        transform: estimate frame → reference frame.
        xy_m: (M, 2) aligned estimated positions.
        yaw_rad: (M,) aligned estimated headings, or None.
    """

    mode: AlignMode
    transform: Transform2D
    xy_m: FloatArray
    yaw_rad: FloatArray | None


def align_positions(
    estimate_xy_m: ArrayLike,
    reference_xy_m: ArrayLike,
    mode: AlignMode,
    *,
    estimate_yaw_rad: ArrayLike | None = None,
    reference_yaw_rad: ArrayLike | None = None,
) -> Alignment:
    """Align paired positions (row i of the estimate belongs with row i of the reference).

    Args:
        estimate_xy_m: (M, 2) estimated positions.
        reference_xy_m: (M, 2) reference positions at the same times.
        mode: ``none``, ``origin`` or ``se2`` (docs/DESIGN-NOTES.md).
        estimate_yaw_rad: (M,) estimated headings, if any (rotated along; used by ``origin``).
        reference_yaw_rad: (M,) reference headings, if any (used by ``origin``).

    Raises:
        ChoiceError: an unknown mode.
        GeometryError: mismatched shapes, or an undetermined ``se2`` rotation.
    """
    mode = parse_choice(AlignChoice, mode, "alignment")
    a, b = paired_xy(estimate_xy_m, reference_xy_m, "alignment")
    yaw_a = None if estimate_yaw_rad is None else np.asarray(estimate_yaw_rad, dtype=np.float64)
    yaw_b = None if reference_yaw_rad is None else np.asarray(reference_yaw_rad, dtype=np.float64)
    for name, yaw in (("estimate", yaw_a), ("reference", yaw_b)):
        if yaw is not None and yaw.shape != (a.shape[0],):
            raise GeometryError(f"{name} headings must be ({a.shape[0]},), got {yaw.shape}")
    if mode is AlignChoice.NONE:
        transform = Transform2D()
    elif mode is AlignChoice.ORIGIN:
        transform = origin_transform(
            a[0],
            b[0],
            None if yaw_a is None else float(yaw_a[0]),
            None if yaw_b is None else float(yaw_b[0]),
        )
    else:
        transform = fit_se2(a, b)
    aligned_yaw = None if yaw_a is None else transform.apply_yaw(yaw_a)
    return Alignment(mode, transform, transform.apply(a), aligned_yaw)


def align(association: Association, mode: AlignMode) -> Alignment:
    """Align an association's estimate onto its interpolated reference."""
    return align_positions(
        association.estimate_xy_m,
        association.reference_xy_m,
        mode,
        estimate_yaw_rad=association.estimate_yaw_rad,
        reference_yaw_rad=association.reference_yaw_rad,
    )
