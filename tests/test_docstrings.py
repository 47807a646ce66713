"""Module docstrings say what a module is and how to use it, in at most five lines.

History, measurements and reasoning belong in commit bodies and docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import ast
from fnmatch import fnmatchcase
from pathlib import Path

SRC = Path(__file__).parents[1] / "src"
MAX_LINES = 5

# Being reworked in session 11: remove an entry once its modules' docstrings are short.
# Patterns are fnmatch patterns over paths under src/ ("*" matches "/" too).
ALLOWED_LONGER: tuple[str, ...] = ()


def _modules() -> list[str]:
    return sorted(p.relative_to(SRC).as_posix() for p in (SRC / "omnical").rglob("*.py"))


def docstring_lines(source: str) -> int:
    """Source lines of a module's docstring, its quotes included; 0 without one."""
    body = ast.parse(source).body
    if not body:
        return 0
    first = body[0]
    if not (
        isinstance(first, ast.Expr)
        and isinstance(first.value, ast.Constant)
        and isinstance(first.value.value, str)
    ):
        return 0
    assert first.end_lineno is not None
    return first.end_lineno - first.lineno + 1


def test_docstring_lines_counts_the_quotes() -> None:
    assert docstring_lines('"""One line."""\n\nX = 1\n') == 1
    assert docstring_lines('"""Summary.\n\nUsage.\n"""\n') == 4
    assert docstring_lines("X = 1\n") == 0
    assert docstring_lines("") == 0


def test_the_allow_list_names_existing_modules() -> None:
    modules = _modules()
    stale = [p for p in ALLOWED_LONGER if not any(fnmatchcase(m, p) for m in modules)]
    assert not stale, f"allow-list entries that match no module: {stale}"


def test_module_docstrings_are_at_most_five_lines() -> None:
    too_long = []
    for module in _modules():
        if any(fnmatchcase(module, pattern) for pattern in ALLOWED_LONGER):
            continue
        lines = docstring_lines((SRC / module).read_text(encoding="utf-8"))
        if lines > MAX_LINES:
            too_long.append(f"{module}: {lines} lines")
    assert not too_long, (
        f"module docstrings longer than {MAX_LINES} lines (say what the module is and how to use "
        "it; move history, measurements and reasoning to docs/DESIGN-NOTES.md):\n"
        + "\n".join(too_long)
    )
