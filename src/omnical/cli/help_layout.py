"""How every ``--help`` of omnical reads, set once for all commands.

:class:`App` (a :class:`typer.Typer`): flags without a type, values as ``PATH``, ``INT``, …, no
ranges, arguments as their metavar (``SCRIPT``); parsing and validation stay typer's.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import typer
from typer.core import TyperArgument, TyperCommand, TyperGroup, TyperOption
from typer.models import CommandFunctionType

_Context = Any
"""click's context, as typer's methods take it (typer vendors click: no public name for it)."""

__all__ = ["App", "Command", "Group"]

_SHORT_TYPES = {"str": "TEXT", "path": "PATH", "int": "INT", "float": "FLOAT"}


def _short_type(label: str) -> str:
    """``<int range>`` → ``INT``, ``<list[Path]>`` → ``PATH``, ``<str>`` → ``TEXT``."""
    label = label.strip("<>").removesuffix(" range")
    if label.startswith("list[") and label.endswith("]"):
        label = label[len("list[") : -1]
    return _SHORT_TYPES.get(label.lower(), label.upper())


class _Option(TyperOption):
    """A typer option whose help shows a short type, none for a flag, and no range."""

    def display_type_rich(self, ctx: _Context) -> str | None:
        if self.metavar is not None:
            return self.metavar
        if self.is_flag or self.count:
            return None
        return _short_type(self.display_type(ctx))

    def _get_number_range_help_str(self) -> str | None:
        return None


class _Argument(TyperArgument):
    """A typer argument shown as its metavar (``SCRIPT``) in the usage line and the help."""

    def display_type_rich(self, ctx: _Context) -> str | None:
        return None

    def get_usage_pieces(self, ctx: _Context) -> list[str]:
        name = self.display_name_raw
        if self.nargs != 1 and not name.endswith("..."):
            name += "..."
        return [name if self.required else f"[{name}]"]

    def _get_number_range_help_str(self) -> str | None:
        return None


def _adopt(param: Any) -> None:
    """Give ``param`` omnical's help display (its class, never its parsing or validation)."""
    if type(param) is TyperOption:
        param.__class__ = _Option
    elif type(param) is TyperArgument:
        param.__class__ = _Argument
        if param.metavar is None and param.name:
            param.metavar = param.name.upper()


class _Adopting:
    """Adopts every parameter of a command or group, its help option too (docs/DESIGN-NOTES.md)."""

    params: list[Any]

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        for param in self.params:
            _adopt(param)

    def get_help_option(self, ctx: _Context) -> TyperOption | None:
        option: TyperOption | None = super().get_help_option(ctx)  # type: ignore[misc]
        _adopt(option)
        return option


class Command(_Adopting, TyperCommand):
    """A typer command whose help reads well at 80 columns (docs/DESIGN-NOTES.md)."""


class Group(_Adopting, TyperGroup):
    """A typer group whose help reads well at 80 columns (docs/DESIGN-NOTES.md)."""


class App(typer.Typer):
    """A :class:`typer.Typer` whose groups are :class:`Group` and commands :class:`Command`."""

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("cls", Group)
        super().__init__(**kwargs)

    def command(
        self, name: str | None = None, **kwargs: Any
    ) -> Callable[[CommandFunctionType], CommandFunctionType]:
        kwargs.setdefault("cls", Command)
        return super().command(name, **kwargs)
