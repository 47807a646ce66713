"""Multilateration: positions from hedgehog–beacon distances, vectorised over fixes.

Methods ``lsq`` (Gauss–Newton), ``robust`` (plus NLOS rejection) and ``grid`` (seed 000's
1 mm search) all return :class:`Fixes`; :func:`locate_recording` solves a whole recording.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
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
    from omnical.ips.solve.locate import (
        Method,
        locate_recording,
        solve_fixes,
    )

_EXPORTS: dict[str, str] = {
    "CHI2_2DOF_95": "omnical.ips.solve.fixes",
    "Ellipses": "omnical.ips.solve.fixes",
    "FixReason": "omnical.ips.solve.fixes",
    "FixStatus": "omnical.ips.solve.fixes",
    "Fixes": "omnical.ips.solve.fixes",
    "Method": "omnical.ips.solve.locate",
    "SolverOptions": "omnical.ips.solve._fit",
    "ellipses_from_covariances": "omnical.ips.solve.fixes",
    "locate_recording": "omnical.ips.solve.locate",
    "mahalanobis_sq": "omnical.ips.solve.fixes",
    "solve_fixes": "omnical.ips.solve.locate",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

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


__getattr__ = lazy_getattr(__name__, _EXPORTS)
