"""Options shared by ``omnical calibrate campaign`` and ``omnical calibrate estimate``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.choices import EstimationMethod
from omnical.cli.options import choice_metavar

__all__ = ["BeaconMapOption", "Installed", "Method"]

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
