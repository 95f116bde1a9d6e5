"""The README's command-line section is written from the parsers (scripts/make_readme_cli.py):
it matches what the script writes now, names every option, and the synopsis follows argparse."""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def script():
    spec = importlib.util.spec_from_file_location(
        "make_readme_cli", ROOT / "scripts" / "make_readme_cli.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_readme_section_is_what_the_script_writes(script):
    readme = (ROOT / "README.md").read_text()
    assert readme.count(script.BEGIN) == 1 and readme.count(script.END) == 1
    assert script.with_section(readme) == readme, (
        "README.md's command-line section has drifted: run python scripts/make_readme_cli.py"
    )


def test_the_section_names_every_command_and_visible_option(script):
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index(script.BEGIN) : readme.index(script.END)]
    for name, parser in script.commands().items():
        row = next(line for line in section.splitlines() if line.startswith(f"| `sidql {name} "))
        for action in parser._actions:
            if action.help == argparse.SUPPRESS or isinstance(action, argparse._HelpAction):
                continue
            if action.container.title and action.container.title.startswith("DQN"):
                continue  # train's DQN settings: one bracketed group in the row
            spelled = [s for s in action.option_strings if f"{s} " in row or f"{s}]" in row]
            assert spelled or not action.option_strings, (name, action.option_strings)


def test_a_synopsis_follows_argparse(script):
    p = argparse.ArgumentParser(prog="x")
    p.add_argument("asf", metavar="ASF")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("-W", "--keyframes", type=int, nargs="+", default=[5], metavar="W")
    p.add_argument("--ray", nargs="?", metavar="ADDRESS")
    p.add_argument("--layout", choices=("a", "b"))
    p.add_argument("-q", "--quiet", action="store_true")
    p.add_argument("--old", help=argparse.SUPPRESS)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--rate", metavar="B/S")
    g.add_argument("--max-q", metavar="Q")
    assert script.synopsis("x", p) == (
        "sidql x ASF --out DIR [-W W [W ...]] [--ray [ADDRESS]] [--layout a|b] [--quiet] "
        "(--rate B/S | --max-q Q)"
    )
