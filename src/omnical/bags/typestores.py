"""rosbags type stores with the Marvelmind message types registered.

From the ``.msg`` files in ``omnical/data/msg/`` (``marvelmind_nav`` v1.0.13 and
``marvelmind_ros2_msgs`` v1.0.2), over rosbags' ROS 1 Noetic and ROS 2 Humble stores.
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import cache
from importlib.resources import files
from typing import Any, Literal

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

__all__ = ["MARVELMIND_PACKAGES", "RosVersion", "complete_store", "typestore"]

RosVersion = Literal[1, 2]

MARVELMIND_PACKAGES: dict[int, str] = {1: "marvelmind_nav", 2: "marvelmind_ros2_msgs"}
"""Name of the Marvelmind message package for each ROS version."""


@cache
def typestore(ros_version: RosVersion) -> Typestore:
    """The type store for ROS 1 (Noetic) or ROS 2 (Humble), Marvelmind types included.

    The store is built once per version and shared; treat it as read-only.
    """
    store = get_typestore(Stores.ROS1_NOETIC if ros_version == 1 else Stores.ROS2_HUMBLE)
    package = MARVELMIND_PACKAGES[ros_version]
    folder = files("omnical").joinpath("data", "msg", package)
    for entry in sorted(folder.iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".msg"):
            name = f"{package}/msg/{entry.name.removesuffix('.msg')}"
            store.register(get_types_from_msg(entry.read_text(encoding="utf-8"), name))
    return store


def complete_store(store: Typestore, msgtypes: Iterable[str], ros_version: RosVersion) -> None:
    """Register in ``store`` the types it lacks (and their dependencies) from :func:`typestore`
    (a bag may embed some definitions or, as ROS 2 Humble bags, none)."""
    ours = typestore(ros_version)
    missing: dict[str, Any] = {}

    def need(name: str) -> None:
        if name in store.fielddefs or name in missing or name not in ours.fielddefs:
            return
        missing[name] = ours.fielddefs[name]
        for _, (nodetype, field_desc) in ours.fielddefs[name][1]:
            desc: Any = field_desc
            if nodetype == Nodetype.NAME:
                need(desc)
            elif nodetype in {Nodetype.ARRAY, Nodetype.SEQUENCE} and desc[0][0] == Nodetype.NAME:
                need(desc[0][1])

    for msgtype in msgtypes:
        need(msgtype)
    if missing:
        store.register(missing)
