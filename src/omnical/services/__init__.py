"""Services: experiments that run across the core and the rigs, returning results (no files).

``demo`` (seed 000's story on the twin), ``hil`` (the serial rig), ``navigation``, ``seed003``,
``path_checks``; ``sources`` (a command's inputs), ``voice`` (what a command's work says).
"""
