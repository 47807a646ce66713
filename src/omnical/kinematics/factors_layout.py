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


def _section(
    source: str, where: str, data: Any, keys: tuple[str, ...], defaults: list[float] | None
) -> list[float]:
    if not isinstance(data, dict):
        msg = f"{source}: field '{where}': expected a mapping of {', '.join(keys)}, got {data!r}"
        raise ConfigError(msg)
    for key in data:
        if key not in keys:
            msg = f"{source}: field '{where}.{key}': unknown key, expected one of {', '.join(keys)}"
            raise ConfigError(msg)
    if defaults is None:
        for key in keys:
            if key not in data:
                msg = f"{source}: field '{where}.{key}': missing"
                raise ConfigError(msg)
        return [_value(source, f"{where}.{k}", data[k]) for k in keys]
    return [
        _value(source, f"{where}.{k}", data[k]) if k in data else d
        for k, d in zip(keys, defaults, strict=True)
    ]


def layout_values(
    data: Any, source: str, prefix: str = "", base: CorrectionFactors | None = None
) -> tuple[list[float], list[float]]:
    """The (scales, cross-talks) of a layout mapping, unvalidated beyond being numbers.

    Without ``base`` both sections and all their keys are required; with ``base`` the mapping
    overlays it (missing sections and keys keep the base's values).
    """
    if not isinstance(data, dict):
        msg = f"{source}: field '{prefix or '(top level)'}': expected a mapping of {', '.join(SECTIONS)}"
        raise ConfigError(msg)
    for key in data:
        if key not in SECTIONS:
            msg = f"{source}: field '{prefix}{key}': unknown key, expected one of {', '.join(SECTIONS)}"
            raise ConfigError(msg)
    base_scales = None if base is None else [float(v) for v in base.scales]
    base_cross = None if base is None else [float(v) for v in base.crosstalks_rad_per_m]
    if base is None:
        for key in SECTIONS:
            if key not in data:
                msg = f"{source}: field '{prefix}{key}': missing"
                raise ConfigError(msg)
    scales = (
        _section(source, f"{prefix}{_SCALE_SECTION}", data[_SCALE_SECTION], SCALE_KEYS, base_scales)
        if _SCALE_SECTION in data
        else list(base_scales or [])
    )
    cross = (
        _section(
            source,
            f"{prefix}{_CROSSTALK_SECTION}",
            data[_CROSSTALK_SECTION],
            CROSSTALK_KEYS,
            base_cross,
        )
        if _CROSSTALK_SECTION in data
        else list(base_cross or [])
    )
    return scales, cross


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
