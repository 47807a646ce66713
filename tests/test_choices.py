"""Closed choices: one enum per choice, one parser, one error class, and the library agrees."""

from __future__ import annotations

import subprocess
import sys
from enum import StrEnum
from typing import get_args

import pytest

from omnical.choices import (
    AlignMode,
    EstimationMethod,
    ExportFormat,
    LocateMethod,
    choice_list,
    parse_choice,
)
from omnical.errors import ChoiceError, ConfigError, OmnicalError


@pytest.mark.parametrize("enum_type", [LocateMethod, AlignMode, EstimationMethod, ExportFormat])
def test_every_value_parses_to_its_member(enum_type: type[StrEnum]) -> None:
    for member in enum_type:
        parsed = parse_choice(enum_type, member.value, "--x")
        assert parsed is member
        assert parse_choice(enum_type, member, "--x") is member
        assert isinstance(parsed, str) and parsed == member.value


def test_unknown_value_is_one_line_naming_option_value_and_choices() -> None:
    with pytest.raises(ChoiceError) as info:
        parse_choice(LocateMethod, "foo", "--method")
    assert str(info.value) == "--method: unknown value 'foo'; choose robust, lsq or grid"
    assert isinstance(info.value, ConfigError) and isinstance(info.value, OmnicalError)
    assert isinstance(info.value, ValueError)


def test_matching_is_exact() -> None:
    with pytest.raises(ChoiceError, match="unknown value 'CSV'; choose csv or tum"):
        parse_choice(ExportFormat, "CSV", "--format")
    with pytest.raises(ChoiceError, match="unknown value ''"):
        parse_choice(AlignMode, "", "--align")


def test_choice_list() -> None:
    assert choice_list(AlignMode) == "none, origin or se2"
    assert choice_list(EstimationMethod) == "procedures or joint"


def _values(tp: object) -> set[str]:
    """The strings a library type admits: an enum's values, or a (union of) Literal's."""
    if isinstance(tp, type) and issubclass(tp, StrEnum):
        return {m.value for m in tp}
    args = get_args(tp)
    if not args:
        return {str(tp)}
    return set().union(*(_values(a) for a in args))


def test_library_types_admit_exactly_the_enum_values() -> None:
    from omnical.calibration import campaign
    from omnical.evaluation import alignment
    from omnical.ips.solve import locate

    assert _values(alignment.AlignMode) == {m.value for m in AlignMode}
    assert _values(campaign.EstimationMethod) == {m.value for m in EstimationMethod}
    assert _values(locate.Method) == {m.value for m in LocateMethod}


def test_importing_choices_stays_light() -> None:
    code = (
        "import sys, omnical.choices\n"
        "heavy = {'numpy', 'scipy', 'matplotlib', 'rosbags', 'typer', 'rich'} & set(sys.modules)\n"
        "print(sorted(heavy))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.strip() == "[]"
