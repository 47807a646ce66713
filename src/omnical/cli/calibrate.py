"""``omnical calibrate``: the seven correction factors (seed 000 Table 2), two ways.

``campaign`` runs seed 000's procedures on a robot (twin or serial) and writes ``DIR/``;
``estimate BAG...`` estimates them from recordings (``calibrate_campaign``, ``calibrate_estimate``).
"""

from __future__ import annotations

from omnical.cli.calibrate_campaign import campaign
from omnical.cli.calibrate_estimate import estimate
from omnical.cli.help_layout import App

__all__ = ["app", "campaign", "estimate"]

app = App(
    name="calibrate",
    help="Calibrate the seven correction factors: run the procedures on a robot (campaign) "
    "or estimate them from recordings (estimate).",
    no_args_is_help=True,
    rich_markup_mode="markdown",
    pretty_exceptions_enable=False,
    add_completion=False,
)
app.command()(campaign)
app.command()(estimate)
