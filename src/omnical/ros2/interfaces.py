"""``tf2_msgs`` (the type of ``/tf``) built where it is missing: from its definition, shipped in
``interfaces/tf2_msgs``, by ROS 2's own toolchain (ament_cmake, rosidl) from the ``[ros2]`` extra,
into this environment's prefix beside the wheels' messages (a system ROS 2 has the package).
:func:`build_tf2_msgs` does it; ``omnical ros2 build-tf2-msgs`` calls it.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

from omnical.errors import ConfigError

__all__ = ["TF2_MSGS_SOURCE", "build_tf2_msgs", "tf2_msgs_installed"]

TF2_MSGS_SOURCE = Path(__file__).parent / "interfaces" / "tf2_msgs"
"""The interface package: ``msg/TFMessage.msg``, its ``package.xml`` and ``CMakeLists.txt``."""

_BUILD_TOOLS = "pip install 'omnical[ros2]' (it brings ament_cmake, rosidl and cmake)"


def tf2_msgs_installed() -> bool:
    """Whether a ``tf2_msgs`` Python package can be found (without importing it)."""
    try:
        return importlib.util.find_spec("tf2_msgs") is not None
    except (ImportError, ValueError):
        return False


def build_tf2_msgs(
    prefix: Path | None = None, *, say: Callable[[str], None] = lambda _: None
) -> Path:
    """Build ``tf2_msgs`` and install it into ``prefix`` (default: this environment's).

    ``prefix`` must hold the ROS 2 wheels' messages and build tools (``share/geometry_msgs``,
    ``share/rosidl_default_generators``); the package lands beside them (``lib/``, ``share/``,
    ``site-packages/tf2_msgs``). Returns the prefix.

    Raises:
        ConfigError: the build tools or a C compiler are missing, or the build failed (its log
            kept and named).
    """
    prefix = Path(sys.prefix if prefix is None else prefix)
    for needed in ("geometry_msgs", "rosidl_default_generators", "ament_cmake"):
        if not (prefix / "share" / needed / "cmake").is_dir():
            msg = f"no {needed} in {prefix}: {_BUILD_TOOLS}"
            raise ConfigError(msg)
    bin_dir = Path(sys.executable).parent
    cmake = shutil.which("cmake", path=os.pathsep.join([str(bin_dir), os.environ.get("PATH", "")]))
    if cmake is None:
        msg = f"cmake not found: {_BUILD_TOOLS}"
        raise ConfigError(msg)
    if not any(shutil.which(cc) for cc in (os.environ.get("CC", "cc"), "gcc", "clang")):
        msg = "no C compiler (cc, gcc or clang) to build tf2_msgs: install one (Debian: gcc)"
        raise ConfigError(msg)
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(
        [str(prefix), *(p for p in env.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p)]
    )
    env["PATH"] = os.pathsep.join([str(bin_dir), env.get("PATH", "")])
    build = Path(tempfile.mkdtemp(prefix="omnical-tf2-msgs-"))
    log = build / "build.log"
    steps = [
        [
            cmake, "-S", str(TF2_MSGS_SOURCE), "-B", str(build / "tree"),
            f"-DCMAKE_PREFIX_PATH={prefix}", f"-DCMAKE_INSTALL_PREFIX={prefix}",
            f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF",
        ],
        [cmake, "--build", str(build / "tree"), "-j", str(os.cpu_count() or 1)],
        [cmake, "--install", str(build / "tree")],
    ]  # fmt: skip
    with log.open("w", encoding="utf-8") as out:
        for step, what in zip(steps, ("configuring", "compiling", "installing"), strict=True):
            say(f"tf2_msgs: {what}")
            out.write(f"$ {' '.join(step)}\n")
            out.flush()
            done = subprocess.run(step, stdout=out, stderr=subprocess.STDOUT, env=env, check=False)
            if done.returncode != 0:
                msg = f"building tf2_msgs failed while {what} (exit {done.returncode}): see {log}"
                raise ConfigError(msg)
    shutil.rmtree(build, ignore_errors=True)
    return prefix
