"""The report layer: the one Markdown writer, the report tables and every file a run leaves.

- :mod:`~omnical.reports.markdown`: sections, tables, figure links, ``report.md``.
- :mod:`~omnical.reports.tables`: seed 000 Tables 2 and 4, the §3.2 measures, iterations.
- :mod:`~omnical.reports.campaign`: the calibration campaign's directory.
- :mod:`~omnical.reports.demo`: the demo's directory.
- :mod:`~omnical.reports.figures`: the matplotlib figures (Agg), one module per subject.

Nothing below this layer writes a report or draws a figure.
"""
