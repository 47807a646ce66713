"""``tf2_msgs`` (the type of ``/tf``) built where it is missing: from its definition, shipped in
``interface_packages/tf2_msgs``, by ROS 2's own toolchain (ament_cmake, rosidl) from the
``[ros2]`` extra, into the venv's prefix beside the wheels' messages (a system ROS 2 has it).
:func:`build_tf2_msgs` does it; ``omnical ros2 build-tf2-msgs`` calls it.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

from omnical.errors import ConfigError

__all__ = [
    "BUILT_AGAINST",
    "TF2_MSGS_SOURCE",
    "build_tf2_msgs",
    "check_tf2_msgs_loads",
    "tf2_msgs_installed",
    "tf2_msgs_stale",
]

TF2_MSGS_SOURCE = Path(__file__).parent / "interface_packages" / "tf2_msgs"
"""The interface package: ``msg/TFMessage.msg``, its ``package.xml`` and ``CMakeLists.txt``."""

BUILT_AGAINST = (
    "ros-rclpy",
    "ros-geometry-msgs",
    "ros-rosidl-runtime-c",
    "ros-rosidl-typesupport-fastrtps-c",
    "ros-rosidl-generator-py",
    "ros-fastcdr",
)
"""The wheels whose versions the compiled ``tf2_msgs`` depends on: recorded at the build
(``share/tf2_msgs/omnical-built-against``), compared by :func:`tf2_msgs_stale`."""

_STAMP = Path("share") / "tf2_msgs" / "omnical-built-against"
_BUILD_TOOLS = "pip install 'omnical[ros2]' (it brings ament_cmake, rosidl and cmake)"
_COMPILERS = (
    "C and C++ compilers and the Python headers to build tf2_msgs: install them "
    "(Debian: g++ python3-dev)"
)


def tf2_msgs_installed() -> bool:
    """Whether a ``tf2_msgs`` Python package can be found (without importing it)."""
    try:
        return importlib.util.find_spec("tf2_msgs") is not None
    except (ImportError, ValueError):
        return False


def _versions() -> dict[str, str]:
    """The installed versions of :data:`BUILT_AGAINST` ("-" where one is missing)."""
    found = {}
    for name in BUILT_AGAINST:
        try:
            found[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            found[name] = "-"
    return found


def tf2_msgs_stale(prefix: Path | None = None) -> str | None:
    """What changed since ``tf2_msgs`` was built into ``prefix`` (default: this environment's),
    e.g. ``"ros-rclpy 7.1.5 → 7.1.6"``; None when nothing did, or when ``prefix`` holds no
    ``tf2_msgs`` (a system ROS 2's is elsewhere)."""
    root = Path(sys.prefix if prefix is None else prefix)
    if not (root / "share" / "tf2_msgs").is_dir():
        return None
    try:
        lines = (root / _STAMP).read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return "built before omnical recorded the wheels' versions"
    built = dict(line.split("==", 1) for line in lines if "==" in line)
    now = _versions()
    changed = [f"{n} {built.get(n, '-')} → {v}" for n, v in now.items() if built.get(n, "-") != v]
    return ", ".join(changed) or None


def check_tf2_msgs_loads() -> None:
    """Import ``tf2_msgs`` and load its compiled type support, as a publisher does (the import
    alone loads Python only).

    Raises:
        ConfigError: it does not load (one line: the loader's reason).
    """
    importlib.invalidate_caches()
    try:
        from rclpy.type_support import check_for_type_support
        from tf2_msgs.msg import TFMessage

        check_for_type_support(TFMessage)
    except (ImportError, OSError) as err:
        first = str(err).splitlines()[0] if str(err) else type(err).__name__
        msg = f"tf2_msgs was built but does not load: {first}"
        raise ConfigError(msg) from None


def build_tf2_msgs(
    prefix: Path | None = None, *, say: Callable[[str], None] = lambda _: None
) -> Path:
    """Build ``tf2_msgs`` and install it into ``prefix`` (default: this environment's).

    ``prefix`` must hold the ROS 2 wheels' messages and build tools (``share/geometry_msgs``,
    ``share/rosidl_default_generators``): a venv (a ``--user`` install has none of them in
    ``sys.prefix``). The package is installed into a staging folder and copied beside them
    (``lib/``, ``share/``, ``site-packages/tf2_msgs``) only once every step succeeded, with
    the versions of :data:`BUILT_AGAINST` (:func:`tf2_msgs_stale`). Returns the prefix.

    Raises:
        ConfigError: the build tools or the compilers are missing, or a step failed (its log
            kept and named).
    """
    prefix = Path(sys.prefix if prefix is None else prefix).absolute()
    for needed in ("geometry_msgs", "rosidl_default_generators", "ament_cmake"):
        if not (prefix / "share" / needed / "cmake").is_dir():
            msg = f"no {needed} in {prefix}: {_BUILD_TOOLS}"
            raise ConfigError(msg)
    bin_dir = Path(sys.executable).parent
    path = os.pathsep.join([str(bin_dir), *_entries(os.environ.get("PATH"))])
    cmake = shutil.which("cmake", path=path)
    if cmake is None:
        msg = f"cmake not found: {_BUILD_TOOLS}"
        raise ConfigError(msg)
    c = [os.environ.get("CC", "cc"), "gcc", "clang"]
    cxx = [os.environ.get("CXX", "c++"), "g++", "clang++"]
    if not any(shutil.which(x, path=path) for x in c) or not any(
        shutil.which(x, path=path) for x in cxx
    ):
        raise ConfigError(_COMPILERS)
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(
        [str(prefix), *_entries(env.get("AMENT_PREFIX_PATH"))]
    )
    env["PATH"] = path
    build = Path(tempfile.mkdtemp(prefix="omnical-tf2-msgs-"))
    stage = build / "stage"
    log = build / "build.log"
    steps = [
        [
            cmake, "-S", str(TF2_MSGS_SOURCE), "-B", str(build / "tree"),
            f"-DCMAKE_PREFIX_PATH={prefix}", f"-DCMAKE_INSTALL_PREFIX={prefix}",
            f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF",
        ],
        [cmake, "--build", str(build / "tree"), "-j", str(os.cpu_count() or 1)],
        [cmake, "--install", str(build / "tree")],  # under DESTDIR: the staging folder
    ]  # fmt: skip
    env["DESTDIR"] = str(stage)
    try:
        with log.open("w", encoding="utf-8") as out:
            for step, what in zip(steps, ("configuring", "compiling", "installing"), strict=True):
                say(f"tf2_msgs: {what}")
                out.write(f"$ {shlex.join(step)}\n")
                out.flush()
                done = subprocess.run(
                    step, stdout=out, stderr=subprocess.STDOUT, env=env, check=False
                )
                if done.returncode != 0:
                    msg = (
                        f"building tf2_msgs failed while {what} (exit {done.returncode}): see {log}"
                    )
                    raise ConfigError(msg)
    except BaseException as err:  # a failed step keeps its log; Ctrl-C leaves nothing behind
        if not isinstance(err, ConfigError):
            shutil.rmtree(build, ignore_errors=True)
        raise
    staged = stage / prefix.relative_to(prefix.anchor)
    (staged / _STAMP).parent.mkdir(parents=True, exist_ok=True)
    (staged / _STAMP).write_text(
        "".join(f"{n}=={v}\n" for n, v in _versions().items()), encoding="utf-8"
    )
    say("tf2_msgs: copying into the environment")
    _install_tree(staged, prefix)
    shutil.rmtree(build, ignore_errors=True)
    return prefix


def _install_tree(source: Path, target: Path) -> None:
    """Copy ``source``'s files into ``target``, each replacing its old copy by a rename (a new
    file, not the old one rewritten: a running ROS 2 process keeps the libraries it mapped)."""
    for folder, dirs, names in os.walk(source):  # links to folders are in dirs, not walked
        here = target / Path(folder).relative_to(source)
        here.mkdir(parents=True, exist_ok=True)
        for name in [*names, *(d for d in dirs if (Path(folder) / d).is_symlink())]:
            src, tmp = Path(folder) / name, here / f".{name}.omnical-new"
            tmp.unlink(missing_ok=True)
            if src.is_symlink():
                tmp.symlink_to(src.readlink())
            else:
                shutil.copy2(src, tmp)
            tmp.replace(here / name)


def _entries(value: str | None) -> list[str]:
    """The non-empty entries of a ``PATH``-like variable (an empty one means the current folder)."""
    return [p for p in (value or "").split(os.pathsep) if p]
