"""Every public function of ``sim`` and ``sidql`` (their ``__all__``) answers bad arguments with a
``SidqlError`` kind: a library user catches one type, as the command line does.

Each function is called with arguments a user could plausibly get wrong: a keyframe count out of
range, an unknown name, an array of the wrong shape, a value that is not finite or not positive,
the wrong kind of object, a file that is not there. The test fails on a function of the public API
that has no bad call listed here, so a new public function must come with its own.
"""

from __future__ import annotations

import inspect

import numpy as np
import pytest
from keyframe_synth import smooth_clip

import sidql
import sim
from sim.errors import ArgumentTypeError, SidqlError, UnknownNameError, UsageError


@pytest.fixture(scope="module")
def clip():
    return smooth_clip(24, 30.0, seed=3)


def _series(clip):
    return sidql.chart(clip)


def _bad_writer(f):  # never called: the path is refused first
    raise AssertionError("written")


#: name -> list of (call(clip, tmp_path), the SidqlError kind expected)
BAD_CALLS = {
    # sim
    "estimate_ground": [
        (lambda c, t: sim.estimate_ground(np.zeros((5, 3)), ["lfoot"], 30.0), UsageError),
        (lambda c, t: sim.estimate_ground(np.full((5, 1, 3), np.nan), ["lfoot"], 30.0), UsageError),
    ],
    "find_trials": [(lambda c, t: sim.find_trials(t / "missing"), SidqlError)],
    "from_clip": [(lambda c, t: sim.from_clip("walk.npz"), ArgumentTypeError)],
    "ingest_directory": [(lambda c, t: sim.ingest_directory(t / "missing", t / "o"), SidqlError)],
    "load_clips": [
        (lambda c, t: sim.load_clips(t / "no.asf", t / "no.amc"), SidqlError),
        (lambda c, t: sim.load_clips(t / "no.asf", t / "no.amc", length=0), UsageError),
    ],
    "load_motion": [
        (lambda c, t: sim.load_motion(t / "no.asf", t / "no.amc"), SidqlError),
        (lambda c, t: sim.load_motion(t / "a", t / "b", skeleton="robot"), UnknownNameError),
        (lambda c, t: sim.load_motion(t / "a", t / "b", fps=7.0), UsageError),
        (lambda c, t: sim.load_motion(t / "a", t / "b", fps=30.0, source_fps=0.0), UsageError),
    ],
    "load_npz": [(lambda c, t: sim.load_npz(t / "missing.npz"), SidqlError)],
    "render_frames": [(lambda c, t: sim.render_frames("walk"), ArgumentTypeError)],
    "run_batch": [
        (lambda c, t: sim.run_batch(len, [1], workers=-1), UsageError),
        (lambda c, t: sim.run_batch("len", [1]), ArgumentTypeError),
    ],
    "save_npz": [(lambda c, t: sim.save_npz("clip", t / "x.npz"), ArgumentTypeError)],
    "subject_model": [(lambda c, t: sim.subject_model(t / "missing.asf"), SidqlError)],
    "summarise": [(lambda c, t: sim.summarise({"mpjpe": 1.0}), ArgumentTypeError)],
    "synthesize": [
        (lambda c, t: sim.synthesize(None, t / "o", -1, progress=False), UsageError),
        (lambda c, t: sim.synthesize(None, t / "o", 1, kinds=("nope",)), UnknownNameError),
    ],
    "synthetic_motion": [
        (lambda c, t: sim.synthetic_motion(-1.0), UsageError),
        (lambda c, t: sim.synthetic_motion(1.0, fps=0.0), UsageError),
    ],
    "write_atomic": [(lambda c, t: sim.write_atomic(t / "x.txt", "text"), ArgumentTypeError)],
    "write_video": [
        (
            lambda c, t: sim.write_video(np.zeros((2, 8, 8, 3), np.uint8), t / "v.mp4", 0.0),
            UsageError,
        ),
        (
            lambda c, t: sim.write_video(np.zeros((2, 8, 8), np.uint8), t / "v.mp4", 30.0),
            UsageError,
        ),
    ],
    # sidql
    "available": [(lambda c, t: sidql.available("hermite"), TypeError)],  # takes no argument
    "chart": [(lambda c, t: sidql.chart(np.zeros((24, 31, 3))), ArgumentTypeError)],
    "decode_file": [(lambda c, t: sidql.decode_file(t / "no.sidq", t / "o.npz"), SidqlError)],
    "decode_to_reconstruction": [
        (lambda c, t: sidql.decode_to_reconstruction(t / "no"), SidqlError)
    ],
    "encode_clip": [
        (lambda c, t: sidql.encode_clip(c, rate=-5.0), UsageError),
        (lambda c, t: sidql.encode_clip("clip", rate=500.0), ArgumentTypeError),
    ],
    "encode_files": [
        (lambda c, t: sidql.encode_files(t / "a", t / "b", t / "o", rate=1e3), SidqlError)
    ],
    "evaluate": [
        (lambda c, t: sidql.evaluate([], ["nope"], [5], progress=False), UnknownNameError),
        (lambda c, t: sidql.evaluate([], ["uniform"], [1], progress=False), UsageError),
    ],
    "load_cases": [(lambda c, t: sidql.load_cases(t / "missing", progress=False), SidqlError)],
    "mpjpe_mm": [
        (lambda c, t: sidql.mpjpe_mm(np.zeros((2, 3, 3)), np.zeros((3, 3, 3))), UsageError),
    ],
    "optimal_keyframes": [
        (lambda c, t: sidql.optimal_keyframes(_series(c), 100), UsageError),
        (lambda c, t: sidql.optimal_keyframes(_series(c), 5, "spline"), UnknownNameError),
        (lambda c, t: sidql.optimal_keyframes(c, 5), ArgumentTypeError),
    ],
    "optimal_table": [(lambda c, t: sidql.optimal_table(_series(c), "spline"), UnknownNameError)],
    "q_error": [
        (lambda c, t: sidql.q_error(_series(c), [0, 100]), UsageError),
        (lambda c, t: sidql.q_error(_series(c), [0, 23], "spline"), UnknownNameError),
    ],
    "reconstruct": [
        (lambda c, t: sidql.reconstruct(c, [0]), UsageError),
        (lambda c, t: sidql.reconstruct(c, [0, 23], "spline"), UnknownNameError),
        (lambda c, t: sidql.reconstruct(c, [0, 5, 3, 23]), UsageError),
    ],
    "reconstruction_of": [(lambda c, t: sidql.reconstruction_of("nope"), UnknownNameError)],
    "register": [
        (lambda c, t: sidql.register("x_test", reconstruction="spline"), UnknownNameError),
        (lambda c, t: sidql.register("", reconstruction="hermite"), UsageError),
    ],
    "report_clips": [
        (lambda c, t: sidql.report_clips([c], t / "r", W=100, methods=["uniform"]), UsageError),
        (lambda c, t: sidql.report_clips([c], t / "r", W=5, methods=["nope"]), UnknownNameError),
    ],
    "report_trial": [
        (
            lambda c, t: sidql.report_trial(t / "a", t / "b", t / "r", W=5, methods=["uniform"]),
            SidqlError,
        ),
    ],
    "segment_cost_matrix": [
        (lambda c, t: sidql.segment_cost_matrix(_series(c), "spline"), UnknownNameError)
    ],
    "select": [
        (lambda c, t: sidql.select("optimal", c, 100), UsageError),
        (lambda c, t: sidql.select("nope", c, 5), UnknownNameError),
        (lambda c, t: sidql.select("optimal", "clip", 5), ArgumentTypeError),
    ],
    "validate_clip": [
        (lambda c, t: sidql.validate_clip(c, ["uniform"], 100), UsageError),
        (lambda c, t: sidql.validate_clip(c, ["nope"], 5), UnknownNameError),
    ],
}


