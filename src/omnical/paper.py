"""The seeds' published numbers, in one place: what omnical reproduces and reports beside its own.

Plain numbers, importable by every layer: seed 000 Tables 2 and 4, the §3.2 measures, seed 003's
Table II and test errors (Table 2 as magnitudes; the signed truth is in :mod:`omnical.twin.params`).
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
    "SEED003_PAPER_TABLE2",
    "SEED003_PAPER_TEST_ERRORS",
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

#: Seed 003 Table II: mean speed (rpm) of motors 1–4 at set points 110–200 rpm.
SEED003_PAPER_TABLE2: Final[tuple[tuple[float, ...], ...]] = (
    (110.1, 110.0, 110.1, 110.0),
    (120.0, 119.8, 119.9, 120.0),
    (129.6, 129.9, 129.9, 129.7),
    (140.1, 140.1, 140.2, 140.3),
    (149.9, 149.5, 149.6, 149.3),
    (160.0, 160.1, 160.0, 159.8),
    (169.9, 169.9, 169.9, 169.9),
    (180.3, 180.4, 180.2, 180.3),
    (190.2, 189.7, 189.8, 189.7),
    (199.8, 200.3, 200.0, 200.1),
)
#: Seed 003's stated errors of its four tests (§IV.B and §V), by test slug: the two numbers
#: and their labels (centred turning: heading error °, final distance error cm; driving
#: forward: final x and y error, cm; square and triangle: maximum |x| and |y| error, cm).
SEED003_PAPER_TEST_ERRORS: Final[Mapping[str, tuple[float, float]]] = MappingProxyType(
    {
        "centred-turning": (4.0, 4.2),
        "driving-forward": (5.0, 2.0),
        "square": (10.4, 12.24),
        "triangle": (22.1, 12.3),
    }
)
