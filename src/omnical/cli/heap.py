"""How the C heap treats a command's large arrays (glibc's ``mallopt`` and ``malloc_trim``;
on another C library, nothing): a choice between memory given back and time.

By default glibc maps a block of 128 kB or more on its own, raises that threshold to the
largest mapped block freed (up to 32 MB), and gives the top of its heap back to the system
beyond twice that: arrays freed and allocated again, window after window, fault their pages
in again each time (system time).
"""

from __future__ import annotations

__all__ = ["give_back_freed_memory", "keep_freed_memory", "map_large_blocks"]

_M_TRIM_THRESHOLD = -1
"""glibc's ``M_TRIM_THRESHOLD`` (malloc.h)."""
_M_MMAP_THRESHOLD = -3
"""glibc's ``M_MMAP_THRESHOLD`` (malloc.h)."""
_MAX_MMAP_THRESHOLD = 32 * 1024 * 1024
"""The largest ``M_MMAP_THRESHOLD`` glibc takes on 64-bit (``HEAP_MAX_SIZE / 2``)."""
KEEP_BYTES = 1 << 30
"""Free memory at the heap's top kept, not given back (:func:`keep_freed_memory`)."""


def _mallopt(*settings: tuple[int, int]) -> None:
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError, TypeError):  # not glibc
        return
    for option, value in settings:
        mallopt(option, value)


def map_large_blocks(from_bytes: int) -> None:
    """Map every block of ``from_bytes`` or more on its own, returned whole when freed
    (memory given back, page faults paid): the peak of a long evaluation (see
    :mod:`omnical.cli.evaluate`)."""
    _mallopt((_M_MMAP_THRESHOLD, from_bytes))


def keep_freed_memory() -> None:
    """Take every block under 32 MB from the heap and keep what is freed there for the next
    ones (time saved, the process's memory not given back until it ends): ``omnical
    locate`` allocates and frees the same arrays a window at a time, in both its processes.
    On the 230,400-fix stress bag (``bench/bench_locate.py``) system time fell from 0.8–0.95
    to 0.40–0.48 s and wall from 3.06–3.35 to 2.89–3.01 s; on the 60-minute twin tour from
    2.24–2.42 to 1.98–2.11 s, its peak 75 → 78 MB."""
    _mallopt((_M_MMAP_THRESHOLD, _MAX_MMAP_THRESHOLD), (_M_TRIM_THRESHOLD, KEEP_BYTES))


def give_back_freed_memory() -> None:
    """Return the heap's free pages to the system now (``malloc_trim``)."""
    import ctypes

    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):  # not glibc
        return
    trim(0)
