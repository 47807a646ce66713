"""Multilateration: positions from hedgehog–beacon distances, vectorised over fixes.

Three methods share one result type (:class:`Fixes`): ``lsq`` (Gauss–Newton least squares
from a closed-form start), ``robust`` (least squares plus leave-one-out rejection of NLOS
ranges) and ``grid`` (seed 000's 1 mm search minimising its Eq. 4).
"""

from omnical.ips.solve._fit import SolverOptions
from omnical.ips.solve.fixes import (
    CHI2_2DOF_95,
    Ellipses,
    Fixes,
    FixReason,
    FixStatus,
    ellipses_from_covariances,
    mahalanobis_sq,
)
from omnical.ips.solve.locate import Method, locate_recording, solve_fixes

__all__ = [
    "CHI2_2DOF_95",
    "Ellipses",
    "FixReason",
    "FixStatus",
    "Fixes",
    "Method",
    "SolverOptions",
    "ellipses_from_covariances",
    "locate_recording",
    "mahalanobis_sq",
    "solve_fixes",
]
