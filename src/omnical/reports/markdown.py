"""The one Markdown writer of omnical: headings, paragraphs, tables and figure links.

A report is a title and :class:`Section` s: paragraphs, :class:`MarkdownTable` s, relative
:class:`FigureLink` s, subsections; every report goes through :func:`write_markdown_report`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TypeAlias

from omnical.errors import RecordingError

__all__ = [
    "Block",
    "FigureLink",
    "MarkdownTable",
    "Section",
    "render_markdown",
    "write_markdown_report",
]


@dataclass(frozen=True)
class MarkdownTable:
    """A table: header cells, rows of cells (strings), an optional caption above, a note below.

    Args:
        header: column titles.
        rows: cells, each row as long as the header.
        caption: bold line above the table ("" for none).
        note: paragraph below the table ("" for none).
        align: per column ``l``, ``r`` or ``c``; default: first column left, others right.

    Raises:
        RecordingError: a row's length or an alignment code does not fit the header.
    """

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    caption: str = ""
    note: str = ""
    align: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "header", tuple(self.header))
        object.__setattr__(self, "rows", tuple(tuple(r) for r in self.rows))
        n = len(self.header)
        if n == 0:
            raise RecordingError("a Markdown table needs at least one column")
        for i, row in enumerate(self.rows):
            if len(row) != n:
                raise RecordingError(f"table row {i} has {len(row)} cells, the header {n}")
        if self.align is not None:
            object.__setattr__(self, "align", tuple(self.align))
            if len(self.align) != n or any(a not in ("l", "r", "c") for a in self.align):
                raise RecordingError(f"table alignment must be {n} codes of l, r, c")


@dataclass(frozen=True)
class FigureLink:
    """An image in the report.

    Args:
        path: the image file: absolute, or relative to the working directory (as the figure
            writers return it), or else to the report directory.
        caption: alternative text, also written in italics under the image.
    """

    path: Path
    caption: str = ""


@dataclass(frozen=True)
class Section:
    """A heading and its blocks.

    Args:
        heading: the heading text.
        blocks: paragraphs (str), tables, figure links and subsections, in order.
        level: heading level, 2 (``##``) for top-level sections; subsections go one deeper.
    """

    heading: str
    blocks: tuple[Block, ...] = ()
    level: int = 2

    def __post_init__(self) -> None:
        object.__setattr__(self, "blocks", tuple(self.blocks))
        if not 1 <= self.level <= 6:
            raise RecordingError(f"heading level must be 1..6, got {self.level}")


Block: TypeAlias = str | MarkdownTable | FigureLink | Section
"""What a section holds: a paragraph, a table, a figure or a subsection."""


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ").strip()


def _render_table(table: MarkdownTable) -> str:
    align = table.align or ("l",) + ("r",) * (len(table.header) - 1)
    rule = {"l": ":---", "r": "---:", "c": ":---:"}
    lines = []
    if table.caption:
        lines += [f"**{_cell(table.caption)}**", ""]
    lines.append("| " + " | ".join(_cell(h) for h in table.header) + " |")
    lines.append("| " + " | ".join(rule[a] for a in align) + " |")
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in table.rows]
    if table.note:
        lines += ["", table.note]
    return "\n".join(lines)


def _figure_file(path: Path, base_dir: Path) -> Path:
    """Where a figure is: an absolute path; a relative one as the caller made it (relative to
    the working directory, as the figure writers return them), else relative to the report."""
    if path.is_absolute():
        return path
    return path if path.is_file() else base_dir / path


def _render_figure(figure: FigureLink, base_dir: Path) -> str:
    target = _figure_file(figure.path, base_dir)
    if not target.is_file():
        raise RecordingError(f"figure {target} does not exist")
    rel = Path(os.path.relpath(target.resolve(), base_dir.resolve())).as_posix()
    alt = _cell(figure.caption).replace("]", ")").replace("[", "(")
    text = f"![{alt}]({rel})"
    return f"{text}\n\n*{_cell(figure.caption)}*" if figure.caption else text


def _render_section(section: Section, base_dir: Path, level: int) -> list[str]:
    parts = [f"{'#' * level} {section.heading.strip()}"]
    for block in section.blocks:
        if isinstance(block, Section):
            parts += _render_section(block, base_dir, min(6, max(block.level, level + 1)))
        elif isinstance(block, MarkdownTable):
            parts.append(_render_table(block))
        elif isinstance(block, FigureLink):
            parts.append(_render_figure(block, base_dir))
        else:
            parts.append(block.strip())
    return parts


def render_markdown(title: str, sections: Sequence[Section], *, base_dir: str | Path) -> str:
    """The Markdown text of a report; figure links are made relative to ``base_dir``.

    Raises:
        RecordingError: a figure file does not exist, or a table is malformed.
    """
    base = Path(base_dir)
    parts = [f"# {title.strip()}"]
    for section in sections:
        parts += _render_section(section, base, section.level)
    return "\n\n".join(parts) + "\n"


def write_markdown_report(
    out_dir: str | Path,
    title: str,
    sections: Sequence[Section],
    *,
    filename: str = "report.md",
) -> Path:
    """Write ``out_dir/filename`` (directory created if needed) and return its path.

    Raises:
        RecordingError: the file cannot be written, or a figure does not exist.
    """
    directory = Path(out_dir)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise RecordingError(
            f"{directory}: cannot create report directory: {err.strerror}"
        ) from None
    text = render_markdown(title, sections, base_dir=directory)
    path = directory / filename
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as err:
        raise RecordingError(f"{path}: cannot write report: {err.strerror}") from None
    return path
