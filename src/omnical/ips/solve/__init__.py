"""Multilateration: positions from hedgehog–beacon distances, vectorised over fixes.

Methods ``lsq`` (Gauss–Newton), ``robust`` (plus NLOS rejection) and ``grid`` (seed 000's
1 mm search) all return :class:`Fixes`; :func:`locate_bursts` solves a whole recording.
"""
