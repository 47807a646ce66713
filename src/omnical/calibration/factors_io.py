"""The ``factors.yaml`` file: the seven correction factors and their one-sigma uncertainties.

Layout (sign conventions of docs/CONVENTIONS.md; the uncertainty section is optional and nests
the same way, one standard deviation per factor, ``.nan`` for a factor that was not estimated)::

    scale: {longitudinal: 1.02, lateral: 1.13, rotational: 1.0236}
    crosstalk_rad_per_m: {forward: 0.0072, reverse: -0.00009, left: 0.0389, right: -0.0277}
    uncertainty:
      scale: {longitudinal: 0.0004, lateral: 0.0006, rotational: 0.0012}
      crosstalk_rad_per_m: {forward: 0.0005, reverse: 0.0005, left: 0.0006, right: 0.0006}

Numbers are written in plain positional notation (``0.00009``, never ``9e-05``, which YAML 1.1
readers take for a string) with the shortest digits that read back to the same float, so a
write/read round trip is exact. Reading validates every field and raises a one-line
:class:`ConfigError` naming the file, the field and the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from omnical.errors import ConfigError
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import FACTORS
from omnical.kinematics.factors_layout import (
    CROSSTALK_KEYS,
    SCALE_KEYS,
    factors_from_layout,
    layout_values,
)
from omnical.userfiles import read_yaml

__all__ = [
    "CROSSTALK_KEYS",
    "SCALE_KEYS",
    "FactorsFile",
    "factors_file_text",
    "parse_factors",
    "read_factors",
    "write_factors",
    "yaml_number",
]


@dataclass(frozen=True)
class FactorsFile:
    """Contents of a ``factors.yaml``.

    Attributes:
        factors: the seven factors.
        uncertainty: one standard deviation per factor (NaN = not estimated), or None when the
            file has no ``uncertainty`` section.
    """

    factors: CorrectionFactors
    uncertainty: CorrectionFactors | None = None


def yaml_number(value: float) -> str:
    """Shortest positional text that YAML reads back to the same float (``.nan``, ``.inf``)."""
    v = float(value)
    if math.isnan(v):
        return ".nan"
    if math.isinf(v):
        return ".inf" if v > 0 else "-.inf"
    return np.format_float_positional(v, unique=True, trim="0")


def _flow(keys: tuple[str, ...], values: np.ndarray) -> str:
    return (
        "{" + ", ".join(f"{k}: {yaml_number(v)}" for k, v in zip(keys, values, strict=True)) + "}"
    )


def factors_file_text(
    factors: CorrectionFactors, uncertainty: CorrectionFactors | None = None, comment: str = ""
) -> str:
    """The text of a ``factors.yaml`` (optionally headed by ``#`` comment lines)."""
    lines = [f"# {line}".rstrip() for line in comment.splitlines()]
    lines.append(f"scale: {_flow(SCALE_KEYS, factors.scales)}")
    lines.append(f"crosstalk_rad_per_m: {_flow(CROSSTALK_KEYS, factors.crosstalks_rad_per_m)}")
    if uncertainty is not None:
        lines.append("uncertainty:")
        lines.append(f"  scale: {_flow(SCALE_KEYS, uncertainty.scales)}")
        lines.append(
            f"  crosstalk_rad_per_m: {_flow(CROSSTALK_KEYS, uncertainty.crosstalks_rad_per_m)}"
        )
    return "\n".join(lines) + "\n"


def write_factors(
    path: str | Path,
    factors: CorrectionFactors,
    uncertainty: CorrectionFactors | None = None,
    *,
    comment: str = "",
) -> Path:
    """Write ``factors.yaml`` (parent directories created); returns the path.

    Raises:
        ConfigError: the file cannot be written.
    """
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(factors_file_text(factors, uncertainty, comment), encoding="utf-8")
    except OSError as err:
        msg = f"{p}: cannot write: {err.strerror or err}"
        raise ConfigError(msg) from None
    return p


def parse_factors(data: Any, source: str = "<factors>") -> FactorsFile:
    """Validate a parsed ``factors.yaml`` mapping.

    Raises:
        ConfigError: naming ``source``, the field and the reason: not a mapping, unknown or
            missing key, a value that is not a number, a scaling outside 0.5 … 2, a cross-talk
            beyond ±1 rad/m or not finite, a negative or infinite uncertainty.
    """
    if not isinstance(data, dict):
        msg = f"{source}: a factors file must be a mapping, got {type(data).__name__}"
        raise ConfigError(msg)
    body = {k: v for k, v in data.items() if k != "uncertainty"}
    factors = factors_from_layout(body, source)
    if "uncertainty" not in data:
        return FactorsFile(factors)
    unc = data["uncertainty"]
    if not isinstance(unc, dict):
        msg = f"{source}: field 'uncertainty': expected a mapping of scale and crosstalk_rad_per_m"
        raise ConfigError(msg)
    u_scales, u_cross = layout_values(unc, source, "uncertainty.")
    named = [
        (f"{f.yaml_section}.{f.yaml_key}", v)
        for f, v in zip(FACTORS, [*u_scales, *u_cross], strict=True)
    ]
    for where, v in named:
        if not (math.isnan(v) or 0.0 <= v < math.inf):
            msg = f"{source}: field 'uncertainty.{where}': {v} is not a standard deviation (>= 0, or .nan)"
            raise ConfigError(msg)
    return FactorsFile(factors, CorrectionFactors(*u_scales, *u_cross))


def read_factors(path: str | Path) -> FactorsFile:
    """Read and validate a ``factors.yaml``.

    Raises:
        ConfigError: the file cannot be read, is not valid YAML, or fails validation (one line
            naming the file, the field and the reason).
    """
    p = Path(path)
    return parse_factors(read_yaml(p, "factors file"), str(p))
