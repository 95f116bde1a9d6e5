"""One error hierarchy: every error raised on purpose is a SidqlError kind, survives pickling (batch
workers send errors back pickled), and reaches the command line as one line with exit 2."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from sidql.codec.encode import encode_series
from sidql.commands import main as cli
from sidql.commands.usage import UsageError
from sidql.keyframes import methods, reconstructions
from sidql.keyframes.spherical import chart
from sidql.learning.policy import load_policy
from sim.errors import (
    BadFileError,
    ModelFileError,
    MotionDataError,
    SidqlError,
    UnknownNameError,
    UnmetTargetError,
)
from sim.motion.ingest import load_motion
from sim.motion.synthetic import synthetic_motion
from sim.simulate.dataset import synthesize


@pytest.mark.parametrize(
    "error",
    [
        MotionDataError("a.amc", 12, "bad frame"),
        MotionDataError(None, None, "no frames"),
        ModelFileError("p.pt", None, "refused: holds objects"),
        UnmetTargetError("walk.amc: rate too low"),
        UnknownNameError("method", "nope", ("random", "uniform")),
        UsageError("--keyframes must be in [2, 60]; got 1"),
    ],
)
def test_every_kind_is_a_sidql_error_and_pickles_whole(error):
    assert isinstance(error, SidqlError)
    back = pickle.loads(pickle.dumps(error))
    assert type(back) is type(error) and str(back) == str(error)
    assert vars(back) == vars(error)


def test_file_errors_name_file_and_line_and_are_siblings():
    e = MotionDataError("d/02_01.amc", 7, "unknown bone 'x'")
    assert str(e) == "d/02_01.amc:7: unknown bone 'x'"
    assert (e.path, e.line, e.problem) == ("d/02_01.amc", 7, "unknown bone 'x'")
    assert isinstance(e, BadFileError) and isinstance(e, ValueError)
    m = ModelFileError("p.pt", None, "refused")
    assert str(m) == "p.pt: refused" and isinstance(m, BadFileError)
    assert not isinstance(m, MotionDataError)  # a policy file is not motion data
    long = MotionDataError("f", None, "x" * 100_000)
    assert len(long.problem) <= MotionDataError.MAX_PROBLEM
    assert pickle.loads(pickle.dumps(long)).problem == long.problem


def test_unknown_names_list_the_valid_ones_unquoted():
    e = UnknownNameError("reconstruction", "spline", ("hermite", "linear"))
    assert str(e) == "unknown reconstruction 'spline'; known: hermite, linear"
    assert isinstance(e, KeyError) and isinstance(e, ValueError)  # what a plain lookup raises
    assert (e.what, e.name, e.known) == ("reconstruction", "spline", ("hermite", "linear"))


def test_unknown_method_and_reconstruction_are_unknown_name_errors():
    with pytest.raises(UnknownNameError, match="unknown method 'nope'; known: .*optimal") as m:
        methods.get("nope")
    assert "greedy" in m.value.known
    with pytest.raises(UnknownNameError, match="unknown reconstruction 'spline'; known: hermite"):
        reconstructions.get("spline")


def test_unknown_names_elsewhere_are_unknown_name_errors(tmp_path):
    clip = synthetic_motion(1.0, seed=0)
    with pytest.raises(UnknownNameError, match="unknown point 'tail'; known: root"):
        clip.index("tail")
    with pytest.raises(UnknownNameError, match="unknown skeleton 'robot'; known: subject"):
        load_motion("x.asf", "x.amc", skeleton="robot")
    with pytest.raises(UnknownNameError, match="unknown kind 'jump'; known: .*procedural"):
        synthesize(None, tmp_path / "s", 1, kinds=("jump",))


@pytest.fixture(scope="module")
def series():
    return chart(synthetic_motion(4.0, seed=1))


def test_a_rate_no_plan_meets_is_an_unmet_target(series):
    with pytest.raises(UnmetTargetError, match="rate too low") as e:
        encode_series(series, rate=5.0, reconstruction="linear", max_gap=10)
    assert not isinstance(e.value, BadFileError)  # the data is fine; the request is not
    with pytest.raises(UnknownNameError, match="unknown reconstruction 'spline'; known: auto"):
        encode_series(series, rate=900.0, reconstruction="spline")


def test_a_refused_policy_file_is_a_model_file_error(tmp_path):
    bad = tmp_path / "p.pt"
    bad.write_bytes(b"not a torch file")
    with pytest.raises(ModelFileError, match="p.pt: "):
        load_policy(bad)
    folder = tmp_path / "dir.pt"
    folder.mkdir()
    with pytest.raises(ModelFileError, match="dir.pt: not a regular file"):
        load_policy(folder)


def test_the_cli_prints_any_sidql_error_as_one_line_and_exits_2(monkeypatch, capsys):
    raised = iter(
        [
            UnmetTargetError("t.amc: rate too low"),
            UnknownNameError("reconstruction", "spline", ("hermite",)),
            ModelFileError("p.pt", None, "refused"),
        ]
    )

    def fails(args):
        raise next(raised)

    monkeypatch.setattr("sidql.commands.decode.run", fails)
    for expected in ("t.amc: rate too low", "unknown reconstruction", "p.pt: refused"):
        parser = cli.build_parser()
        args = parser.parse_args(["decode", "x.sidq", "--out", "x.npz"])
        assert args.func is fails
        assert cli.main(["decode", "x.sidq", "--out", "x.npz"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("sidql decode: error: ") and expected in err[0]


def test_a_bug_is_not_a_sidql_error_but_misuse_is():
    assert not issubclass(ZeroDivisionError, SidqlError)
    assert not issubclass(AttributeError, SidqlError)
    with pytest.raises(UsageError) as e:  # misuse of a function: a UsageError, also a ValueError
        reconstructions.rebuild("hermite", synthetic_motion(1.0, seed=0), np.array([3, 1]))
    assert isinstance(e.value, SidqlError) and isinstance(e.value, ValueError)
