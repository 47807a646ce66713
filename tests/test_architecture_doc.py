"""docs/ARCHITECTURE.md matches the tree: every module, package and path it names exists.

Checked: dotted names (``omnical.bags.bag``, ``control.loop.run_controller``: the module,
and the first name after it defined or exported there), ``.py`` paths (``twin/closed_loop.py``,
``services/hil.py::SerialRig``), and the Layout block, whose package entries list their modules
by name (prose in parentheses, or before a colon) and must cover every package.
"""

from __future__ import annotations

import ast
import re
from functools import cache
from pathlib import Path

ROOT = Path(__file__).parents[1]
SRC = ROOT / "src"
PACKAGE = SRC / "omnical"
DOC = ROOT / "docs" / "ARCHITECTURE.md"

TOP_LEVEL = frozenset(
    p.stem if p.is_file() else p.name
    for p in PACKAGE.iterdir()
    if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").is_file()
)
DOTTED = re.compile(r"(?<![\w./-])(?:omnical\.)?([a-z_][a-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)+)")
PY_PATH = re.compile(r"(?<![\w./-])((?:[\w.-]+/)*[\w-]+\.py)(?:::([A-Za-z_]\w*))?")
ENTRY = re.compile(r"^  (\S+)\s+(.*)$")
CONTINUATION = re.compile(r"^ {4,}(\S.*)$")


def _text() -> str:
    return DOC.read_text(encoding="utf-8")


def _module_file(dotted: str) -> Path | None:
    """The file of module ``omnical.<dotted>``, or None."""
    base = PACKAGE.joinpath(*dotted.split("."))
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


@cache
def _names(path: Path) -> frozenset[str]:
    """Names a module defines, imports or exports lazily (``_EXPORTS``), at module level."""
    names: set[str] = set()
    body = list(ast.parse(path.read_text(encoding="utf-8")).body)
    while body:
        node = body.pop()
        if isinstance(node, ast.If | ast.Try):
            body.extend(node.body + node.orelse)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Import | ast.ImportFrom):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update(t.id for t in targets if isinstance(t, ast.Name))
            is_exports = any(isinstance(t, ast.Name) and t.id == "_EXPORTS" for t in targets)
            if is_exports and isinstance(node.value, ast.Dict):
                names.update(
                    k.value
                    for k in node.value.keys
                    if isinstance(k, ast.Constant) and isinstance(k.value, str)
                )
    return frozenset(names)


def resolve_dotted(dotted: str) -> str | None:
    """None when ``omnical.<dotted>`` names a module, or a name in one; else what is missing."""
    parts = dotted.split(".")
    for end in range(len(parts), 0, -1):
        module = _module_file(".".join(parts[:end]))
        if module is None:
            continue
        if end == len(parts) or parts[end] in _names(module):
            return None
        return f"{'.'.join(parts[:end])} has no {parts[end]}"
    return f"no module omnical.{parts[0]}"


def resolve_path(path: str, name: str | None) -> str | None:
    """None when a ``.py`` path (from the repository, src/ or src/omnical/) exists."""
    for base in (ROOT, SRC, PACKAGE):
        candidate = base / path
        if candidate.is_file():
            if name is not None and name not in _names(candidate):
                return f"{path} has no {name}"
            return None
    return f"no file {path}"


def layout_entries() -> dict[str, list[str]]:
    """The Layout block: entry (``errors.py``, ``ips/solve/``) → the text beside it."""
    section = _text().split("## Layout", 1)[1]
    block = section.split("```", 2)[1]
    entries: dict[str, list[str]] = {}
    current: list[str] | None = None
    for line in block.splitlines():
        if (match := ENTRY.match(line)) is not None:
            current = entries.setdefault(match.group(1), [])
            current.append(match.group(2))
        elif (match := CONTINUATION.match(line)) is not None and current is not None:
            current.append(match.group(1))
    return entries


def listed_modules(text: str) -> list[str]:
    """The module names of a package entry: prose in parentheses or before a colon left out."""
    depth, kept = 0, []
    for char in text:
        depth += char == "("
        if depth == 0:
            kept.append(char)
        depth -= char == ")" and depth > 0
    items = re.split(r"[,;]", "".join(kept))
    return [item.rsplit(":", 1)[-1].strip() for item in items if item.strip()]


def test_dotted_names_exist() -> None:
    text = _text()
    checked = {
        m for m in DOTTED.findall(text) if m.split(".")[0] in TOP_LEVEL and not m.endswith(".py")
    }
    assert checked, "no dotted omnical name found: is the pattern still right?"
    missing = sorted(f"{name}: {why}" for name in checked if (why := resolve_dotted(name)))
    assert not missing, "ARCHITECTURE.md names what does not exist:\n" + "\n".join(missing)


def test_paths_exist() -> None:
    found = PY_PATH.findall(_text())
    assert found, "no .py path found: is the pattern still right?"
    missing = sorted({why for path, name in found if (why := resolve_path(path, name or None))})
    assert not missing, "ARCHITECTURE.md names files that do not exist:\n" + "\n".join(missing)


def test_layout_modules_exist() -> None:
    missing = []
    for entry, lines in layout_entries().items():
        target = PACKAGE / entry
        if entry.endswith(".py"):
            if not target.is_file():
                missing.append(entry)
            continue
        if not (target / "__init__.py").is_file():
            missing.append(entry)
            continue
        if entry == "data/":
            continue  # shipped files, no modules
        for name in listed_modules(" ".join(lines)):
            if not re.fullmatch(r"[A-Za-z_]\w*", name):
                missing.append(f"{entry}: '{name}' is not a module name")
            elif not (
                (target / f"{name}.py").is_file() or (target / name / "__init__.py").is_file()
            ):
                missing.append(f"{entry}{name}")
    assert not missing, (
        "the Layout of ARCHITECTURE.md names what is not in the tree:\n" + "\n".join(missing)
    )


def test_layout_lists_every_package() -> None:
    entries = set(layout_entries())
    packages = {
        p.parent.relative_to(PACKAGE).as_posix() + "/"
        for p in PACKAGE.rglob("__init__.py")
        if p.parent != PACKAGE and "data" not in p.relative_to(PACKAGE).parts
    }
    assert "data/" in entries
    unlisted = sorted(packages - entries)
    assert not unlisted, f"packages missing from the Layout of ARCHITECTURE.md: {unlisted}"


def test_the_checks_catch_a_wrong_name() -> None:
    assert resolve_dotted("bags.bag.read_bag") is None
    assert resolve_dotted("bags.bag") is None
    assert resolve_dotted("bags.bag.no_such_name") is not None
    assert resolve_dotted("recording.no_such_module") is not None
    assert resolve_path("twin/closed_loop.py", None) is None
    assert resolve_path("src/omnical/errors.py", "OmnicalError") is None
    assert resolve_path("twin/no_such_module.py", None) is not None
    assert listed_modules("a (x, y: z), b; label: c") == ["a", "b", "c"]
