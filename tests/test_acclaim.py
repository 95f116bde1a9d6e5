"""Acclaim reading: every real file loads; every kind of malformed input gets one clear error."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from sim.acclaim.amc import parse_amc
from sim.acclaim.asf import parse_asf
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


def knee_renamed(name: str) -> str:
    """The tiny ASF with its bone ``knee`` called ``name`` (in its definition and the hierarchy)."""
    return ASF.replace("name knee", f"name {name}").replace("hip knee", f"hip {name}")


# ------------------------------------------------------------- hostile input ----------------
# Each case is the tiny ASF/AMC above with one change; the error must be a MotionDataError naming
# the file and the line of the change.

HOSTILE_ASF = {
    "limits without dof": (
        ASF.replace("    dof rx\n", ""),
        "limits (0 170)",
        r"0 dofs but 1 limits",
    ),
    "nan in axis": (ASF.replace("axis 0 0 0 XYZ", "axis 0 nan 0 XYZ", 1), "nan", r"non-finite"),
    "inf in axis": (ASF.replace("axis 0 0 0 XYZ", "axis 0 0 -inf XYZ", 1), "inf", r"non-finite"),
    "nan root orientation": (
        ASF.replace("orientation 0 0 0", "orientation nan 0 0"),
        "orientation nan",
        r"non-finite value 'nan' in root orientation",
    ),
    "inf units length": (ASF.replace("length 0.45", "length inf"), "length inf", r"non-finite"),
    "tiny units length": (
        ASF.replace("length 0.45", "length 1e-300"),
        "length 1e-300",
        r"units length 1e-300 outside",
    ),
    "inf bone length": (ASF.replace("length 5\n", "length inf\n", 1), "length inf", r"non-finite"),
    "overflowing bone length": (
        ASF.replace("length 5\n", "length 1e308\n", 1),
        "length 1e308",
        r"exceeds 10000 m",
    ),
    "nan limit": (ASF.replace("(0 170)", "(nan 170.0)"), "(nan 170.0)", r"non-finite"),
    "inverted limit": (ASF.replace("(0 170)", "(170 0)"), "(170 0)", r"lower above upper"),
    "junk after limits": (ASF.replace("(0 170)", "(0 170) x"), "(0 170) x", r"cannot read limits"),
    "huge axis angle": (
        ASF.replace("axis 0 0 0 XYZ", "axis 0 0 1e300 XYZ", 1),
        "1e300",
        r"exceeds 100000",
    ),
    "zero direction": (ASF.replace("direction 0 -1 0", "direction 0 0 0", 1), "begin", r"zero"),
    "quote in bone name": (
        knee_renamed('kn"ee'),
        'name kn"ee',
        r"is not of the form",
    ),
    "angle bracket and ampersand in bone name": (
        knee_renamed("<a&b>"),
        "name <a&b>",
        r"is not of the form",
    ),
    "unicode bone name": (
        knee_renamed("kné"),
        "name kné",
        r"is not of the form",
    ),
    "numeric bone name": (
        knee_renamed("12"),
        "name 12",
        r"is not of the form",
    ),
    "reserved bone name": (
        knee_renamed("floor"),
        "name floor",
        r"reserved",
    ),
    "bone missing from the hierarchy": (
        ASF.replace("    hip knee\n", ""),
        "id 2",
        r"bones not in ':hierarchy': knee",
    ),
    "cycle": (ASF.replace("root hip\n    hip knee", "knee hip\n    hip knee"), "id 1", r"cycle"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE_ASF))
def test_hostile_asf_is_refused_on_its_line(tmp_path, case):
    text, needle, pattern = HOSTILE_ASF[case]
    path = write(tmp_path, "bad.asf", text)
    with pytest.raises(MotionDataError, match=pattern) as err:
        parse_asf(path)
    assert err.value.path == str(path)
    # Bone-level problems point at the bone's 'begin' (the line before its 'id').
    expected = line_of(text, needle) - (1 if needle.startswith("id ") else 0)
    assert err.value.line == expected, (err.value, expected)


def test_radian_asf_bounds_apply_in_radians(tmp_path):
    text = ASF.replace("angle deg", "angle rad").replace("(0 170)", "(0 3000)")
    with pytest.raises(MotionDataError, match="exceeds 1745"):
        parse_asf(write(tmp_path, "t.asf", text))


def test_limits_on_one_line_and_limits_after_each_dof_count(tmp_path):
    one_line = ASF.replace("limits (-90 90)\n           (-90 90)\n", "limits (-90 90) (-90 90)\n")
    skel = parse_asf(write(tmp_path, "t.asf", one_line))
    np.testing.assert_array_equal(skel.bone("hip").limits, [[-90, 90]] * 3)
    too_few = ASF.replace("           (-90 90)\n           (-90 90)\n", "")
    with pytest.raises(MotionDataError, match="3 dofs but 1 limits") as err:
        parse_asf(write(tmp_path, "few.asf", too_few))
    assert err.value.line == line_of(too_few, "limits (-90 90)")


def test_deep_or_huge_skeletons_are_refused_before_building_a_model(tmp_path):
    from sim.acclaim.records import MAX_DEPTH

    n = MAX_DEPTH + 1
    blocks = "".join(
        f"  begin\n     name b{i}\n     direction 0 -1 0\n     length 0.1\n  end\n"
        for i in range(n)
    )
    chain = "".join(f"    {'root' if i == 0 else f'b{i - 1}'} b{i}\n" for i in range(n))
    text = ASF.split(":bonedata")[0] + ":bonedata\n" + blocks + ":hierarchy\n  begin\n" + chain
    text += "  end\n"
    path = write(tmp_path, "deep.asf", text)
    with pytest.raises(MotionDataError, match=f"more than {MAX_DEPTH} bones deep") as err:
        parse_asf(path)
    assert err.value.line == line_of(text, f"name b{MAX_DEPTH}") - 1


def test_a_chain_at_the_depth_limit_builds_a_mujoco_model(tmp_path):
    import mujoco

    from sim.acclaim.records import MAX_DEPTH
    from sim.model.humanoid import build_mjcf

    n = MAX_DEPTH
    blocks = "".join(
        f"  begin\n     name b{i}\n     direction 0 -1 0\n     length 0.1\n     dof rx\n  end\n"
        for i in range(n)
    )
    chain = "".join(f"    {'root' if i == 0 else f'b{i - 1}'} b{i}\n" for i in range(n))
    text = ASF.split(":bonedata")[0] + ":bonedata\n" + blocks + ":hierarchy\n  begin\n" + chain
    skel = parse_asf(write(tmp_path, "deep.asf", text + "  end\n"))
    model = mujoco.MjModel.from_xml_string(build_mjcf(skel))
    assert model.nbody == n + 2  # world, root, one per bone


def test_model_name_is_escaped_and_in_memory_bad_names_are_refused(tmp_path):
    import dataclasses

    import mujoco

    from sim.model.humanoid import build_mjcf

    skel = parse_asf(write(tmp_path, "t.asf", ASF.replace(":name tiny", ':name a"<b>&c')))
    model = mujoco.MjModel.from_xml_string(build_mjcf(skel))
    assert model.nbody == 4
    bad = dataclasses.replace(skel.bones[1], name='x"y')
    with pytest.raises(MotionDataError, match="is not of the form"):
        build_mjcf(dataclasses.replace(skel, bones=(skel.bones[0], bad)))


def amc_with(text_before: str, text_after: str) -> str:
    assert text_before in AMC
    return AMC.replace(text_before, text_after)


HOSTILE_AMC = {
    "frame number >= 2^63": (amc_with("\n2\n", "\n9223372036854775808\n"), "9223372036854775808"),
    "frame number of 5000 digits": (amc_with("\n2\n", "\n" + "7" * 5000 + "\n"), "7777"),
    "unicode digit frame number": (amc_with("\n2\n", "\n²\n"), "²"),
    "first frame number unicode": (amc_with("\n1\n", "\n١\n"), "١"),
    "nan angle": (amc_with("knee 21", "knee nan"), "knee nan"),
    "inf translation": (amc_with("root 0 30 1 0 0 0", "root 0 inf 1 0 0 0"), "root 0 inf"),
    "1e308 translation": (amc_with("root 0 30 1 0 0 0", "root 0 1e308 1 0 0 0"), "1e308"),
    "1e300 angle": (amc_with("hip 12 0 0", "hip 12 1e300 0"), "1e300"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE_AMC))
def test_hostile_amc_is_refused_on_its_line(tmp_path, case):
    text, needle = HOSTILE_AMC[case]
    skel = parse_asf(write(tmp_path, "t.asf", ASF))
    amc = write(tmp_path, "t.amc", text)
    with pytest.raises(MotionDataError) as err:
        parse_amc(amc, skel)
    assert err.value.path == str(amc)
    assert err.value.line == line_of(text, needle), err.value


def test_1e308_root_translation_in_every_frame_is_refused_on_the_first_line(tmp_path):
    skel = parse_asf(write(tmp_path, "t.asf", ASF))
    text = re.sub(r"root 0 30", "root 1e308 30", AMC)
    amc = write(tmp_path, "t.amc", text)
    with pytest.raises(MotionDataError, match="exceeds") as err:
        parse_amc(amc, skel)
    assert err.value.line == line_of(text, "root 1e308")


def test_frames_without_root_or_with_only_dofless_bones_are_refused(tmp_path):
    asf = ASF.replace("    dof rx\n    limits (0 170)\n", "")  # knee: no dofs
    skel = parse_asf(write(tmp_path, "t.asf", asf))
    no_root = re.sub(r"root [^\n]*\n", "", AMC).replace("knee 20\n", "").replace("knee 21\n", "")
    no_root = no_root.replace("knee 22\n", "")
    path = write(tmp_path, "noroot.amc", no_root)
    with pytest.raises(MotionDataError, match="no 'root' line") as err:
        parse_amc(path, skel)
    assert err.value.line == line_of(no_root, "1")
    only_dofless = ":FULLY-SPECIFIED\n:DEGREES\n1\nknee\n2\nknee\n"
    path = write(tmp_path, "dofless.amc", only_dofless)
    with pytest.raises(MotionDataError, match="no 'root' line") as err:
        parse_amc(path, skel)
    assert err.value.line == 3


def test_lone_cr_line_ends_count_as_lines(tmp_path):
    skel = parse_asf(write(tmp_path, "t.asf", ASF))
    text = AMC.replace("knee 22", "knee 2x2")
    path = tmp_path / "cr.amc"
    path.write_bytes(text.replace("\n", "\r").encode())
    with pytest.raises(MotionDataError, match="non-numeric") as err:
        parse_amc(path, skel)
    assert err.value.line == line_of(text, "knee 2x2")
    path.write_bytes(AMC.replace("\n", "\r").encode())
    np.testing.assert_array_equal(
        parse_amc(path, skel).root, parse_amc(write(tmp_path, "lf.amc", AMC), skel).root
    )


def test_unicode_or_signed_frame_numbers_mid_file_are_refused_on_their_line(tmp_path):
    skel = parse_asf(write(tmp_path, "t.asf", ASF))
    for number in ("٣", "+3", "3_0"):
        text = amc_with("\n3\n", f"\n{number}\n")
        amc = write(tmp_path, "t.amc", text)
        with pytest.raises(MotionDataError) as err:
            parse_amc(amc, skel)
        assert err.value.line == line_of(text, number), (number, err.value)


def test_too_many_bones_are_refused_at_the_first_extra_bone(tmp_path):
    from sim.acclaim.records import MAX_BONES

    blocks = "".join(
        f"  begin\n     name b{i}\n     direction 0 -1 0\n     length 0.1\n  end\n"
        for i in range(MAX_BONES + 5)
    )
    text = ASF.split(":bonedata")[0] + ":bonedata\n" + blocks + ":hierarchy\n  begin\n  end\n"
    with pytest.raises(MotionDataError, match=f"more than {MAX_BONES} bones") as err:
        parse_asf(write(tmp_path, "many.asf", text))
    # The 'begin' line of the first extra bone (1-based: the 0-based index of its name line).
    assert err.value.line == text.splitlines().index(f"     name b{MAX_BONES}")


def test_huge_tokens_give_a_bounded_message_that_survives_pickling(tmp_path):
    import pickle

    skel = parse_asf(write(tmp_path, "t.asf", ASF))
    text = amc_with("hip 11 0 0", "x" * 100_000 + " 11 0 0")
    with pytest.raises(MotionDataError, match="unknown bone") as err:
        parse_amc(write(tmp_path, "t.amc", text), skel)
    assert len(err.value.problem) <= MotionDataError.MAX_PROBLEM
    assert str(pickle.loads(pickle.dumps(err.value))) == str(err.value)


def _frames_edited(cmu_dir, tmp_path, edits: dict[int, str]) -> tuple[Path, list[str]]:
    """02_01.amc with line ``i`` (0-based) replaced by ``edits[i]`` (LF line breaks)."""
    lines = (cmu_dir / "02" / "02_01.amc").read_text().splitlines()
    for i, text in edits.items():
        lines[i] = text
    path = tmp_path / "edited.amc"
    path.write_text("\n".join(lines) + "\n")
    return path, lines


def _bone_lines(cmu_dir, bone: str) -> list[int]:
    lines = (cmu_dir / "02" / "02_01.amc").read_text().splitlines()
    return [i for i, ln in enumerate(lines) if ln.startswith(bone + " ")]


def test_lines_whose_miscounts_cancel_out_are_refused_on_the_first(cmu_dir, tmp_path):
    # one line with a value too many, a later one of the same bone with one too few: the
    # chunk's totals match, each line's count does not (the fast path must not take it)
    skel = parse_asf(cmu_dir / "02" / "02.asf")
    rows = _bone_lines(cmu_dir, "lfemur")
    a, b = rows[100], rows[140]
    original = (cmu_dir / "02" / "02_01.amc").read_text().splitlines()

    def more(k):
        return original[k] + " 1.5"

    def fewer(k):
        return " ".join(original[k].split()[:-1])

    for edits, bad, got in (
        ({a: more(a), b: fewer(b)}, a, 4),
        ({a: fewer(a), b: more(b)}, a, 2),
        ({b: more(b)}, b, 4),  # only a value too many
    ):
        path, _ = _frames_edited(cmu_dir, tmp_path, edits)
        with pytest.raises(MotionDataError, match=rf"'lfemur' needs 3 values, got {got}") as err:
            parse_amc(path, skel)
        assert err.value.line == bad + 1


@pytest.mark.parametrize("blank", ["\t", "  ", "\x1f", "\xa0"])
def test_values_split_by_other_blanks_read_as_with_single_spaces(cmu_dir, tmp_path, blank):
    # one line's values split by another blank, a later line with values too many: the
    # chunk's count of spaces matches, each line's count of values does not
    skel = parse_asf(cmu_dir / "02" / "02.asf")
    lines = (cmu_dir / "02" / "02_01.amc").read_text().splitlines()
    i, j = _bone_lines(cmu_dir, "lfemur")[50:52]
    name, *values = lines[i].split()
    spread = name + " " + blank.join(values)
    extra = 1 if blank == "  " else 2  # as many spaces as the blanks took (a run: one)
    path, _ = _frames_edited(cmu_dir, tmp_path, {i: spread, j: lines[j] + " 7.5" * extra})
    with pytest.raises(MotionDataError, match=rf"'lfemur' needs 3 values, got {3 + extra}") as err:
        parse_amc(path, skel)
    assert err.value.line == j + 1
    path, _ = _frames_edited(cmu_dir, tmp_path, {i: spread})
    edited = parse_amc(path, skel)
    whole = parse_amc(cmu_dir / "02" / "02_01.amc", skel)
    np.testing.assert_array_equal(edited.angles["lfemur"], whole.angles["lfemur"])
    np.testing.assert_array_equal(edited.root, whole.root)
