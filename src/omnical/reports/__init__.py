"""The report layer: the one Markdown writer, the report tables and every file a run leaves.

``markdown``, ``tables``, ``campaign``, ``demo``, ``navigation``, ``seed003``, ``tracking``,
``outputs``, ``figures`` (matplotlib, Agg); ``locate``, ``evaluate``, ``estimate`` (a single
command's work, shared with its fleet); nothing below this layer writes a report or a figure.
"""
