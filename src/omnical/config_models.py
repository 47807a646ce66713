"""The pydantic base of every user file's model: :class:`StrictModel`.

No unknown key, no NaN or infinity, and never ``true`` where a number is expected (pydantic's
lax mode would take it for 1); the robot, twin and motion-script files are read through it.
"""

from __future__ import annotations

from typing import get_args

from pydantic import BaseModel, ConfigDict, ValidationInfo, field_validator
from pydantic_core import PydanticCustomError

__all__ = ["StrictModel"]


def _numeric(annotation: object) -> bool:
    """``annotation`` takes a number (``float``, ``int``: alone, optional, or inside)."""
    return annotation in (float, int) or any(_numeric(a) for a in get_args(annotation))


def _has_bool(value: object) -> bool:
    if isinstance(value, bool):
        return True
    if isinstance(value, list | tuple):
        return any(_has_bool(v) for v in value)
    if isinstance(value, dict):
        return any(_has_bool(v) for v in value.values())
    return False


class StrictModel(BaseModel):
    """A user file's model: extra keys and non-finite numbers refused, booleans not numbers."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    @field_validator("*", mode="before")
    @classmethod
    def _no_bool(cls, value: object, info: ValidationInfo) -> object:
        field = cls.model_fields.get(info.field_name or "")
        if field is not None and _numeric(field.annotation) and _has_bool(value):
            raise PydanticCustomError("bool_not_number", "expected a number, got a boolean")
        return value
