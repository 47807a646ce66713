"""No module of omnical uses another module's private names (one leading underscore).

``from omnical.a.b import _name``, and ``omnical.a.b._name`` through an imported module, fail
here unless the module is the importing one. Private modules are fine (``omnical.twin._kernel``,
``omnical.ips.solve._kernels``): the rule is about the names a module keeps to itself.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

SRC = Path(__file__).parents[1] / "src"

# (importing module, module imported from, private name) tolerated for now, being removed in
# session 11. Empty: the last ones (services.hil_control's _hold, _MonoClock and _Recorder of
# services.hil) went with that module in 1390cfe.
ALLOWED: frozenset[tuple[str, str, str]] = frozenset()


def is_private(name: str) -> bool:
    """A leading underscore, not a dunder (``__all__``, ``__version__``)."""
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _is_module(dotted: str) -> bool:
    """Whether ``dotted`` names a module or package under src/."""
    base = SRC.joinpath(*dotted.split("."))
    return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()


def _absolute(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    """The module a ``from ... import`` reads from, relative imports resolved."""
    if not node.level:
        return node.module or ""
    parts = module.split(".") if is_package else module.split(".")[:-1]
    parts = parts[: len(parts) - (node.level - 1)]
    return ".".join([*parts, *([node.module] if node.module else [])])


def _dotted(node: ast.expr) -> list[str] | None:
    """``a.b.c`` as ``["a", "b", "c"]``; None for anything but names and attributes."""
    names: list[str] = []
    while isinstance(node, ast.Attribute):
        names.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    return [node.id, *reversed(names)]


def private_uses(source: str, module: str, is_package: bool = False) -> list[tuple[str, str, int]]:
    """Every ``(module, private name, line)`` that ``module``'s ``source`` takes from another
    omnical module: by ``from ... import``, or as an attribute of a module it imported."""
    tree = ast.parse(source)
    found: list[tuple[str, str, int]] = []
    bound: dict[str, str] = {}  # local name → the dotted module (or package prefix) it is
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            source_module = _absolute(node, module, is_package)
            if source_module.split(".")[0] != "omnical":
                continue
            for alias in node.names:
                dotted = f"{source_module}.{alias.name}"
                if _is_module(dotted):  # a submodule (private or not), not a name
                    bound[alias.asname or alias.name] = dotted
                elif is_private(alias.name) and source_module != module:
                    found.append((source_module, alias.name, node.lineno))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] != "omnical":
                    continue
                if alias.asname:
                    bound[alias.asname] = alias.name
                else:
                    bound[alias.name.split(".")[0]] = alias.name.split(".")[0]
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        names = _dotted(node)
        if names is None or names[0] not in bound:
            continue
        owner = bound[names[0]]
        for attr in names[1:-1]:  # down the chain of modules, to the module that owns the last
            if not _is_module(f"{owner}.{attr}"):
                break
            owner = f"{owner}.{attr}"
        else:
            last = names[-1]
            if is_private(last) and not _is_module(f"{owner}.{last}") and owner != module:
                found.append((owner, last, node.lineno))
    return found


def test_private_uses_finds_both_forms() -> None:
    source = (
        "import omnical.recording.topics\n"
        "import omnical.recording.topics as t\n"
        "from omnical.recording import topics\n"
        "from omnical.recording.topics import _BY_NAME, ODOM\n"
        "from . import _floats\n"
        "from omnical.recording.topics import _BY_TYPE as BY_TYPE\n"
        "a = omnical.recording.topics._SPECS\n"
        "b = t._BY_NAME, topics._floats, t.ODOM, t.__all__\n"
    )
    uses = private_uses(source, "omnical.recording.bag")
    assert sorted((m, n) for m, n, _ in uses) == [
        ("omnical.recording", "_floats"),
        ("omnical.recording.topics", "_BY_NAME"),
        ("omnical.recording.topics", "_BY_NAME"),
        ("omnical.recording.topics", "_BY_TYPE"),
        ("omnical.recording.topics", "_SPECS"),
        ("omnical.recording.topics", "_floats"),
    ]


def test_a_module_may_use_its_own_names_and_private_modules() -> None:
    source = (
        "from omnical.recording.topics import _BY_NAME\n"
        "from omnical._lazy import lazy_getattr\n"
        "from omnical.ips.solve import _kernels\n"
        "from omnical.ips.solve._kernels import gauss_newton\n"
        "import omnical.ips.solve._kernels\n"
        "x = omnical.ips.solve._kernels.solve, _kernels.solve\n"
    )
    assert private_uses(source, "omnical.recording.topics") == []


@functools.cache
def _all_uses() -> tuple[tuple[Path, str, str, str, int], ...]:
    """``(path, module, owner, name, line)`` of every private use in src/omnical (parsed once
    for the two tests below)."""
    uses = []
    for path in sorted((SRC / "omnical").rglob("*.py")):
        module = _module_name(path)
        source = path.read_text(encoding="utf-8")
        for owner, name, line in private_uses(source, module, path.name == "__init__.py"):
            uses.append((path, module, owner, name, line))
    return tuple(uses)


def test_no_module_uses_another_modules_private_names() -> None:
    offences = [
        f"{path.relative_to(SRC)}:{line}: {name} of {owner}"
        for path, module, owner, name, line in _all_uses()
        if (module, owner, name) not in ALLOWED
    ]
    assert not offences, (
        "private names used outside their module (make the name public where another module "
        "needs it, or move the code):\n" + "\n".join(offences)
    )


def test_the_allow_list_holds_only_uses_that_remain() -> None:
    remaining = {(module, owner, name) for _, module, owner, name, _ in _all_uses()}
    assert not ALLOWED - remaining, f"gone, remove from ALLOWED: {sorted(ALLOWED - remaining)}"
