"""A small Markdown report writer: headings, tables, figure links, and seed 000 Table 4.

A report is a title and a sequence of :class:`Section` s; a section holds blocks — paragraphs
(plain strings), :class:`MarkdownTable` s, :class:`FigureLink` s and nested sections. Figure
links are written relative to the report's directory, so the directory can be moved or
published as a whole.

:func:`table4` lays out seed 000 Table 4 (RMSE of position, x and y for odometry and IPS,
uncalibrated vs calibrated kinematics) with the paper's numbers beside omnical's. The paper's
"position" row equals sqrt((x² + y²) / 2) of its own x and y rows in all four columns (see
:mod:`omnical.evaluation.metrics`), so the table compares that row with
:attr:`TrackingMetrics.rmse_per_axis_m` and shows the Euclidean RMSE (evo's APE) separately,
with the paper's value derived as sqrt(x² + y²) in parentheses.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Final, TypeAlias

from omnical.errors import RecordingError
from omnical.evaluation.metrics import IPS_KEY, ODOMETRY_KEY, TrackingMetrics

__all__ = [
    "PAPER_TABLE4",
    "Block",
    "FigureLink",
    "MarkdownTable",
    "Section",
    "render_markdown",
    "table4",
    "write_markdown_report",
]

Table4Numbers = Mapping[str, Mapping[str, tuple[float, float, float]]]

PAPER_TABLE4: Final[Table4Numbers] = MappingProxyType(
    {
        "uncalibrated": MappingProxyType(
            {ODOMETRY_KEY: (0.0083, 0.0089, 0.0076), IPS_KEY: (0.1119, 0.1518, 0.0445)}
        ),
        "calibrated": MappingProxyType(
            {ODOMETRY_KEY: (0.0085, 0.0086, 0.0083), IPS_KEY: (0.0171, 0.0168, 0.0173)}
        ),
    }
)
"""Seed 000 Table 4: kinematics → estimate → (position, x, y) RMSE in metres."""


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
        path: the image file: absolute, or relative to the report directory.
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


def _render_figure(figure: FigureLink, base_dir: Path) -> str:
    target = figure.path if figure.path.is_absolute() else base_dir / figure.path
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


def _m(value: float | None) -> str:
    return "—" if value is None else f"{value:.4f}"


def table4(
    metrics_before: Mapping[str, TrackingMetrics] | None,
    metrics_after: Mapping[str, TrackingMetrics] | None,
    paper: Table4Numbers | None = PAPER_TABLE4,
    *,
    ips_key: str = IPS_KEY,
) -> MarkdownTable:
    """Seed 000 Table 4, omnical's RMSE beside the paper's, uncalibrated vs calibrated.

    Rows: position as Table 4 defines it (sqrt((x² + y²) / 2)), x, y, and the Euclidean
    position RMSE (evo's APE; the paper's value derived as sqrt(x² + y²), in parentheses).
    Columns: for uncalibrated then calibrated kinematics, odometry and IPS, each "omnical" and,
    when ``paper`` is given, "paper".

    Args:
        metrics_before: estimate name → metrics with uncalibrated kinematics (None: "—").
        metrics_after: the same with calibrated kinematics (None: "—").
        paper: the paper's numbers (default :data:`PAPER_TABLE4`); None leaves them out.
        ips_key: which estimate fills the IPS columns (``ips`` = the vendor's fixes;
            ``multilateration`` for omnical's).
    """
    header = ["RMSE (m)"]
    Column = tuple[bool, TrackingMetrics | None, tuple[float, float, float] | None]
    columns: list[Column] = []  # (is the paper's, omnical's metrics, the paper's numbers)
    for phase, results in (("uncalibrated", metrics_before), ("calibrated", metrics_after)):
        for key, paper_key, label in (
            (ODOMETRY_KEY, ODOMETRY_KEY, "odometry"),
            (ips_key, IPS_KEY, "IPS"),
        ):
            header.append(f"{phase} {label}")
            columns.append((False, None if results is None else results.get(key), None))
            if paper is not None:
                header.append(f"{phase} {label} (paper)")
                columns.append((True, None, paper.get(phase, {}).get(paper_key)))

    def row(label: str, ours_of: str, paper_of: int | None) -> tuple[str, ...]:
        cells = [label]
        for is_paper, ours, theirs in columns:
            if not is_paper:
                cells.append(_m(None if ours is None else float(getattr(ours, ours_of))))
            elif theirs is None:
                cells.append("—")
            elif paper_of is None:
                cells.append(f"({(theirs[1] ** 2 + theirs[2] ** 2) ** 0.5:.4f})")
            else:
                cells.append(_m(theirs[paper_of]))
        return tuple(cells)

    rows = (
        row("position (Table 4: √((x²+y²)/2))", "rmse_per_axis_m", 0),
        row("x", "rmse_x_m", 1),
        row("y", "rmse_y_m", 2),
        row("position, Euclidean (evo APE)", "rmse_m", None),
    )
    note = (
        "Seed 000 Table 4's position row equals √((x²+y²)/2) of its x and y rows in every "
        "column; the Euclidean RMSE √(x²+y²) is evo's APE translation RMSE. Paper values in "
        "parentheses are derived from its x and y rows."
    )
    if paper is None:
        note = "The Euclidean RMSE √(x²+y²) is evo's APE translation RMSE."
    return MarkdownTable(
        tuple(header),
        rows,
        caption="Root-mean-squared trajectory tracking deviation (seed 000 Table 4)",
        note=note,
    )
