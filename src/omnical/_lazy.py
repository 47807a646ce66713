"""Lazy package exports (PEP 562): a package names what it exports, and imports it on first use.

A package ``__init__`` lists ``_EXPORTS`` and repeats them under ``TYPE_CHECKING``; importing one
submodule then costs that submodule's imports only.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from importlib import import_module
from typing import Any

__all__ = ["lazy_getattr"]


def lazy_getattr(package: str, exports: Mapping[str, str]) -> Callable[[str], Any]:
    """The module ``__getattr__`` of ``package``: exported name → defining module, on first use.

    Raises (from the returned function):
        AttributeError: ``name`` is not exported.
    """
    namespace = import_module(package).__dict__

    def __getattr__(name: str) -> Any:  # noqa: N807 (the module hook's own name)
        module = exports.get(name)
        if module is None:
            msg = f"module {package!r} has no attribute {name!r}"
            raise AttributeError(msg)
        value = getattr(import_module(module), name)
        namespace[name] = value
        return value

    return __getattr__