def public_functions() -> list[str]:
    names = []
    for module in (sim, sidql):
        for name in module.__all__:
            if inspect.isfunction(getattr(module, name)):
                names.append(name)
    return sorted(set(names))


def test_every_public_function_has_bad_calls_listed():
    assert sorted(BAD_CALLS) == public_functions()


CASES = [
    (name, i, call, kind)
    for name, calls in BAD_CALLS.items()
    for i, (call, kind) in enumerate(calls)
]


@pytest.mark.parametrize("name,i,call,kind", CASES, ids=[f"{name}-{i}" for name, i, _, _ in CASES])
def test_bad_arguments_raise_a_sidql_error(name, i, call, kind, clip, tmp_path):
    with pytest.raises(kind) as e:
        call(clip, tmp_path)
    if kind is not TypeError:  # a call Python itself refuses (too many arguments) is not ours
        assert isinstance(e.value, SidqlError), f"{name}: {type(e.value).__name__}: {e.value}"
    assert "\n" not in str(e.value), f"{name}: a message of one line"
    assert not (tmp_path / "o").exists() or name in ("synthesize", "ingest_directory")


@pytest.mark.parametrize(
    "make",
    [
        lambda c: sidql.Clip(**{**vars(c), "fps": 0.0}),
        lambda c: sim.PointMotion(c.names, c.parents, c.positions[:, :3], c.fps),
        lambda c: sidql.KeyframeEnv([]),
    ],
    ids=["Clip", "PointMotion", "KeyframeEnv"],
)
def test_public_classes_refuse_inconsistent_values(make, clip):
    with pytest.raises(UsageError):
        make(clip)
