"""Hostile BVH files: one test per known attack, and mutations of two seeds (a CMU trial written
as BVH, a file of another skeleton) fuzzed by hypothesis. The property, the Acclaim readers'
(``tests/acclaim_mutations.py``): one :class:`MotionDataError` naming the file and, when it gives
a line, a line of the file; or finite values and valid bone names, through the whole ingest."""

from __future__ import annotations

import os
import random
import resource

import numpy as np
import pytest
from acclaim_mutations import Breach, line_count, mutate, non_finite
from bvh_files import bvh_text, creature, motion
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sim.acclaim.asf import check_bone_name
from sim.bvh.convert import to_acclaim
from sim.bvh.reader import parse_bvh
from sim.errors import MotionDataError
from sim.motion.ingest import load_motion

GOOD = bvh_text(creature(), motion(creature(), 8, 30.0), 30.0)


def one_line_error(tmp_path, text: str | bytes, match: str, *, unit=None) -> MotionDataError:
    path = tmp_path / "h.bvh"
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    with pytest.raises(MotionDataError) as info:
        to_acclaim(parse_bvh(path), unit=unit)
    e = info.value
    assert "\n" not in str(e) and str(e).startswith(str(path)), str(e)
    assert e.line is None or 1 <= e.line <= line_count(path)
    assert match in e.problem, str(e)
    return e


def motion_lines(text: str) -> tuple[list[str], int]:
    lines = text.splitlines()
    return lines, lines.index("MOTION")


def test_the_seed_reads(tmp_path):
    (tmp_path / "ok.bvh").write_text(GOOD)
    assert to_acclaim(parse_bvh(tmp_path / "ok.bvh")).motion.n_frames == 8


def test_a_truncated_motion_names_the_frames_found_and_declared(tmp_path):
    lines, m = motion_lines(GOOD)
    e = one_line_error(
        tmp_path, "\n".join(lines[:-3]) + "\n", "truncated MOTION: 5 frames of the 8"
    )
    assert e.line == len(lines) - 3
    one_line_error(tmp_path, "\n".join(lines[: m + 2]) + "\n", "ends before 'Frame Time")
    one_line_error(tmp_path, GOOD[: GOOD.index("MOTION")], "no MOTION section")


def test_a_frame_count_that_lies_is_refused_before_allocating(tmp_path):
    lines, m = motion_lines(GOOD)
    lines[m + 1] = "Frames: 7"
    e = one_line_error(tmp_path, "\n".join(lines) + "\n", "more frames than 'Frames: 7'")
    assert e.line == len(lines)
    lines[m + 1] = "Frames: 16000000"  # 16e6 x 54 channels x 8 bytes = 7 GB: never allocated
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    e = one_line_error(tmp_path, "\n".join(lines) + "\n", "cannot fit in a file of")
    assert e.line == m + 2
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 100_000  # KB
    for bad in ("Frames: -3", "Frames: 1e9", "Frames: 0", "Frames: 99999999999999999999"):
        lines[m + 1] = bad
        one_line_error(tmp_path, "\n".join(lines) + "\n", "Frames")


@pytest.mark.parametrize(
    ("channels", "problem"),
    [
        ("CHANNELS 7 Xrotation", "channel count '7'; expected 0 to 6"),
        ("CHANNELS 99999999999999 Xrotation", "channel count"),
        ("CHANNELS 3 Xrotation Xrotation Yrotation", "channel Xrotation listed twice"),
        ("CHANNELS 3 Xrotation Wrotation Yrotation", "unknown channel 'Wrotation'"),
        ("CHANNELS 2 Xrotation", "CHANNELS 2 lists only 1 channels"),
    ],
)
def test_channel_lists_out_of_the_grammar_are_refused(tmp_path, channels, problem):
    text = GOOD.replace("CHANNELS 1 Xrotation", channels, 1)
    assert text != GOOD
    one_line_error(tmp_path, text, problem)


