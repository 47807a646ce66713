"""Recordings in memory: one columnar table per topic (:class:`Recording`), the canonical topics
and their columns (:mod:`.topics`), summaries. Bag files are :mod:`omnical.bags`."""
