"""The command-line interface: one thin module per command over the library.

:mod:`~omnical.cli.main` assembles the typer app from :mod:`~omnical.cli.simulate`,
:mod:`~omnical.cli.info`, :mod:`~omnical.cli.export`, :mod:`~omnical.cli.locate`,
:mod:`~omnical.cli.evaluate`, :mod:`~omnical.cli.calibrate` (``campaign`` and ``estimate``) and
:mod:`~omnical.cli.demo`. :mod:`~omnical.cli.errors` maps failures to exit statuses;
:mod:`~omnical.cli.output`, :mod:`~omnical.cli.options`, :mod:`~omnical.cli.progress` and
:mod:`~omnical.cli.calibrate_output` are shared helpers (the last two are heavy and imported only
when a command runs).
"""