@pytest.mark.parametrize(
    "token",
    ["nan", "-inf", "1e999", "1,5", "0x10", "1_000", "\u0661\u0662", "--1", "1e", ".", "NaN",
     "1..2", "+-1", "1-2", ".e1", "1e5.5", "-", "e5", "1e+", "5e-", "1e5e5", "+"],
)  # fmt: skip
def test_a_value_that_is_no_plain_finite_decimal_names_its_line(tmp_path, token):
    lines, m = motion_lines(GOOD)
    values = lines[m + 5].split()
    values[4] = token
    lines[m + 5] = " ".join(values)
    e = one_line_error(tmp_path, "\n".join(lines) + "\n", "frame 3")
    assert e.line == m + 6


def test_offsets_and_angles_out_of_bounds_are_refused(tmp_path):
    one_line_error(tmp_path, GOOD.replace("OFFSET 10.000000", "OFFSET nan", 1), "OFFSET")
    one_line_error(tmp_path, GOOD.replace("OFFSET 10.000000", "OFFSET 1e300", 1), "exceeds")
    lines, m = motion_lines(GOOD)
    values = lines[m + 4].split()
    values[5] = "1e6"  # a rotation of a million degrees
    lines[m + 4] = " ".join(values)
    one_line_error(tmp_path, "\n".join(lines) + "\n", "exceeds 100000")
    # an OFFSET within the reader's bound that makes a bone longer than 10 km in metres
    far = GOOD.replace("OFFSET 10.000000", "OFFSET 9000000", 1)
    one_line_error(tmp_path, far, "exceeds 10000 m", unit="m")


def test_a_hierarchy_too_deep_or_too_wide_is_refused(tmp_path):
    def chain(n: int) -> str:
        text = "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
        text += "".join(f"JOINT j{i}\n{{\nOFFSET 0 1 0\nCHANNELS 1 Xrotation\n" for i in range(n))
        return (
            text + "}\n" * (n + 1) + "MOTION\nFrames: 1\nFrame Time: 0.01\n" + "0 " * (n + 3) + "\n"
        )

    (tmp_path / "ok.bvh").write_text(chain(50))
    assert len(parse_bvh(tmp_path / "ok.bvh").joints) == 51
    one_line_error(tmp_path, chain(150), "more than 100 joints deep")
    wide = "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n"
    wide += "End Site\n{\nOFFSET 0 1 0\n}\n" * 600 + "}\nMOTION\nFrames: 1\nFrame Time: 0.01\n0\n"
    one_line_error(tmp_path, wide, "more than 500 joints")


@pytest.mark.parametrize(
    ("old", "new", "problem"),
    [
        ("HIERARCHY", "HIERARCHIE", "expected 'HIERARCHY'"),
        ("JOINT LeftKnee", "JOINT Left:Thigh", "as the joint of line"),  # both become Left_Thigh
        ("JOINT LeftKnee", "JOINT root", ""),  # reserved: becomes root_, accepted below
        ("Frame Time: 0.03333333", "Frame Time: 0", "Frame Time 0 s"),
        ("Frame Time: 0.03333333", "Frame Time: 5", "Frame Time 5 s; expected 0.001 to 1 s"),
        ("Frame Time: 0.03333333", "Frame Time: abc", "not a plain decimal"),
        ("ROOT mixamorig:Hips", "ROOT", "joint without a name"),
        ("}\nMOTION", "}\n}\nMOTION", "after the ROOT's closing brace"),
    ],
)
def test_malformed_hierarchies_name_their_line(tmp_path, old, new, problem):
    text = GOOD.replace(old, new, 1)
    assert text != GOOD
    if not problem:
        (tmp_path / "ok.bvh").write_text(text)
        names = to_acclaim(parse_bvh(tmp_path / "ok.bvh")).skeleton.bone_names
        assert "root_" in names and all(check_bone_name(n) is None for n in names)
        return
    one_line_error(tmp_path, text, problem)


