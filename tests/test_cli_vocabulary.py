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
from sidql.learning.settings import Args, field_docs, option_of
from sim import paths

#: Commands that read a folder of CMU trials, that choose W keyframes (several: a sweep), that
#: run keyframe methods, that show progress bars.
FOLDER = {"dataset", "demo", "eval", "synth", "train"}
KEYFRAMES = {"demo": False, "report": False, "extract": True, "eval": True, "train": True}
METHODS = {"demo", "report", "extract", "eval"}
PROGRESS = {"dataset", "demo", "report", "eval", "synth", "train"}
WORKERS = {"dataset", "report", "eval", "synth"}


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
        assert not {"--from", "--method", "--dir", "--subjects", "--simulate-samples"} & set(opts)
        assert ("--workers" in opts) == (name in WORKERS), name
        if name in WORKERS:  # one declaration: one default, one metavar
            assert (opts["--workers"].default, opts["--workers"].metavar) == (1, "N"), name


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
        action = train[option_of(f.name)]
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
        (["eval", "--subjects", "01", "07"], "test_subjects", ["01", "07"], "--test-subjects"),
        (["eval", "--simulate", "--simulate-samples", "8"], "samples", 8, "--samples N"),
        (["eval", "--methods", "uniform", "xyz"], "methods", ["uniform", "cartesian"],
         "use cartesian"),
    ],
)  # fmt: skip
def test_old_spellings_still_work_and_warn(argv, dest, value, new):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        args = cli.build_parser().parse_args(argv)
    assert getattr(args, dest) == value
    (w,) = [c for c in caught if issubclass(c.category, UsageWarning)]
    assert "old " in str(w.message) and new in str(w.message)


def test_new_spellings_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        args = cli.build_parser().parse_args(["dataset", "--data", "D", "--out", "o"])
        assert args.data == "D"
        args = cli.build_parser().parse_args(["extract", "a", "b", "-W", "4", "6"])
        assert args.W == [4, 6] and args.methods == ["optimal"]
        args = cli.build_parser().parse_args(["eval", "--test-subjects", "01", "--samples", "8"])
        assert args.test_subjects == ["01"] and args.samples == 8
        args = cli.build_parser().parse_args(["report", "a", "b", "--methods", "cartesian",
                                              "--out", "o"])  # fmt: skip
        assert args.methods == ["cartesian"]


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


def test_each_command_summary_is_kept_once_in_main():
    """``sidql --help`` and each command's own parser show the one summary of
    ``main.COMMANDS``; a command module holds its description and options, no summary."""
    import importlib
    import inspect

    top = cli.build_parser().format_help()
    for name, summary in cli.COMMANDS.items():
        assert " ".join(summary.split()[:4]) in " ".join(top.split()), name
        module = importlib.import_module(f"sidql.commands.{name}")
        assert "add_parser" not in inspect.getsource(module), name
        assert module.DESCRIPTION.strip(), name
    assert set(commands()) == set(cli.COMMANDS)


def test_the_least_w_is_one_rule(cmu_dir, trial_files, capsys):
    """W counts both end frames: 2 for every method; 3 for training (one decision to learn)."""
    from sidql.keyframes.counts import LEAST_LEARNED_W, LEAST_W

    assert (LEAST_W, LEAST_LEARNED_W) == (2, 3)
    asf, amc = trial_files
    assert cli.main(["extract", asf, amc, "-W", "1"]) == 2
    assert "--keyframes must be in [2, 60]; got 1" in capsys.readouterr().err
    assert cli.main(["train", "--data", str(cmu_dir), "-W", "2", "5"]) == 2
    assert "--keyframes must be in [3, 60]; got [2, 5]" in capsys.readouterr().err


@pytest.fixture
def trial_files(cmu_dir):
    return str(cmu_dir / "02" / "02.asf"), str(cmu_dir / "02" / "02_01.amc")
