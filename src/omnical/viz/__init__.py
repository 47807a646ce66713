"""Figures (matplotlib, Agg backend): kept at the edge, imported only by the CLI and reports."""
