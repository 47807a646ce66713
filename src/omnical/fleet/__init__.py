"""Fleets and sweeps: many recordings or twin campaigns as pure jobs on an executor (local
processes or Dask), one row each, resumable (:mod:`omnical.fleet.recordings`, :mod:`.sweep`).
"""
