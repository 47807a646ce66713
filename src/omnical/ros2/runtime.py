"""Importing rclpy: from the PyPI Jazzy wheels (their libraries put on the library path by one
re-execution of the command) or from a sourced system ROS 2; one line when neither is there.

Call :func:`ensure_ros_environment` first thing in a command body, then :func:`import_rclpy`.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

from omnical.errors import ConfigError

__all__ = [
    "INSTALL_HINT",
    "REEXEC_GUARD",
    "ensure_ros_environment",
    "import_rclpy",
    "library_path_line",
    "rclpy_available",
    "wheel_library_dirs",
]

INSTALL_HINT = (
    "ROS 2 is not installed: pip install 'omnical[ros2]' (x86-64 Linux), or source a ROS 2 "
    "install and make the venv with --system-site-packages"
)
REEXEC_GUARD = "OMNICAL_ROS2_LIBRARY_PATH_SET"
"""Set in the environment of the re-executed command (and the wheels' own bootstrap guard)."""
_WHEELS_GUARD = "_ROS_WHEELS_BOOTSTRAP_COMPLETE"


def rclpy_available() -> bool:
    """Whether an rclpy package can be found (without importing it)."""
    if "rclpy" in sys.modules:
        return sys.modules["rclpy"] is not None
    try:
        return importlib.util.find_spec("rclpy") is not None
    except (ImportError, ValueError):
        return False


def wheel_library_dirs() -> list[str]:
    """The shared-library folders of the PyPI ROS 2 wheels in this environment ([] without them).

    The wheels put the message libraries in ``<prefix>/lib`` and each C++ core library with its
    vendored dependencies in ``site-packages/ros_*.libs``.
    """
    prefix_lib = Path(sys.prefix) / "lib"
    if not any(prefix_lib.glob("librcl_interfaces__rosidl_typesupport_c.so")):
        return []
    dirs = [str(prefix_lib)]
    for entry in sys.path:
        if entry.endswith("site-packages") and Path(entry).is_dir():
            dirs.extend(str(p) for p in sorted(Path(entry).glob("ros_*.libs")) if p.is_dir())
    return dirs


def library_path_line(current: str | None = None) -> str | None:
    """The ``LD_LIBRARY_PATH`` a program using the PyPI wheels' rclpy needs: their folders
    (:func:`wheel_library_dirs`) before ``current`` (default: this process's); None without
    the wheels (a sourced ROS 2 sets its own). :class:`ConfigError` without rclpy at all."""
    if not rclpy_available():
        raise ConfigError(INSTALL_HINT)
    dirs = wheel_library_dirs()
    if not dirs:
        return None
    value = os.environ.get("LD_LIBRARY_PATH", "") if current is None else current
    present = [p for p in value.split(os.pathsep) if p]
    return os.pathsep.join([*dirs, *(p for p in present if p not in dirs)])


MAX_DOMAIN_ID = 232
"""The largest ROS_DOMAIN_ID whose DDS ports fit (ROS 2's "The ROS_DOMAIN_ID" concept page)."""


def check_domain_id(value: str | None) -> None:
    """Refuse a ``ROS_DOMAIN_ID`` that is not a whole number in 0..232 (unset or empty: 0).

    Raises:
        ConfigError: naming the variable and its value.
    """
    if value is None or value.strip() == "":
        return
    if not (value.strip().isdigit() and int(value) <= MAX_DOMAIN_ID):
        msg = f"ROS_DOMAIN_ID={value!r}: give a whole number from 0 to {MAX_DOMAIN_ID}"
        raise ConfigError(msg)


def ensure_ros_environment(*, reexec: bool = True) -> None:
    """Make the wheels' libraries loadable: re-execute this process once with them on
    ``LD_LIBRARY_PATH`` (the dynamic loader reads it only at start-up).

    Does nothing with a system ROS 2 (sourced: its paths are set) or when the paths are
    already there. Raises :class:`ConfigError` without rclpy, or when the paths are missing
    and ``reexec`` is False (a library caller: start the program through ``omnical``).
    """
    if not rclpy_available():
        raise ConfigError(INSTALL_HINT)
    check_domain_id(os.environ.get("ROS_DOMAIN_ID"))
    dirs = wheel_library_dirs()
    present = [p for p in os.environ.get("LD_LIBRARY_PATH", "").split(os.pathsep) if p]
    missing = [d for d in dirs if d not in present]
    if not missing:
        return
    if os.environ.get(REEXEC_GUARD) or not reexec:
        msg = (
            "the ROS 2 wheels' libraries are not on LD_LIBRARY_PATH: "
            f"export LD_LIBRARY_PATH={os.pathsep.join([*missing, *present])}"
        )
        raise ConfigError(msg)
    env = dict(os.environ)
    env["LD_LIBRARY_PATH"] = os.pathsep.join([*missing, *present])
    env[REEXEC_GUARD] = "1"
    env[_WHEELS_GUARD] = "1"
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    os.execve(sys.executable, sys.orig_argv, env)


def import_rclpy() -> ModuleType:
    """``rclpy``, imported; :class:`ConfigError` in one line when it cannot be."""
    if not rclpy_available():
        raise ConfigError(INSTALL_HINT)
    try:
        return importlib.import_module("rclpy")
    except ImportError as err:
        first = str(err).splitlines()[0] if str(err) else type(err).__name__
        msg = f"ROS 2's rclpy is installed but cannot be loaded: {first}"
        raise ConfigError(msg) from None
