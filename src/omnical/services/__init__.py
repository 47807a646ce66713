"""Services: experiments that run across the core and the twin, returning results (no files).

- :mod:`omnical.services.demo`: the whole story of seed 000 on the ``rosy-mecanum`` twin.
"""
