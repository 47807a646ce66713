"""The figures (matplotlib, Agg backend), one module per subject; imported lazily by the reports."""
