"""Write the README's command-line section from the parser itself, so the two cannot drift.

    python scripts/make_readme_cli.py          # rewrite README.md between the section:cli markers
    python scripts/make_readme_cli.py --check  # exit 1 if README.md differs from what it would write

The table has one row per command of ``sidql.commands.main.COMMANDS``: its synopsis, built from
its argparse options (required ones bare, the others in brackets; ``train``'s DQN settings as
one group), and its one-line summary. The paragraphs below it list the shared vocabulary and every
old spelling still accepted (each parser's hidden ``OldSpelling`` options and the old method
names), read from the parsers too. ``tests/test_readme_cli.py`` fails when README.md differs.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sidql.commands import main as cli  # noqa: E402
from sidql.commands.usage import OldSpelling  # noqa: E402
from sidql.keyframes.old_names import RENAMED  # noqa: E402

BEGIN, END = "<!-- section:cli -->", "<!-- /section:cli -->"

INTRO = (
    "Written from the parsers by `python scripts/make_readme_cli.py` (a test fails when this "
    "section differs); `sidql COMMAND --help` has every option with its default."
)

VOCABULARY = (
    "One vocabulary across commands: `--data DIR` is the folder of trials, `-W`/`--keyframes` "
    "the number of keyframes W per clip, both end frames included (several values where a command "
    "sweeps them; at least 2, and 3 for `train`, whose policy must decide at least one), "
    "`--methods` the keyframe methods (`cartesian`: the Cartesian baseline), `--test-subjects` "
    "the subjects a command evaluates on, `--samples N` the sampling tracker's rollouts per "
    "window, `--out` what is written, `--quiet` silences progress bars, `--workers N` (default 1: "
    "this process) and `--ray [ADDRESS]` spread batch jobs over processes or a Ray cluster. "
    "`sidql --version` prints the version."
)

ERRORS = (
    "Bad input exits with status 2 and one line naming the file, the line and the problem, e.g.\n"
    "`bad.amc:11: unknown bone 'lfemurX'; known: head, lclavicle, ...`; an unknown method or\n"
    "reconstruction lists the valid ones."
)


def commands() -> dict[str, argparse.ArgumentParser]:
    """Every command's parser, by name, in the order of ``main.COMMANDS``."""
    parser = cli.build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return {name: sub.choices[name] for name in cli.COMMANDS}


def _flag(action: argparse.Action) -> str:
    """The spelling shown: ``-W`` for the keyframe count, else the first long option."""
    strings = action.option_strings
    if "-W" in strings:
        return "-W"
    return next((s for s in strings if s.startswith("--")), strings[0])


def _value(action: argparse.Action) -> str:
    if action.metavar is not None:
        name = action.metavar
    elif action.choices is not None:
        name = "|".join(map(str, action.choices))
    else:
        name = action.dest.upper()
    if action.nargs == "+":
        return f"{name} [{name} ...]"
    if action.nargs == "?":
        return f"[{name}]"
    return name


def _word(action: argparse.Action) -> str:
    """One action as typed: ``--out DIR``, ``--physics``, ``ASF``."""
    if not action.option_strings:
        return _value(action)
    if action.nargs == 0:
        return _flag(action)
    return f"{_flag(action)} {_value(action)}"


def synopsis(name: str, parser: argparse.ArgumentParser) -> str:
    """``sidql NAME ...``: positionals, then options (optional ones in brackets) in declaration
    order; a required mutually exclusive group as ``(A | B)``; a titled argument group (train's
    DQN settings) as one bracketed word."""
    shown = [
        a
        for a in parser._actions
        if a.help != argparse.SUPPRESS and not isinstance(a, argparse._HelpAction)
    ]
    group_of = {id(a): g for g in parser._mutually_exclusive_groups for a in g._group_actions}
    titled = {
        id(a): g.title
        for g in parser._action_groups
        if g.title not in ("positional arguments", "options", "optional arguments")
        for a in g._group_actions
    }
    words, done = [], set()
    for a in shown:
        if not a.option_strings:
            words.append(_word(a))
    for a in shown:
        if not a.option_strings or id(a) in done:
            continue
        if id(a) in titled:
            title = titled[id(a)].split(" (")[0]
            words.append(f"[{title} ...]")
            done.update(id(b) for b in shown if titled.get(id(b)) == titled[id(a)])
            continue
        group = group_of.get(id(a))
        if group is not None:
            members = [b for b in group._group_actions if b.help != argparse.SUPPRESS]
            done.update(id(b) for b in members)
            inner = " | ".join(_word(b) for b in members)
            words.append(f"({inner})" if group.required else f"[{inner}]")
            continue
        words.append(_word(a) if a.required else f"[{_word(a)}]")
    return " ".join([f"sidql {name}", *words])


def old_spellings(parsers: dict[str, argparse.ArgumentParser]) -> list[str]:
    """Every old spelling still accepted: ``sidql CMD OLD`` (-> NEW), and old method names."""
    out = []
    for name, p in parsers.items():
        for a in p._actions:
            if isinstance(a, OldSpelling):
                old = a.option_strings[0] if a.option_strings else (a.metavar or a.dest.upper())
                out.append(f"`{name} {old}` (now `{a.new.split()[0]}`)")
    out += [f"method `{old}` (now `{new}`)" for old, new in RENAMED.items()]
    return out


def _wrap(text: str) -> str:
    return textwrap.fill(text, width=99, break_long_words=False, break_on_hyphens=False)


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def cli_section() -> str:
    """The README's command-line section, markers included."""
    parsers = commands()
    rows = [
        f"| `{_cell(synopsis(name, p))}` | {_cell(cli.COMMANDS[name])} |"
        for name, p in parsers.items()
    ]
    olds = ", ".join(old_spellings(parsers))
    return "\n".join(
        [
            BEGIN,
            "## Command line",
            "",
            _wrap(INTRO),
            "",
            "| command | what it does |",
            "|---|---|",
            *rows,
            "",
            _wrap(f"{VOCABULARY} Older spellings still work and warn in one line: {olds}."),
            "",
            ERRORS,
            END,
        ]
    )


def with_section(readme: str) -> str:
    """``readme`` with its command-line section replaced by :func:`cli_section`."""
    start, end = readme.index(BEGIN), readme.index(END) + len(END)
    return readme[:start] + cli_section() + readme[end:]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only check; exit 1 if it differs")
    ap.add_argument("--readme", default=str(ROOT / "README.md"), help="the README to write")
    args = ap.parse_args(argv)
    path = Path(args.readme)
    old = path.read_text()
    new = with_section(old)
    if args.check:
        if new != old:
            print(f"{path}: the command-line section differs; run {Path(__file__).name}")
            return 1
        return 0
    if new != old:
        path.write_text(new)  # a checked-in source file, rewritten in place by its owner
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
