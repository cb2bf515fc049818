"""``lrauv ... --help`` is for users at every level of the command tree: what the command does, an example,
a word on every flag, nothing from the developers' docstrings, and no wider than 100 columns."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from planner.cli import build_parser
from planner.contract.columns import WIDTH

LRAUV = str(Path(sys.executable).parent / "lrauv")
DEVELOPER_MARKERS = ("``", ":func:", ":class:", "Returns", "Raises", "python -m", "docstring")
MODULE_PATH = re.compile(r"\b(planner|executive|vehicle_sim|tests)\.[a-z_]")  # e.g. planner.cli, not "executive."


def developer_text(text: str) -> list[str]:
    return [m for m in DEVELOPER_MARKERS if m in text] + MODULE_PATH.findall(text)


def parsers(parser: argparse.ArgumentParser, path: tuple[str, ...] = ("lrauv",)) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    """Every parser of the tree under ``parser``, named by its command line."""
    yield " ".join(path), parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from parsers(sub, (*path, name))


TREE = dict(parsers(build_parser()))


def test_the_tree_has_nested_commands():
    assert {"lrauv forecast synth", "lrauv log recover", "lrauv waypoints import", "lrauv sim"} <= set(TREE)


@pytest.mark.parametrize("command", sorted(set(TREE) - {"lrauv"}))
def test_every_command_says_what_it_does_with_an_example_and_no_developer_text(command, monkeypatch):
    parser = TREE[command]
    assert parser.description and parser.epilog and parser.epilog.startswith("example"), command
    assert f"\n  {command} " in "\n" + parser.epilog.split(":", 1)[1], parser.epilog  # the example runs this command
    for text in (parser.description, parser.epilog):
        assert developer_text(text) == [], text
    flags = [a for a in parser._actions if not isinstance(a, argparse._SubParsersAction)]
    assert [a.dest for a in flags if not a.help] == [], command
    monkeypatch.setenv("COLUMNS", "250")  # a wide terminal: help still fits in 100 columns
    text = parser.format_help()
    assert [line for line in text.splitlines() if len(line) > WIDTH] == [] and developer_text(text) == [], text


@pytest.mark.parametrize("argv", [["forecast", "synth"], ["log", "recover"], ["waypoints", "import"], ["sim"]])
def test_nested_help_exits_0_with_the_user_text(argv):
    proc = subprocess.run([LRAUV, *argv, "--help"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"usage: lrauv {' '.join(argv)}") and "\nexample" in proc.stdout, proc.stdout
    assert developer_text(proc.stdout) == [], proc.stdout
