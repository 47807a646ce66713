"""The seeds' published numbers, in one place: what omnical reproduces and reports beside its own.

Plain numbers only (no omnical imports), so every layer may read them: the twin takes seed 000
Table 2 as its default truth, the tests take these as golden values and the report layer prints
them beside the twin's.

* :data:`SEED000_TABLE2` — the seven correction factors (seed 000 Table 2), as the paper prints
  them: magnitudes, scalings first then cross-talks forward, reverse, left, right (rad/m). The
  twin's signed truth (docs/CONVENTIONS.md) is in :mod:`omnical.twin.params`.
* :data:`SEED000_TABLE4` — RMSE of tracking the Lissajous curve (position, x, y in metres) for
  wheel odometry and the IPS, uncalibrated and calibrated. The "position" column is
  sqrt((x² + y²) / 2) of the other two (see :mod:`omnical.evaluation.metrics`).
* :data:`SEED000_MEASURES` — the before/after measures of seed 000 §3.2 (value before
  calibration, bound after), by measure key.
* :data:`SEED000_IMPROVEMENT` — the IPS RMSE ratio uncalibrated / calibrated of Table 4.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Final

__all__ = [
    "SEED000_IMPROVEMENT",
    "SEED000_MEASURES",
    "SEED000_TABLE2",
    "SEED000_TABLE4",
    "Table4Numbers",
]

SEED000_TABLE2: Final[tuple[float, float, float, float, float, float, float]] = (
    1.02,
    1.13,
    1.0236,
    0.0072,
    0.00009,
    0.0389,
    0.0277,
)
"""Seed 000 Table 2: k_lon, k_lat, k_rot, then |c| forward, reverse, left, right (rad/m)."""

Table4Numbers = Mapping[str, Mapping[str, tuple[float, float, float]]]
"""Phase (``uncalibrated``/``calibrated``) → estimate (``odometry``/``ips``) → (pos, x, y) m."""

SEED000_TABLE4: Final[Table4Numbers] = MappingProxyType(
    {
        "uncalibrated": MappingProxyType(
            {"odometry": (0.0083, 0.0089, 0.0076), "ips": (0.1119, 0.1518, 0.0445)}
        ),
        "calibrated": MappingProxyType(
            {"odometry": (0.0085, 0.0086, 0.0083), "ips": (0.0171, 0.0168, 0.0173)}
        ),
    }
)
"""Seed 000 Table 4: kinematics → estimate → (position, x, y) RMSE in metres."""

SEED000_IMPROVEMENT: Final[float] = (
    SEED000_TABLE4["uncalibrated"]["ips"][0] / SEED000_TABLE4["calibrated"]["ips"][0]
)
"""How much lower the paper's IPS RMSE of the Lissajous is after calibration (≈ 6.5×)."""

SEED000_MEASURES: Final[Mapping[str, tuple[float, float]]] = MappingProxyType(
    {
        "heading": (25.5, 3.0),
        "longitudinal": (25.0, 5.0),
        "lateral": (22.0, 5.0),
        "crosstalk_longitudinal": (7.0, 1.5),
        "crosstalk_lateral": (38.0, 5.0),
    }
)
"""Seed 000 §3.2: measure → (before calibration, bound after) in °, cm, cm, mrad/m, mrad/m."""
