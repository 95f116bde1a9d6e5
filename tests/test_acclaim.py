"""Acclaim reading: every real file loads; every kind of malformed input gets one clear error."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from sim.acclaim.reader import parse_amc, parse_asf
from sim.errors import MotionDataError, MotionDataWarning


def manifest(cmu_dir):
    rows = [ln.split("\t") for ln in (cmu_dir / "MANIFEST.tsv").read_text().splitlines()[1:]]
    return [(r[0], r[3]) for r in rows if r[0].endswith(".amc")]


def test_every_real_file_loads_with_metre_lengths(cmu_dir):
    for rel, frames in manifest(cmu_dir):
        subject = rel.split("/")[0]
        skel = parse_asf(cmu_dir / subject / f"{subject}.asf")
        assert len(skel.bones) == 30
        # CMU's convention: metres = value * 0.0254 / 0.45.
        femur = skel.bone("lfemur").length
        assert 0.3 < femur < 0.55, (rel, femur)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MotionDataWarning)
            motion = parse_amc(cmu_dir / rel, skel)
        assert motion.n_frames in (int(frames), int(frames) - 1), rel
        assert motion.angles["lfemur"].shape == (motion.n_frames, 3)


def test_length_units_follow_the_header(cmu_dir):
    skel = parse_asf(cmu_dir / "01" / "01.asf")
    # 01.asf: lfemur length 7.1578 with ':units length 0.45'.
    assert skel.bone("lfemur").length == pytest.approx(7.1578 * 0.0254 / 0.45)


def test_crlf_and_lf_files_read_the_same(tmp_path, cmu_dir):
    src = (cmu_dir / "02" / "02.asf").read_bytes().replace(b"\r\n", b"\n")
    amc = (cmu_dir / "02" / "02_01.amc").read_bytes().replace(b"\r\n", b"\n")
    (tmp_path / "lf.asf").write_bytes(src)
    (tmp_path / "crlf.asf").write_bytes(src.replace(b"\n", b"\r\n"))
    (tmp_path / "lf.amc").write_bytes(amc)
    (tmp_path / "crlf.amc").write_bytes(amc.replace(b"\n", b"\r\n"))
    a = parse_amc(tmp_path / "lf.amc", parse_asf(tmp_path / "lf.asf"))
    b = parse_amc(tmp_path / "crlf.amc", parse_asf(tmp_path / "crlf.asf"))
    np.testing.assert_array_equal(a.root, b.root)
    np.testing.assert_array_equal(a.angles["rhumerus"], b.angles["rhumerus"])


def test_incomplete_final_frame_is_dropped_with_a_note_unless_strict(cmu_dir):
    skel = parse_asf(cmu_dir / "07" / "07.asf")
    with pytest.warns(MotionDataWarning, match=r"07_12\.amc:\d+: truncated frame 245"):
        motion = parse_amc(cmu_dir / "07" / "07_12.amc", skel)
    assert motion.n_frames == 244 and motion.notes
    with pytest.raises(MotionDataError, match="truncated frame 245: missing ltoes"):
        parse_amc(cmu_dir / "07" / "07_12.amc", skel, strict=True)


# ---------------------------------------------------------------------------- malformed input

ASF = """\
:version 1.10
:name tiny
:units
  mass 1.0
  length 0.45
  angle deg
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name hip
     direction 0 -1 0
     length 5
     axis 0 0 0 XYZ
    dof rx ry rz
    limits (-90 90)
           (-90 90)
           (-90 90)
  end
  begin
     id 2
     name knee
     direction 0 -1 0
     length 5
     axis 0 0 0 XYZ
    dof rx
    limits (0 170)
  end
:hierarchy
  begin
    root hip
    hip knee
  end
