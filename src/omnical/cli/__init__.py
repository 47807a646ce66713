"""The command-line interface: one thin module per command over the library.

:mod:`~omnical.cli.main` assembles the typer app, :mod:`~omnical.cli.errors` maps failures to exit
statuses; the other modules are commands and the options and output they share.
"""
