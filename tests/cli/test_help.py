"""Issue 29: every ``--help`` reads well at 80 columns and wide, and ``info``'s table at 80.

Before: ``<bool>`` beside every flag, ``[0<=x<=9223372036854775807]`` beside ``--seed``,
``{run}`` in the usage lines, option names cut at 80 columns (``--tolerance-cros…``) and
Marvelmind's type names folded by ``info`` at 80–100 columns.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest
import typer.main
from rich.console import Console
from typer.testing import CliRunner

from omnical.cli import info
from omnical.cli.main import app

runner = CliRunner()


def _commands(command: object, path: tuple[str, ...]) -> Iterator[tuple[tuple[str, ...], object]]:
    """Every command and group under ``command``, by its words on the command line."""
    yield path, command
    for name, sub in getattr(command, "commands", {}).items():
        yield from _commands(sub, (*path, name))


COMMANDS = dict(_commands(typer.main.get_command(app), ()))


def _option_names(command: object) -> list[str]:
    return [
        name
        for param in getattr(command, "params", [])
        if not getattr(param, "hidden", False)
        for name in (*param.opts, *param.secondary_opts)
        if name.startswith("-")
    ]


@pytest.mark.parametrize("columns", [80, 120])
@pytest.mark.parametrize("path", list(COMMANDS), ids=lambda p: " ".join(p) or "omnical")
def test_help_reads_well(path: tuple[str, ...], columns: int) -> None:
    result = runner.invoke(app, [*path, "--help"], env={"COLUMNS": str(columns)})
    assert result.exit_code == 0, result.output
    text = result.output
    assert max(len(line) for line in text.splitlines()) <= columns
    assert "<bool>" not in text and "<str>" not in text and "<path>" not in text
    assert "9223372036854775807" not in text and "<=x<=" not in text
    (usage,) = [line for line in text.splitlines() if "Usage: omnical" in line]
    assert "{" not in usage and "}" not in usage
    words = set(re.split(r"[\s│╭╮╰╯─,]+", text))  # every option name whole, never "--name…"
    for name in [*_option_names(COMMANDS[path]), "--help", "-h"]:
        assert name in words, f"{name} cut or missing at {columns} columns:\n{text}"
    assert "…" not in text


def test_usage_and_arguments_read_as_users_write_them() -> None:
    usages = {
        ("run",): "omnical run [OPTIONS] SCRIPT",
        ("info",): "omnical info [OPTIONS] BAG",
        ("plan",): "omnical plan [OPTIONS] MAP",
        ("calibrate", "estimate"): "omnical calibrate estimate [OPTIONS] BAG...",
    }
    for path, usage in usages.items():
        assert usage in runner.invoke(app, [*path, "--help"]).output
    missing = runner.invoke(app, ["info"])
    assert missing.exit_code == 2 and "Missing argument 'BAG'" in missing.output


def test_flags_show_no_type_values_a_short_one_and_the_bounds_still_hold() -> None:
    text = runner.invoke(app, ["calibrate", "campaign", "--help"], env={"COLUMNS": "120"}).output
    assert re.search(r"--yes\s+-y\s+Do not ask", text)
    assert re.search(r"--out\s+-o\s+PATH\s", text) and re.search(r"--seed\s+INT\s", text)
    assert re.search(r"--method\s+METHOD\s", text) and "≥ 0" in text
    # the ranges are not shown, but still enforced
    for seed in ("-1", str(2**63)):
        refused = runner.invoke(app, ["seed003", "--seed", seed, "--out", "never"])
        assert refused.exit_code == 2 and "--seed" in refused.output


def test_version_and_short_help_are_kept() -> None:
    assert runner.invoke(app, ["--version"]).output.startswith("omnical ")
    text = runner.invoke(app, ["-h"], env={"COLUMNS": "80"}).output
    assert "--version" in text and "-h" in text and "<bool>" not in text


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("help")
    script = directory / "tiny.yaml"
    script.write_text("name: tiny\nsteps:\n  - hold: {duration_s: 0.2}\n", encoding="utf-8")
    out = directory / "run.mcap"
    result = runner.invoke(app, ["simulate", str(script), "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out


@pytest.mark.parametrize("columns", [80, 100, 160])
def test_info_keeps_type_names_whole(
    tiny_run: Path, columns: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On a terminal of 80–100 columns the type goes under the topic's name, whole."""
    terminal = Console(width=columns, force_terminal=True, color_system=None, soft_wrap=True)
    monkeypatch.setattr(info, "console", lambda: terminal)
    result = runner.invoke(app, ["info", str(tiny_run)])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert max(len(line) for line in lines) <= columns
    assert "…" not in result.output
    words = result.output.split()
    for msgtype in (
        "nav_msgs/Odometry",
        "marvelmind/BeaconPositionAddressed",
        "marvelmind/HedgePositionAngle",
        "geometry_msgs/Twist",
    ):
        assert msgtype in words, result.output
    for command in ("evaluate", "calibrate", "locate"):  # 'used by' wraps between words only
        assert command in words


@pytest.mark.parametrize("path", list(COMMANDS), ids=lambda p: " ".join(p) or "omnical")
def test_an_off_by_default_flag_has_no_negative_twin(path: tuple[str, ...]) -> None:
    """``--inscribed/--no-inscribed`` (plan) and ``--overwrite/--no-overwrite`` (navigate)
    where every other command has plain flags: a ``--no-`` form only for what is on by
    default (``--no-home``, ``--no-figures``)."""
    for param in getattr(COMMANDS[path], "params", []):
        if getattr(param, "secondary_opts", None):
            assert param.default is True, f"{' '.join(path)} {param.opts[0]}: off by default"
