"""``omnical calibrate``: the seven correction factors (seed 000 Table 2), two ways.

* ``omnical calibrate campaign --robot ROBOT --twin TWIN --out DIR`` runs seed 000's
  procedures (Figure 7) on a robot (its digital twin, or a real one over serial ports) and writes ``DIR/factors.yaml``,
  ``DIR/omnical_factors.h``, ``DIR/wheeltec_params.yaml``, ``DIR/report.md``,
  ``DIR/figures/*.png`` and ``DIR/recordings/*.mcap``.
* ``omnical calibrate estimate BAG... --robot ROBOT --out factors.yaml`` estimates the factors
  from recordings and writes ``factors.yaml`` with the C header and the ROS parameters beside it.

The commands live in :mod:`omnical.cli.calibrate_campaign` and
:mod:`omnical.cli.calibrate_estimate`; the tables are printed by :mod:`omnical.cli.calibrate_output`.
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
