"""The ``factors.yaml`` layout of the seven correction factors, as plain mappings.

``scale: {longitudinal, lateral, rotational}``, ``crosstalk_rad_per_m: {forward, reverse, left,
right}``: one parser for every reader; file I/O is in :mod:`omnical.calibration.factors_io`.
"""

from __future__ import annotations

from typing import Any

from omnical.errors import ConfigError
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import CROSSTALKS, SCALES, FactorKind

__all__ = ["CROSSTALK_KEYS", "SCALE_KEYS", "SECTIONS", "factors_from_layout", "layout_values"]

SCALE_KEYS: tuple[str, ...] = tuple(f.yaml_key for f in SCALES)
"""Keys of the ``scale`` section, in CorrectionFactors field order."""
CROSSTALK_KEYS: tuple[str, ...] = tuple(f.yaml_key for f in CROSSTALKS)
"""Keys of the ``crosstalk_rad_per_m`` section, in CorrectionFactors field order."""
_SCALE_SECTION = FactorKind.SCALE.yaml_section
_CROSSTALK_SECTION = FactorKind.CROSSTALK.yaml_section
SECTIONS: tuple[str, ...] = (_SCALE_SECTION, _CROSSTALK_SECTION)
"""The two sections of the layout, scalings first."""

_SCALE_RANGE = (0.5, 2.0)
_MAX_CROSSTALK_RAD_PER_M = 1.0


def _value(source: str, where: str, value: Any) -> float:
    if isinstance(value, bool) or value is None:
        msg = f"{source}: field '{where}': expected a number, got {value!r}"
        raise ConfigError(msg)
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            pass
    msg = f"{source}: field '{where}': expected a number, got {value!r}"
    raise ConfigError(msg)


def _mapping(
    source: str, name: str, prefix: str, data: Any, keys: tuple[str, ...], required: bool
) -> dict[Any, Any]:
    """``data`` checked as a mapping (field ``name``) of ``keys`` (fields ``prefix + key``); a
    section's (``prefix`` is ``name.``) says what it got instead."""
    if not isinstance(data, dict):
        got = f", got {data!r}" if prefix == f"{name}." else ""
        msg = f"{source}: field '{name}': expected a mapping of {', '.join(keys)}{got}"
        raise ConfigError(msg)
    for key in data:
        if key not in keys:
            msg = f"{source}: field '{prefix}{key}': unknown key, expected one of {', '.join(keys)}"
            raise ConfigError(msg)
    for key in keys if required else ():
        if key not in data:
            msg = f"{source}: field '{prefix}{key}': missing"
            raise ConfigError(msg)
    return data


def layout_values(
    data: Any, source: str, prefix: str = "", base: CorrectionFactors | None = None
) -> tuple[list[float], list[float]]:
    """The (scales, cross-talks) of a layout mapping, unvalidated beyond being numbers.

    Without ``base`` both sections and all their keys are required; with ``base`` the mapping
    overlays it (missing sections and keys keep the base's values).
    """
    required = base is None
    top = _mapping(source, prefix or "(top level)", prefix, data, SECTIONS, required)
    base = base or CorrectionFactors()  # required: every value is given
    out: list[list[float]] = []
    for section, keys, defaults in (
        (_SCALE_SECTION, SCALE_KEYS, base.scales),
        (_CROSSTALK_SECTION, CROSSTALK_KEYS, base.crosstalks_rad_per_m),
    ):
        where = f"{prefix}{section}"
        part = _mapping(source, where, f"{where}.", top.get(section, {}), keys, required)
        given = {k: _value(source, f"{where}.{k}", part[k]) for k in keys if k in part}
        out.append([given.get(k, float(d)) for k, d in zip(keys, defaults, strict=True)])
    return out[0], out[1]


def factors_from_layout(
    data: Any, source: str, prefix: str = "", base: CorrectionFactors | None = None
) -> CorrectionFactors:
    """Validated correction factors from a layout mapping (optionally overlaying ``base``).

    Raises:
        ConfigError: naming ``source`` and the field: not a mapping, unknown or missing key, not
            a number, a scaling outside 0.5 … 2, a cross-talk beyond ±1 rad/m or not finite.
    """
    scales, cross = layout_values(data, source, prefix, base)
    lo, hi = _SCALE_RANGE
    for key, v in zip(SCALE_KEYS, scales, strict=True):
        if not lo < v < hi:
            msg = f"{source}: field '{prefix}{_SCALE_SECTION}.{key}': {v} is not a plausible scaling ({lo} … {hi})"
            raise ConfigError(msg)
    for key, v in zip(CROSSTALK_KEYS, cross, strict=True):
        if not abs(v) < _MAX_CROSSTALK_RAD_PER_M:
            msg = (
                f"{source}: field '{prefix}{_CROSSTALK_SECTION}.{key}': {v} is not a plausible "
                f"cross-talk (|c| < {_MAX_CROSSTALK_RAD_PER_M} rad/m)"
            )
            raise ConfigError(msg)
    return CorrectionFactors(*scales, *cross)
