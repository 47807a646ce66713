"""``omnical``: the typer app. One module per command; this one only assembles them.

It and the command modules import typer, the standard library and :mod:`omnical.choices` only;
everything else inside the command bodies (``bench/bench_startup.py`` measures it).
"""

from __future__ import annotations

from typing import Annotated

import typer

from omnical.cli import (
    calibrate,
    demo,
    evaluate,
    export,
    fleet,
    info,
    locate,
    map,
    monitor,
    navigate,
    plan,
    recover,
    ros2,
    run,
    seed003,
    simulate,
    sweep,
    twin,
)
from omnical.cli.errors import install_signal_handlers, stop_behind
from omnical.cli.help_layout import App

__all__ = ["app", "main"]

app = App(
    name="omnical",
    help="Kinematics, digital twin, indoor positioning and calibration for omnidirectional robots.",
    no_args_is_help=True,
    rich_markup_mode="markdown",
    pretty_exceptions_enable=False,
    add_completion=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _show_version(value: bool) -> None:
    if value:
        from importlib.metadata import version

        typer.echo(f"omnical {version('omnical')}")
        raise typer.Exit


@app.callback()
def _omnical(
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            help="Print omnical's version and exit.",
            callback=_show_version,
            is_eager=True,
        ),
    ] = False,
) -> None:
    """Kinematics, digital twin, indoor positioning and calibration for omnidirectional robots."""


app.command()(simulate.simulate)
app.command()(info.info)
app.command()(export.export)
app.command()(recover.recover)
app.command()(locate.locate)
app.command()(evaluate.evaluate)
app.command()(plan.plan)
app.command(name="map")(map.map_command)
app.command()(navigate.navigate)
app.add_typer(calibrate.app, name="calibrate")
app.command()(run.run)
app.add_typer(twin.app, name="twin")
app.add_typer(ros2.app, name="ros2")
app.command()(demo.demo)
app.command()(seed003.seed003)
app.add_typer(fleet.app, name="fleet")
app.command()(sweep.sweep)
app.command()(monitor.monitor)


def main() -> None:
    """Console-script entry point."""
    install_signal_handlers()
    try:
        app()
    except Exception as err:  # a stop before the command body, wrapped (said by _on_stop)
        stop = stop_behind(err)
        if stop is None:
            raise
        raise SystemExit(stop.code) from None


if __name__ == "__main__":
    main()
