"""The ``factors.yaml`` file: the seven correction factors, their 1σ and why any was held.

Layout: docs/DESIGN-NOTES.md. Numbers are written so that a round trip is exact; a bad field
raises a one-line :class:`ConfigError` naming the file, the field and the reason.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from omnical.errors import ConfigError
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import FACTORS, FactorKind
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
    "held_factors",
    "held_section",
    "parse_factors",
    "read_factors",
    "write_factors",
    "write_text",
    "yaml_number",
]


@dataclass(frozen=True)
class FactorsFile:
    """Contents of a ``factors.yaml``.

    Attributes:
        factors: the seven factors.
        uncertainty: one standard deviation per factor (NaN = not estimated), or None when the
            file has no ``uncertainty`` section.
        held: CorrectionFactors field name → why it was not estimated (kept at the installed
            value); empty when the file has no ``held`` section.
    """

    factors: CorrectionFactors
    uncertainty: CorrectionFactors | None = None
    held: Mapping[str, str] = field(default_factory=dict)


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


NOT_ESTIMATED = "not estimated"
"""The reason given to a held factor when only its ``.nan`` uncertainty says it was held."""


def held_factors(
    uncertainty: CorrectionFactors | None, held: Mapping[str, str] | None = None
) -> dict[str, str]:
    """Factor field name → reason, in field order: ``held``, else the NaN uncertainties.

    Raises:
        ConfigError: ``held`` names something that is not a factor.
    """
    names = [f.field for f in FACTORS]
    if held is not None:
        unknown = [k for k in held if k not in names]
        if unknown:
            msg = f"held factors: {', '.join(map(str, unknown))} are not factors"
            raise ConfigError(msg)
        return {n: str(held[n]) for n in names if n in held}
    if uncertainty is None:
        return {}
    return {n: NOT_ESTIMATED for n in names if math.isnan(float(getattr(uncertainty, n)))}


def factors_file_text(
    factors: CorrectionFactors,
    uncertainty: CorrectionFactors | None = None,
    comment: str = "",
    held: Mapping[str, str] | None = None,
) -> str:
    """The text of a ``factors.yaml`` (optionally headed by ``#`` comment lines).

    ``held`` (field name → reason) writes the ``held`` section; without it, the factors with a
    NaN uncertainty are marked ``"not estimated"``.
    """
    marked = held_factors(uncertainty, held)
    lines = [f"# {line}".rstrip() for line in comment.splitlines()]
    lines.append(f"scale: {_flow(SCALE_KEYS, factors.scales)}")
    lines.append(f"crosstalk_rad_per_m: {_flow(CROSSTALK_KEYS, factors.crosstalks_rad_per_m)}")
    if uncertainty is not None:
        lines.append("uncertainty:")
        lines.append(f"  scale: {_flow(SCALE_KEYS, uncertainty.scales)}")
        lines.append(
            f"  crosstalk_rad_per_m: {_flow(CROSSTALK_KEYS, uncertainty.crosstalks_rad_per_m)}"
        )
    if marked:
        lines.append("# held at the installed value: not supported by the recordings")
        lines += held_section(marked)
    return "\n".join(lines) + "\n"


def held_section(marked: Mapping[str, str], indent: str = "") -> list[str]:
    """The lines of a ``held`` YAML section (section → key → reason), ``held:`` at ``indent``."""
    lines = [f"{indent}held:"]
    for kind in (FactorKind.SCALE, FactorKind.CROSSTALK):
        items = [f for f in FACTORS if f.kind is kind and f.field in marked]
        if items:
            lines.append(f"{indent}  {kind.yaml_section}:")
            lines += [f"{indent}    {f.yaml_key}: {json.dumps(marked[f.field])}" for f in items]
    return lines


def write_factors(
    path: str | Path,
    factors: CorrectionFactors,
    uncertainty: CorrectionFactors | None = None,
    *,
    comment: str = "",
    held: Mapping[str, str] | None = None,
) -> Path:
    """Write ``factors.yaml`` (:func:`factors_file_text`, :func:`write_text`); returns the path."""
    return write_text(Path(path), factors_file_text(factors, uncertainty, comment, held))


def write_text(path: Path, text: str) -> Path:
    """Write ``text`` to ``path``, parent directories made (ConfigError if it cannot)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    except OSError as err:
        msg = f"{path}: cannot write: {err.strerror or err}"
        raise ConfigError(msg) from None
    return path


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
    body = {k: v for k, v in data.items() if k not in ("uncertainty", "held")}
    factors = factors_from_layout(body, source)
    held = _parse_held(data.get("held", {}), source)
    if "uncertainty" not in data:
        return FactorsFile(factors, None, held)
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
    return FactorsFile(factors, CorrectionFactors(*u_scales, *u_cross), held)


def _parse_held(data: Any, source: str) -> dict[str, str]:
    """The ``held`` section: section → key → reason (a string)."""
    if data is None:
        return {}
    if not isinstance(data, dict):
        msg = f"{source}: field 'held': expected a mapping of scale and crosstalk_rad_per_m"
        raise ConfigError(msg)
    by_place = {(f.yaml_section, f.yaml_key): f.field for f in FACTORS}
    sections = {f.yaml_section for f in FACTORS}
    out: dict[str, str] = {}
    for section, items in data.items():
        if section not in sections:
            msg = (
                f"{source}: field 'held.{section}': unknown key, expected one of "
                f"{', '.join(sorted(sections))}"
            )
            raise ConfigError(msg)
        if not isinstance(items, dict):
            msg = f"{source}: field 'held.{section}': expected a mapping of factor → reason"
            raise ConfigError(msg)
        for key, reason in items.items():
            if (section, key) not in by_place:
                keys = [k for s, k in by_place if s == section]
                msg = (
                    f"{source}: field 'held.{section}.{key}': unknown key, expected one of "
                    f"{', '.join(keys)}"
                )
                raise ConfigError(msg)
            if not isinstance(reason, str):
                msg = f"{source}: field 'held.{section}.{key}': expected a reason (text), got {reason!r}"
                raise ConfigError(msg)
            out[by_place[(section, key)]] = reason
    return {f.field: out[f.field] for f in FACTORS if f.field in out}


def read_factors(path: str | Path) -> FactorsFile:
    """Read and validate a ``factors.yaml``.

    Raises:
        ConfigError: the file cannot be read, is not valid YAML, or fails validation (one line
            naming the file, the field and the reason).
    """
    p = Path(path)
    return parse_factors(read_yaml(p, "factors file"), str(p))
