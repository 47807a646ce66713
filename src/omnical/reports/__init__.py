"""The report layer: the one Markdown writer, the report tables and every file a run leaves.

``markdown``, ``tables``, ``campaign``, ``demo``, ``navigation``, ``seed003``, ``tracking``,
``outputs``, ``figures`` (Agg); ``locate``, ``evaluate``, ``estimate`` (a command's work, also
its fleet's). Nothing below this layer writes a report or a figure."""
