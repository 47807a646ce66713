"""Plain least squares: closed-form linearised start, then Gauss–Newton over all beacons."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from omnical.ips.solve._fit import Solution, SolverOptions, fit
from omnical.ips.solve._kernels import RangeProblem

__all__ = ["solve_lsq"]


def solve_lsq(problem: RangeProblem, valid: NDArray[np.bool_], options: SolverOptions) -> Solution:
    """Solve every fix by Gauss–Newton least squares over all its valid distances.

    Args:
        problem: Distances of n fixes to m beacons (beacon-major).
        valid: Which distances are valid, shape (m, n).
        options: Numerical options.

    Returns:
        The solution; no fix is rejected here except through its flags.
    """
    result = fit(problem, valid, options)
    rejected = np.zeros(valid.shape[1], dtype=bool)
    return Solution(result.point, valid, result.reason, rejected, result.normal, result.cost)
