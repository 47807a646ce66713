"""Bag files: recordings as ROS bags (ROS 2 MCAP, ROS 1), exported as CSV and TUM.

``read_bag``/``write_bag`` for whole recordings, :class:`BagRecorder` for runs that flush as
they go, ``recover_bag`` for a run cut short, ``summarize_bag`` for counts from the index.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
    from omnical.bags.bag import bag_location, read_bag, write_bag
    from omnical.bags.baginfo import summarize_bag
    from omnical.bags.export import export_csv, export_tum
    from omnical.bags.recorder import BagRecorder
    from omnical.bags.recover import recover_bag

_EXPORTS: dict[str, str] = {
    "BagRecorder": "omnical.bags.recorder",
    "bag_location": "omnical.bags.bag",
    "export_csv": "omnical.bags.export",
    "export_tum": "omnical.bags.export",
    "read_bag": "omnical.bags.bag",
    "recover_bag": "omnical.bags.recover",
    "summarize_bag": "omnical.bags.baginfo",
    "write_bag": "omnical.bags.bag",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

__all__ = [
    "BagRecorder",
    "bag_location",
    "export_csv",
    "export_tum",
    "read_bag",
    "recover_bag",
    "summarize_bag",
    "write_bag",
]

__getattr__ = lazy_getattr(__name__, _EXPORTS)