"""

AMC = """\
:FULLY-SPECIFIED
:DEGREES
1
root 0 30 0 0 0 0
hip 10 0 0
knee 20
2
root 0 30 1 0 0 0
hip 11 0 0
knee 21
3
root 0 30 2 0 0 0
hip 12 0 0
knee 22
"""


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_tiny_files_parse(tmp_path):
    skel = parse_asf(write(tmp_path, "t.asf", ASF))
    m = parse_amc(write(tmp_path, "t.amc", AMC), skel)
    assert m.n_frames == 3
    np.testing.assert_allclose(m.root[:, 2], np.array([0, 1, 2]) * 0.0254 / 0.45)
    np.testing.assert_allclose(m.angles["knee"][:, 0], [20, 21, 22])


def line_of(text: str, needle: str) -> int:
    return next(i for i, ln in enumerate(text.splitlines(), 1) if needle in ln)


AMC_CASES = {
    "truncated frame": (
        AMC.replace("knee 21\n", ""),
        "knee 21",
        r"t\.amc:\d+: truncated frame 2: missing knee",
    ),
    "unknown bone": (AMC.replace("hip 11", "hop 11"), "hop 11", r"unknown bone 'hop'; known:"),
    "wrong number of values": (
        AMC.replace("hip 11 0 0", "hip 11 0"),
        "hip 11 0",
        r"bone 'hip' needs 3 values, got 2",
    ),
    "non-numeric token": (
        AMC.replace("knee 22", "knee 2x2"),
        "knee 2x2",
        r"non-numeric value '2x2'",
    ),
    "duplicate bone in frame": (
        AMC.replace("knee 21\n", "knee 21\nknee 21\n"),
        None,
        r"bone 'knee' appears twice",
    ),
    "out-of-order frame number": (AMC.replace("\n2\n", "\n7\n"), None, r"frame number 7"),
}


@pytest.mark.parametrize("case", sorted(AMC_CASES))
def test_malformed_amc_names_file_line_and_problem(tmp_path, case):
    text, needle, pattern = AMC_CASES[case]
    skel = parse_asf(write(tmp_path, "t.asf", ASF))
    amc = write(tmp_path, "t.amc", text)
    with pytest.raises(MotionDataError, match=pattern) as err:
        parse_amc(amc, skel, strict=True)
    assert str(amc) in str(err.value)
    assert err.value.line is not None
    if needle is not None and case != "truncated frame":
        assert err.value.line == line_of(text, needle)


def test_truncated_frame_in_the_middle_is_an_error_even_when_lenient(tmp_path):
    skel = parse_asf(write(tmp_path, "t.asf", ASF))
    amc = write(tmp_path, "t.amc", AMC.replace("knee 21\n", ""))
    with pytest.raises(MotionDataError, match="truncated frame 2"):
        parse_amc(amc, skel)


ASF_CASES = {
    "missing section": (
        re.sub(r":hierarchy.*", "", ASF, flags=re.S),
        r"missing section ':hierarchy'",
    ),
    "duplicate bone": (ASF.replace("name knee", "name hip"), r"duplicate bone 'hip'"),
    "hierarchy cycle": (
        ASF.replace("root hip\n    hip knee", "root hip\n    knee hip\n    hip knee"),
        r"two parents|cycle",
    ),
    "true cycle": (
        ASF.replace("root hip\n    hip knee", "knee hip\n    hip knee"),
        r"hierarchy cycle",
    ),
    "unknown bone in hierarchy": (ASF.replace("hip knee", "hip ankle"), r"unknown bone 'ankle'"),
    "non-numeric token": (ASF.replace("length 5\n", "length five\n", 1), r"non-numeric"),
    "wrong number of values": (ASF.replace("direction 0 -1 0", "direction 0 -1", 1), r"3 values"),
    "bad dof": (ASF.replace("dof rx\n", "dof rw\n"), r"unsupported dof 'rw'"),
}


@pytest.mark.parametrize("case", sorted(ASF_CASES))
def test_malformed_asf_names_file_and_problem(tmp_path, case):
    text, pattern = ASF_CASES[case]
    path = write(tmp_path, "bad.asf", text)
    with pytest.raises(MotionDataError, match=pattern) as err:
        parse_asf(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize("name", ["empty.asf", "empty.amc"])
def test_empty_files_are_named(tmp_path, name):
    path = write(tmp_path, name, "   \n")
    skel = parse_asf(write(tmp_path, "t.asf", ASF))
    with pytest.raises(MotionDataError, match=r"empty\.a[sm][fc]: empty file"):
        parse_asf(path) if name.endswith("asf") else parse_amc(path, skel)


def test_missing_file_is_a_motion_data_error(tmp_path):
    with pytest.raises(MotionDataError, match="cannot read file"):
        parse_asf(tmp_path / "nope.asf")


def test_binary_garbage_is_a_clear_error(tmp_path):
    path = tmp_path / "junk.amc"
    path.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(MotionDataError):
        parse_amc(path, parse_asf(write(tmp_path, "t.asf", ASF)))
