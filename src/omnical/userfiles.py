"""Reading a user's text file (YAML, CSV) safely: one place for what a file may be.

Every user file omnical reads (robot, twin, motion script, beacon map, factors, reference CSV)
comes through :func:`read_text_file` (and :func:`read_yaml` for YAML), which turns every way a
file can be wrong into one :class:`~omnical.errors.ConfigError` naming the file and the reason:
missing, a directory, unreadable, larger than :data:`MAX_FILE_BYTES`, binary (a NUL byte) or
not UTF-8, invalid YAML (with line and column), nested deeper than :data:`MAX_NESTING`.
Values are validated afterwards by each file's own parser.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Final

import yaml

from omnical.errors import ConfigError

__all__ = ["MAX_FILE_BYTES", "MAX_NESTING", "read_text_file", "read_yaml"]

MAX_FILE_BYTES: Final = 16 * 1024 * 1024
"""Largest user file read (16 MiB): a robot or a script is a few kB, a reference CSV a few MB."""

MAX_NESTING: Final = 32
"""Deepest nesting of mappings and lists accepted in a YAML file (real files need 4–6)."""


def read_text_file(path: str | Path, what: str = "file") -> str:
    """The UTF-8 text of a user file.

    Args:
        path: the file.
        what: what the file should be, for messages ("robot file", "reference CSV").

    Raises:
        ConfigError: ``path: <reason>`` — missing, a directory, unreadable, too large, binary or
            not UTF-8.
    """
    p = Path(path)
    try:
        if p.is_dir():
            msg = f"{p}: is a directory, expected a {what}"
            raise ConfigError(msg)
        size = p.stat().st_size
        if size > MAX_FILE_BYTES:
            msg = f"{p}: {size} bytes is too large for a {what} (at most {MAX_FILE_BYTES})"
            raise ConfigError(msg)
        data = p.read_bytes()
    except OSError as err:
        msg = f"{p}: cannot read: {err.strerror or err}"
        raise ConfigError(msg) from None
    if b"\x00" in data:
        msg = f"{p}: not a text file (binary data), expected a {what}"
        raise ConfigError(msg)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        msg = f"{p}: not UTF-8 text (byte {err.start}), expected a {what}"
        raise ConfigError(msg) from None


def _depth(node: yaml.Node, limit: int) -> int:
    """Nesting depth of a composed YAML node, stopping once past ``limit``."""
    deepest, stack = 0, [(node, 1)]
    while stack:
        current, depth = stack.pop()
        deepest = max(deepest, depth)
        if deepest > limit:
            return deepest
        if isinstance(current, yaml.SequenceNode):
            stack += [(child, depth + 1) for child in current.value]
        elif isinstance(current, yaml.MappingNode):
            stack += [(v, depth + 1) for _, v in current.value]
    return deepest


def read_yaml(path: str | Path, what: str = "YAML file") -> Any:
    """The parsed YAML document of a user file (plain data: mappings, lists, scalars).

    Raises:
        ConfigError: as :func:`read_text_file`, invalid YAML (with its line and column), more
            than one document, or nesting deeper than :data:`MAX_NESTING`.
    """
    p = Path(path)
    text = read_text_file(p, what)
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
        if node is not None and _depth(node, MAX_NESTING) > MAX_NESTING:
            msg = f"{p}: nested deeper than {MAX_NESTING} levels, expected a {what}"
            raise ConfigError(msg)
        return yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(err, "problem", None) or "invalid YAML"
        msg = f"{p}: invalid YAML{where}: {problem}"
        raise ConfigError(msg) from None
    except RecursionError:
        msg = f"{p}: nested too deeply to read, expected a {what}"
        raise ConfigError(msg) from None
