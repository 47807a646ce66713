"""Reading a user's text file (YAML, CSV) safely: one place for what a file may be.

A regular UTF-8 file of bounded size; YAML as plain data, no aliases, within :data:`MAX_NESTING`
levels and :data:`MAX_YAML_NODES` values. Each parser checks its values.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path
from typing import Any, Final, Protocol

import yaml

from omnical.errors import ConfigError

__all__ = [
    "MAX_FILE_BYTES",
    "MAX_NESTING",
    "MAX_YAML_NODES",
    "file_kind",
    "parse_yaml",
    "read_file_bytes",
    "read_text_file",
    "read_yaml",
]

MAX_FILE_BYTES: Final = 16 * 1024 * 1024
"""Largest user file read (16 MiB): a robot or a script is a few kB, a reference CSV a few MB."""

MAX_NESTING: Final = 32
"""Deepest nesting of mappings and lists accepted in a YAML file (real files need 4–6)."""

MAX_YAML_NODES: Final = 200_000
"""Most values (scalars, lists, mappings) in a YAML file: a robot or a map has fewer than 200, a
motion script of 10,000 steps about 60,000. It keeps reading a 16 MiB file to a second or two."""


class _Loader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """libyaml's parser where PyYAML has it (much faster), else PyYAML's own: the same data.

    A number with an exponent and no dot (``2e-2``) is a float, as in YAML 1.2 and ROS's
    ``map_server`` (yaml-cpp); PyYAML's YAML 1.1 reads it as the string "2e-2".
    """


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)
_LOADER: Final = _Loader

_KINDS: Final = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def file_kind(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is that is not a regular file: "a FIFO"…"""
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def read_file_bytes(path: str | Path, what: str = "file", limit: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a user file: a regular file of at most ``limit`` bytes.

    Opening does not block (a FIFO is refused before anyone writes to it) and at most ``limit``
    + 1 bytes are read, whatever the file claims its size is.

    Raises:
        ConfigError: ``path: <reason>`` — missing, unreadable, a directory (``is a directory``),
            a FIFO, a device or a socket (``is not a regular file``), larger than ``limit``.
    """
    p = Path(path)
    try:
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    except IsADirectoryError:
        msg = f"{p}: is a directory, expected a {what}"
        raise ConfigError(msg) from None
    except OSError as err:
        msg = f"{p}: cannot read: {err.strerror or err}"
        raise ConfigError(msg) from None
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):
            msg = f"{p}: is a directory, expected a {what}"
            raise ConfigError(msg)
        if not stat.S_ISREG(mode):
            msg = f"{p}: is not a regular file ({file_kind(mode)}), expected a {what}"
            raise ConfigError(msg)
        with os.fdopen(fd, "rb", closefd=False) as stream:
            data = stream.read(limit + 1)
    except OSError as err:
        msg = f"{p}: cannot read: {err.strerror or err}"
        raise ConfigError(msg) from None
    finally:
        os.close(fd)
    if len(data) > limit:
        msg = f"{p}: larger than {limit} bytes, too large for a {what}"
        raise ConfigError(msg)
    return data


def read_text_file(path: str | Path, what: str = "file") -> str:
    """The UTF-8 text of a user file (:func:`read_file_bytes`, at most :data:`MAX_FILE_BYTES`).

    Args:
        path: the file.
        what: what the file should be, for messages ("robot file", "reference CSV").

    Raises:
        ConfigError: ``path: <reason>`` — as :func:`read_file_bytes`, binary or not UTF-8.
    """
    p = Path(path)
    data = read_file_bytes(p, what)
    if b"\x00" in data:
        msg = f"{p}: not a text file (binary data), expected a {what}"
        raise ConfigError(msg)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        msg = f"{p}: not UTF-8 text (byte {err.start}), expected a {what}"
        raise ConfigError(msg) from None


class _Mark(Protocol):
    """Where in the text (PyYAML's and libyaml's marks alike), counted from 0."""

    line: int
    column: int


def _where(mark: _Mark | None) -> str:
    return f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""


def _check_events(text: str, source: str, what: str) -> None:
    """Walk the YAML events once (no data built): refuse an alias, a nesting deeper than
    :data:`MAX_NESTING` or more than :data:`MAX_YAML_NODES` values, at the first one."""
    depth = nodes = 0
    for event in yaml.parse(text, Loader=_LOADER):
        if isinstance(event, yaml.AliasEvent):
            msg = (
                f"{source}: YAML alias *{event.anchor}{_where(event.start_mark)}: aliases are "
                "not accepted (they can expand without bound); write the value out"
            )
            raise ConfigError(msg)
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > MAX_NESTING:
                msg = f"{source}: nested deeper than {MAX_NESTING} levels, expected a {what}"
                raise ConfigError(msg)
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1
        if isinstance(event, yaml.NodeEvent):
            nodes += 1
            if nodes > MAX_YAML_NODES:
                msg = (
                    f"{source}: more than {MAX_YAML_NODES} YAML values{_where(event.start_mark)}, "
                    f"too many for a {what}"
                )
                raise ConfigError(msg)


def parse_yaml(text: str, source: str, what: str = "YAML file") -> Any:
    """The YAML document of ``text`` as plain data (mappings, lists, scalars), guarded.

    Args:
        text: the YAML.
        source: where it came from, first in every message (a path, ``preset rosy-mecanum``).
        what: what it should be, for messages.

    Raises:
        ConfigError: ``source: <reason>`` — invalid YAML (with its line and column), more than
            one document, an alias, nesting deeper than :data:`MAX_NESTING`, more than
            :data:`MAX_YAML_NODES` values.
    """
    try:
        _check_events(text, source, what)
        return yaml.load(text, Loader=_LOADER)  # a safe loader; aliases refused above
    except yaml.YAMLError as err:
        problem = getattr(err, "problem", None) or "invalid YAML"
        if "nesting depth" in problem:  # libyaml's own limit (1000), met before ours
            msg = f"{source}: nested deeper than {MAX_NESTING} levels, expected a {what}"
            raise ConfigError(msg) from None
        msg = f"{source}: invalid YAML{_where(getattr(err, 'problem_mark', None))}: {problem}"
        raise ConfigError(msg) from None
    except RecursionError:
        msg = f"{source}: nested too deeply to read, expected a {what}"
        raise ConfigError(msg) from None


def read_yaml(path: str | Path, what: str = "YAML file", *, allow_empty: bool = False) -> Any:
    """The parsed YAML document of a user file (:func:`read_text_file`, then :func:`parse_yaml`);
    ``allow_empty``: an empty file (or comments only) is None, else refused.

    Raises:
        ConfigError: as :func:`read_text_file` and :func:`parse_yaml`; an empty file.
    """
    p = Path(path)
    document = parse_yaml(read_text_file(p, what), str(p), what)
    if document is None and not allow_empty:
        msg = f"{p}: empty (no YAML in it), expected a {what}"
        raise ConfigError(msg)
    return document
