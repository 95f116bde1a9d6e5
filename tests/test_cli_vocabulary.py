"""One vocabulary across commands: the same idea is the same option everywhere, old spellings still
work and warn in one line, --version, and --help that says only what is true."""

from __future__ import annotations

import argparse
import dataclasses
import json
import warnings

import pytest

import sidql
from sidql.commands import main as cli
from sidql.commands.usage import UsageWarning, one_line_warning
from sidql.learning.settings import Args, field_docs
from sim import paths

#: Commands that read a folder of CMU trials, that choose W keyframes (several: a sweep), that
#: run keyframe methods, that show progress bars.
FOLDER = {"dataset", "demo", "eval", "synth", "train"}
KEYFRAMES = {"demo": False, "report": False, "extract": True, "eval": True, "train": True}
METHODS = {"demo", "report", "extract", "eval"}
PROGRESS = {"dataset", "demo", "report", "eval", "synth", "train"}


def commands() -> dict[str, argparse.ArgumentParser]:
    parser = cli.build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


def options(p: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {s: a for a in p._actions for s in a.option_strings if a.help != argparse.SUPPRESS}


def test_one_spelling_per_idea_in_every_command():
    cmds = commands()
    assert set(cmds) >= FOLDER | set(KEYFRAMES) | METHODS | PROGRESS
    for name, p in cmds.items():
        opts = options(p)
        assert ("--data" in opts) == (name in FOLDER), name
        assert ("--keyframes" in opts) == (name in KEYFRAMES), name
        if name in KEYFRAMES:
            assert opts["-W"] is opts["--keyframes"], name
            assert (opts["-W"].nargs == "+") == KEYFRAMES[name], name
        assert ("--methods" in opts) == (name in METHODS), name
        assert ("--quiet" in opts) == (name in PROGRESS), name
        assert not {"--from", "--method", "--dir"} & set(opts), name  # old spellings: hidden


def test_help_shows_no_empty_defaults_and_train_explains_every_setting():
    for name, p in commands().items():
        text = p.format_help()
        assert "(default: None)" not in text and "(default: False)" not in text, name
        assert "(default: [" not in text, name  # lists as they are typed: 5 10 15
    train = options(commands()["train"])
    docs = field_docs()
    shown = {"progress", "extra", "synthetic_tasks", "data"}  # not options, or --data's own help
    for f in dataclasses.fields(Args):
        if f.name in shown:
            continue
        action = train["--" + f.name.replace("_", "-")]
        assert action.help and action.help == docs[f.name].replace("%", "%%"), f.name
    assert "discount" in train["--gamma"].help and train["--gamma"].default == Args().gamma


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.strip() == f"sidql {sidql.__version__}"


@pytest.mark.parametrize(
    "argv, dest, value, new",
    [
        (["dataset", "D", "--out", "o"], "data", "D", "--data DIR"),
        (["synth", "--from", "D", "--n", "1", "--out", "o"], "data", "D", "--data DIR"),
        (["extract", "a.asf", "b.amc", "-W", "5", "--method", "greedy"], "methods", ["greedy"],
         "--methods"),
    ],
)  # fmt: skip
def test_old_spellings_still_work_and_warn(argv, dest, value, new):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        args = cli.build_parser().parse_args(argv)
    assert getattr(args, dest) == value
    (w,) = [c for c in caught if issubclass(c.category, UsageWarning)]
    assert "old spelling" in str(w.message) and new in str(w.message)


def test_new_spellings_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        args = cli.build_parser().parse_args(["dataset", "--data", "D", "--out", "o"])
        assert args.data == "D"
        args = cli.build_parser().parse_args(["extract", "a", "b", "-W", "4", "6"])
        assert args.keyframes == [4, 6] and args.methods == ["optimal"]


def test_an_old_spelling_through_the_cli_is_one_warning_line(cmu_dir, tmp_path, capsys):
    asf, amc = str(cmu_dir / "02" / "02.asf"), str(cmu_dir / "02" / "02_01.amc")
    out = tmp_path / "k.json"
    argv = ["extract", asf, amc, "-W", "4", "6", "--method", "uniform", "--out", str(out)]
    assert cli.main(argv) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "warning: sidql extract --method: an old spelling, use --methods NAME [NAME ...]"
    ]
    rows = json.loads(out.read_text())["clips"]
    assert {(r["method"], r["keyframes"]) for r in rows} == {("uniform", 4), ("uniform", 6)}
    assert {len(r["indices"]) for r in rows} == {4, 6}


def test_a_usage_warning_names_no_python_file(capsys):
    one_line_warning(UsageWarning("sidql x --from: an old spelling"), UsageWarning, "f.py", 3)
    assert capsys.readouterr().err == "warning: sidql x --from: an old spelling\n"


def test_the_data_folder_comes_from_the_environment_or_is_asked_for(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv(paths.DATA_ENV, str(tmp_path / "named"))
    assert cli.main(["dataset", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sidql dataset: error: ") and str(tmp_path / "named") in err
    monkeypatch.delenv(paths.DATA_ENV)
    monkeypatch.setattr(paths, "default_data_dir", lambda: None)  # no checkout beside data
    assert cli.main(["eval", "--out", str(tmp_path / "r.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "pass --data DIR or set SIDQL_DATA" in err
