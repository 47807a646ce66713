"""The vocabulary of the seven correction factors of seed 000 (Table 2): one place for names.

:class:`Factor` gives each factor's field, kind, unit, label and YAML key: ``SCALE`` (ratio,
neutral 1, relative changes) or ``CROSSTALK`` (rad/m, neutral 0, differences); no prefix is parsed.
"""

from __future__ import annotations

import enum

__all__ = ["CROSSTALKS", "FACTORS", "SCALES", "Factor", "FactorKind"]


class FactorKind(enum.Enum):
    """Scaling (dimensionless, neutral 1) or cross-talk (rad/m, neutral 0)."""

    SCALE = "scale"
    CROSSTALK = "crosstalk"

    @property
    def neutral(self) -> float:
        """The value that corrects nothing: 1 for a scaling, 0 for a cross-talk."""
        return 1.0 if self is FactorKind.SCALE else 0.0

    @property
    def unit(self) -> str:
        """Unit of the value: ``""`` (dimensionless) or ``"rad/m"``."""
        return "" if self is FactorKind.SCALE else "rad/m"

    @property
    def yaml_section(self) -> str:
        """Section of the ``factors.yaml`` layout: ``scale`` or ``crosstalk_rad_per_m``."""
        return "scale" if self is FactorKind.SCALE else "crosstalk_rad_per_m"

    def change(self, old: float, new: float) -> float:
        """Change from ``old`` to ``new``: relative for a scaling, a difference for a cross-talk."""
        return new / old - 1.0 if self is FactorKind.SCALE else new - old


class Factor(enum.Enum):
    """One of the seven factors, in :class:`~omnical.kinematics.correction.CorrectionFactors`
    field order. The value is the field name."""

    SCALE_LONGITUDINAL = "scale_longitudinal"
    SCALE_LATERAL = "scale_lateral"
    SCALE_ROTATIONAL = "scale_rotational"
    CROSSTALK_FORWARD = "crosstalk_forward_rad_per_m"
    CROSSTALK_REVERSE = "crosstalk_reverse_rad_per_m"
    CROSSTALK_LEFT = "crosstalk_left_rad_per_m"
    CROSSTALK_RIGHT = "crosstalk_right_rad_per_m"

    @property
    def field(self) -> str:
        """Field name in :class:`~omnical.kinematics.correction.CorrectionFactors`."""
        return self.value

    @property
    def kind(self) -> FactorKind:
        """Scaling or cross-talk."""
        return _KIND[self]

    @property
    def is_scale(self) -> bool:
        """True for the three scalings."""
        return self.kind is FactorKind.SCALE

    @property
    def unit(self) -> str:
        """Unit of the value (``""`` for a scaling, ``"rad/m"`` for a cross-talk)."""
        return self.kind.unit

    @property
    def neutral(self) -> float:
        """The value that corrects nothing."""
        return self.kind.neutral

    @property
    def yaml_section(self) -> str:
        """Section in the ``factors.yaml`` layout."""
        return self.kind.yaml_section

    @property
    def yaml_key(self) -> str:
        """Key inside the section (``longitudinal`` … ``right``)."""
        return _YAML_KEY[self]

    @property
    def key(self) -> str:
        """Short dotted name, as shown in tables: ``scale.longitudinal``, ``crosstalk.forward``."""
        return f"{self.kind.value}.{self.yaml_key}"

    @property
    def label(self) -> str:
        """Row label of seed 000 Table 2."""
        return _LABEL[self]

    @property
    def short(self) -> str:
        """Short column heading: ``k lon`` … ``c right``."""
        return _SHORT[self]

    def change(self, old: float, new: float) -> float:
        """Change from ``old`` to ``new`` (relative for a scaling, a difference for a cross-talk)."""
        return self.kind.change(old, new)

    @classmethod
    def from_field(cls, name: str) -> Factor:
        """The factor of a CorrectionFactors field name.

        Raises:
            ValueError: not a factor field.
        """
        return cls(name)


_KIND = {
    Factor.SCALE_LONGITUDINAL: FactorKind.SCALE,
    Factor.SCALE_LATERAL: FactorKind.SCALE,
    Factor.SCALE_ROTATIONAL: FactorKind.SCALE,
    Factor.CROSSTALK_FORWARD: FactorKind.CROSSTALK,
    Factor.CROSSTALK_REVERSE: FactorKind.CROSSTALK,
    Factor.CROSSTALK_LEFT: FactorKind.CROSSTALK,
    Factor.CROSSTALK_RIGHT: FactorKind.CROSSTALK,
}
_YAML_KEY = {
    Factor.SCALE_LONGITUDINAL: "longitudinal",
    Factor.SCALE_LATERAL: "lateral",
    Factor.SCALE_ROTATIONAL: "rotational",
    Factor.CROSSTALK_FORWARD: "forward",
    Factor.CROSSTALK_REVERSE: "reverse",
    Factor.CROSSTALK_LEFT: "left",
    Factor.CROSSTALK_RIGHT: "right",
}
_LABEL = {
    Factor.SCALE_LONGITUDINAL: "Longitudinal velocity",
    Factor.SCALE_LATERAL: "Lateral velocity",
    Factor.SCALE_ROTATIONAL: "Rotational velocity",
    Factor.CROSSTALK_FORWARD: "Longitudinal-forward velocity to rotational",
    Factor.CROSSTALK_REVERSE: "Longitudinal-reverse velocity to rotational",
    Factor.CROSSTALK_LEFT: "Lateral-left velocity to rotational",
    Factor.CROSSTALK_RIGHT: "Lateral-right velocity to rotational",
}
_SHORT = {
    Factor.SCALE_LONGITUDINAL: "k lon",
    Factor.SCALE_LATERAL: "k lat",
    Factor.SCALE_ROTATIONAL: "k rot",
    Factor.CROSSTALK_FORWARD: "c fwd",
    Factor.CROSSTALK_REVERSE: "c rev",
    Factor.CROSSTALK_LEFT: "c left",
    Factor.CROSSTALK_RIGHT: "c right",
}

FACTORS: tuple[Factor, ...] = tuple(Factor)
"""All seven, in field order."""
SCALES: tuple[Factor, ...] = tuple(f for f in Factor if f.is_scale)
"""The three scalings, in field order."""
CROSSTALKS: tuple[Factor, ...] = tuple(f for f in Factor if not f.is_scale)
"""The four cross-talks, in field order."""
