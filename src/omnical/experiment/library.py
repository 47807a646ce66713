"""Built-in motion scripts shipped with omnical (``src/omnical/data/scripts/*.yaml``)."""

from __future__ import annotations

from importlib import resources
from typing import Any

import yaml

__all__ = ["builtin_script_data", "builtin_script_names"]

_PACKAGE = "omnical.data.scripts"


def builtin_script_names() -> list[str]:
    """Names usable in place of a script path."""
    root = resources.files(_PACKAGE)
    return sorted(p.name.removesuffix(".yaml") for p in root.iterdir() if p.name.endswith(".yaml"))


def builtin_script_data(name: str) -> Any:
    """The parsed YAML of a built-in script."""
    text = resources.files(_PACKAGE).joinpath(f"{name}.yaml").read_text(encoding="utf-8")
    return yaml.safe_load(text)
