"""Options shared by several commands, so that they read the same everywhere."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated, TypeAlias

import typer

from omnical.choices import AlignMode, EstimationMethod, LocateMethod

__all__ = [
    "Align",
    "BeaconMapOption",
    "Beacons",
    "EstimateMethod",
    "HedgeZ",
    "Installed",
    "LocateMethodOption",
    "Method",
    "NoSelfCalibration",
    "Robot",
    "Seed",
    "SigmaM",
    "choice_metavar",
    "twin_start_fix",
]

Robot: TypeAlias = Annotated[
    str, typer.Option(help="Robot preset (rosy-mecanum, omni-x) or robot YAML.")
]
Seed: TypeAlias = Annotated[
    int, typer.Option(min=0, max=2**63 - 1, help="Random seed ≥ 0 (same seed, same run).")
]
Beacons: TypeAlias = Annotated[
    Path | None, typer.Option(help="Beacon map YAML (default: seed 000 Table 3).")
]


def choice_metavar(enum_type: type[StrEnum]) -> str:
    """``METHOD`` for ``LocateMethod``: the metavar of an option taking one of ``enum_type``'s
    values, the last word of the enum's name in capitals, short enough to leave the help text
    room at 80 columns. The help text names the values.

    The option itself is a plain ``str`` validated by :func:`omnical.choices.parse_choice`
    in the command, so that a wrong value gets omnical's one-line message and exit status 2.
    """
    import re

    words = re.findall(r"[A-Z][a-z0-9]*", enum_type.__name__)
    return (words[-1] if words else enum_type.__name__).upper()


Overwrite = Annotated[
    bool,
    typer.Option(
        "--overwrite",
        help="Replace an earlier omnical output there (never files omnical did not write).",
    ),
]

# the options of locate and evaluate, and of calibrate estimate, that their fleet commands share

LocateMethodOption = Annotated[
    str,
    typer.Option(
        metavar=choice_metavar(LocateMethod),
        help="robust (least squares, NLOS ranges rejected), lsq (plain least squares) "
        "or grid (seed 000's 1 mm search).",
    ),
]
HedgeZ = Annotated[
    float | None,
    typer.Option(
        help="Hedgehog height, m (default: map, vendor, the beacons' plane if they are "
        "coplanar, else estimated).",
    ),
]
SigmaM = Annotated[
    float | None,
    typer.Option(help="Fix the range noise σ, m (default: learned from the recording)."),
]
NoSelfCalibration = Annotated[
    bool,
    typer.Option(
        "--no-self-calibration",
        help="Use the ranges as they are: no σ, bias or scale learned from the recording.",
    ),
]
Align = Annotated[
    str,
    typer.Option(
        metavar=choice_metavar(AlignMode),
        help="Alignment of every estimate but odometry (always aligned at its origin): "
        "none, origin or se2.",
    ),
]
EstimateMethod = Annotated[
    str | None,
    typer.Option(
        metavar=choice_metavar(EstimationMethod),
        help="procedures (seed 000, one factor group per manoeuvre, with the IPS) or joint "
        "(one least squares over all seven factors and the hedgehog offset); default joint "
        "with an external reference or without /cmd_vel, else procedures.",
    ),
]


# calibrate campaign and calibrate estimate

Method = Annotated[
    str,
    typer.Option(
        metavar=choice_metavar(EstimationMethod),
        help="procedures (seed 000, one factor group per manoeuvre) or joint (one least "
        "squares over all seven factors and the hedgehog offset).",
    ),
]
Installed = Annotated[
    Path | None,
    typer.Option(
        help="factors.yaml installed in the vehicle controller during the runs "
        "(campaign: at its start; estimate: default from the recordings' events, else identity)."
    ),
]
BeaconMapOption = Annotated[
    Path | None,
    typer.Option(help="Beacon map YAML (default: each recording's /beacons_pos_a)."),
]


def twin_start_fix(twin_spec: str) -> str:
    """How to give a twin (``--twin``: a preset or a file) a start out of the walls."""
    if twin_spec in {"default", "ideal"}:
        return "give --twin a file with a free start_pose_map"
    return "give a free start_pose_map in the --twin file"