def test_files_that_are_not_files_or_not_text_are_refused(tmp_path):
    one_line_error(tmp_path, b"", "empty file")
    one_line_error(tmp_path, os.urandom(4096).replace(b"\n", b" "), "")
    with pytest.raises(MotionDataError, match="not a regular file"):
        parse_bvh("/dev/zero")
    with pytest.raises(MotionDataError, match="not a regular file"):
        parse_bvh(tmp_path)
    fifo = tmp_path / "fifo.bvh"
    os.mkfifo(fifo)
    with pytest.raises(MotionDataError, match="not a regular file"):
        parse_bvh(fifo)


# --- fuzzing ----------------------------------------------------------------------------------

FUZZ = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    database=None,
)


def check(path, full: bool) -> str:
    """The property on one input: ``"error"`` or ``"ok"``, else :class:`Breach`."""
    try:
        take = to_acclaim(parse_bvh(path))
        values = [take.skeleton, take.motion]
        if full:
            values.append(load_motion(path, fps=take.fps))
    except MotionDataError as e:
        if e.path != str(path):
            raise Breach("bad-error", f"error names another file: {e}") from e
        if e.line is not None and not 1 <= e.line <= line_count(path):
            raise Breach("bad-error", f"line out of range: {e}") from e
        if "\n" in str(e):
            raise Breach("bad-error", "error of several lines") from e
        return "error"
    bad = [n for v in values for n in non_finite(v)]
    if bad:
        raise Breach("non-finite", ", ".join(bad))
    names = [p for b in values[0].bones if (p := check_bone_name(b.name))]
    if names:
        raise Breach("bad-name", "; ".join(names))
    return "ok"


@pytest.fixture(scope="module")
def seeds(cmu_dir, tmp_path_factory):
    from sim.bvh.writer import bvh_text as write_text
    from sim.motion.trial import read_trial

    skeleton, take, _ = read_trial(cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc")
    take = type(take)(
        path="", root=take.root[:20], angles={k: v[:20] for k, v in take.angles.items()}
    )
    return {"cmu": write_text(skeleton, take, 120.0).encode(), "creature": GOOD.encode()}


@FUZZ
@given(data=st.data())
def test_mutated_bvh_reads_cleanly_or_fails_cleanly(seeds, tmp_path_factory, data):
    seed = seeds[data.draw(st.sampled_from(sorted(seeds)))]
    rng = random.Random(data.draw(st.integers(0, 2**64 - 1), label="seed"))
    text, _ = mutate(seed, rng)
    path = tmp_path_factory.mktemp("bvh") / "m.bvh"
    path.write_bytes(text)
    assert check(path, full=data.draw(st.booleans())) in ("ok", "error")


def test_the_fuzz_seeds_read_to_finite_values(seeds, tmp_path):
    for name, text in seeds.items():
        path = tmp_path / f"{name}.bvh"
        path.write_bytes(text)
        assert check(path, full=True) == "ok"
        assert np.isfinite(parse_bvh(path).values).all()


def test_numbers_numpy_reads_in_the_fast_path_are_the_grammars(tmp_path):
    """Well-formed tokens of every shape the grammar allows read to the same values whether a
    chunk goes through numpy or line by line (a bad line elsewhere in it sends it there)."""
    tokens = ["1e5", ".5", "5.", "+.5", "-.5e-3", "1.e5", "1E5", "00012", "1e0005", "-0", "0."]
    lines, m = motion_lines(GOOD)
    row = lines[m + 3].split()
    row[: len(tokens)] = tokens
    lines[m + 3] = " ".join(row)
    path = tmp_path / "ok.bvh"
    path.write_text("\n".join(lines) + "\n")
    fast = parse_bvh(path).values
    lines.insert(m + 6, "")  # a blank line: this chunk goes line by line (and is skipped)
    path.write_text("\n".join(lines) + "\n")
    np.testing.assert_array_equal(parse_bvh(path).values, fast)
    np.testing.assert_array_equal(fast[0, : len(tokens)], [float(t) for t in tokens])
