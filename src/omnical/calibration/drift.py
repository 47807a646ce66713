"""Factor drift across a fleet: a recording's factor more than 3σ from the rest of the fleet
(median and robust spread of the others) or from its previous calibration (matched by name).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np

__all__ = [
    "ALERT_SIGMAS",
    "MIN_FLEET",
    "Alert",
    "FactorSpread",
    "check_unique_names",
    "factor_alerts",
    "fleet_spread",
]

ALERT_SIGMAS: Final = 3.0
"""A factor this many combined σ away is a maintenance alert."""

MIN_FLEET: Final = 3
"""Fewest other recordings (with the factor estimated) to compare one against the fleet."""

_MAD_TO_SIGMA: Final = 1.4826


@dataclass(frozen=True)
class Alert:
    """One factor of one recording that moved.

    Attributes:
        name: the recording's name in the table.
        factor: the factor's field name.
        value: its estimate.
        reference: the fleet's median (of the others) or the previous estimate.
        sigma: the combined 1σ of the difference.
        z: (value − reference) / sigma.
        against: ``fleet`` or ``previous``.
    """

    name: str
    factor: str
    value: float
    reference: float
    sigma: float
    z: float
    against: str


@dataclass(frozen=True)
class FactorSpread:
    """One factor across the fleet's ok rows where it was estimated.

    Attributes:
        factor: the field name.
        count: recordings with it estimated.
        mean: their mean; std: their standard deviation (0 for one).
        median_sigma: the median of their own 1σ.
        low, high: the smallest and largest estimate.
    """

    factor: str
    count: int
    mean: float
    std: float
    median_sigma: float
    low: float
    high: float


def check_unique_names(rows: Sequence[Mapping[str, str]], source: str) -> None:
    """Refuse a table in which two rows have the same name: drift is matched by name.

    Raises:
        RecordingError: the first name found twice, with ``source`` (where the rows are from).
    """
    from omnical.errors import RecordingError

    seen: set[str] = set()
    for row in rows:
        name = row.get("name", "")
        if name in seen:
            msg = (
                f"{source}: two rows are named {name!r}: factors are compared by recording "
                "name, so these could be another robot's"
            )
            raise RecordingError(msg)
        seen.add(name)


def _estimates(rows: Sequence[Mapping[str, str]], factor: str) -> dict[str, tuple[float, float]]:
    """name → (value, σ) of the ok rows with ``factor`` estimated (finite σ)."""
    out = {}
    for row in rows:
        if row.get("status") != "ok":
            continue
        try:
            value, sigma = float(row[factor]), float(row[f"{factor}_sigma"])
        except (KeyError, ValueError):
            continue
        if math.isfinite(value) and math.isfinite(sigma):
            out[row["name"]] = (value, sigma)
    return out


def fleet_spread(rows: Sequence[Mapping[str, str]], factors: Sequence[str]) -> list[FactorSpread]:
    """Each factor's spread across the fleet (factors no row estimated are left out).

    Raises:
        RecordingError: two rows have the same name.
    """
    check_unique_names(rows, "the fleet")
    spreads = []
    for factor in factors:
        found = _estimates(rows, factor)
        if not found:
            continue
        values = np.array([v for v, _ in found.values()])
        sigmas = np.array([s for _, s in found.values()])
        spreads.append(
            FactorSpread(
                factor,
                len(values),
                float(values.mean()),
                float(values.std(ddof=1)) if len(values) > 1 else 0.0,
                float(np.median(sigmas)),
                float(values.min()),
                float(values.max()),
            )
        )
    return spreads


def factor_alerts(
    rows: Sequence[Mapping[str, str]],
    factors: Sequence[str],
    previous: Sequence[Mapping[str, str]] = (),
    *,
    sigmas: float = ALERT_SIGMAS,
) -> list[Alert]:
    """The factors more than ``sigmas`` combined σ from the fleet or from ``previous``.

    Against the fleet: the median of the others', σ = its own 1σ and the others' robust spread
    (1.4826 × MAD) in quadrature. Against a previous calibration (rows of an earlier
    ``fleet.csv``, matched by name): the two 1σ in quadrature.

    Raises:
        RecordingError: two rows of ``rows``, or of ``previous``, have the same name.
    """
    check_unique_names(rows, "the fleet")
    check_unique_names(previous, "the previous fleet.csv")
    alerts = []
    for factor in factors:
        found = _estimates(rows, factor)
        earlier = _estimates(previous, factor)
        for name, (value, sigma) in found.items():
            others = np.array([v for n, (v, _) in found.items() if n != name])
            if len(others) >= MIN_FLEET:
                median = float(np.median(others))
                spread = _MAD_TO_SIGMA * float(np.median(np.abs(others - median)))
                combined = math.hypot(sigma, spread)
                if combined > 0.0 and abs(value - median) > sigmas * combined:
                    z = (value - median) / combined
                    alerts.append(Alert(name, factor, value, median, combined, z, "fleet"))
            if name in earlier:
                before, before_sigma = earlier[name]
                combined = math.hypot(sigma, before_sigma)
                if combined > 0.0 and abs(value - before) > sigmas * combined:
                    z = (value - before) / combined
                    alerts.append(Alert(name, factor, value, before, combined, z, "previous"))
    return alerts
