"""The motion readers' compiled fast path (sim.decimals, sim.acclaim.frames): every number it
takes is the double Python's float() gives, bit for bit, and it refuses (None: the reader then
reads the text as before) every token outside the readers' strict grammar, every number it
cannot convert exactly and every run of AMC frames not laid out exactly like the first."""

from __future__ import annotations

import random
import re

import numpy as np
import pytest

from sim.acclaim.frames import read_run
from sim.decimals import parse_table

#: the readers' grammar, written out here (an oracle sharing no code with the parser)
STRICT = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z")
HOSTILE = ["nan", "inf", "-inf", "1_0", "0x10", "1e", "1e+", ".", "+", "-", "--1", "+-1", "1..2",
           "1.2.3", "\u0661", "1,5", "e5", "1e5.5", "1\x1f2", "1d5", "٣", "１", "1e 5", "0b1",
           "1.5f", "1e99999999999", "2e400"]  # fmt: skip


def _token(rng: random.Random) -> str:
    k = rng.random()
    if k < 0.4:
        return f"{rng.uniform(-400, 400):.{rng.randint(0, 8)}f}"
    if k < 0.6:
        return repr(rng.uniform(-1e3, 1e3) * 10.0 ** rng.randint(-30, 30))
    s = rng.choice(["", "+", "-"]) + "".join(rng.choices("0123456789", k=rng.randint(0, 20)))
    if rng.random() < 0.5:
        s += "." + "".join(rng.choices("0123456789", k=rng.randint(0, 10)))
    if rng.random() < 0.3:
        s += rng.choice("eE") + rng.choice(["", "+", "-"]) + str(rng.randint(0, 40))
    return s


def test_every_number_taken_is_pythons_float_bit_for_bit():
    rng = random.Random(5)
    taken = 0
    for _ in range(20000):
        tokens = [_token(rng) for _ in range(4)]
        got = parse_table(" ".join(tokens), 1, 4)
        if got is None:
            continue
        assert all(STRICT.match(t) for t in tokens), tokens
        assert got.tobytes() == np.array([float(t) for t in tokens]).tobytes(), tokens
        taken += 1
    assert taken > 5000  # most plain decimals are taken
    typical = "-12.345678 0.000000 -0 1e-5 +.5 7. 9007199254740992"  # 2^53
    assert parse_table(typical, 1, 7) is not None


@pytest.mark.parametrize("bad", HOSTILE)
def test_tokens_outside_the_grammar_are_refused(bad):
    assert parse_table(f"1 {bad} 2", 1, 3) is None


def test_tables_with_another_shape_or_spacing_are_refused():
    assert parse_table("1 2\t3\n 4  5 6 ", 2, 3).tolist() == [[1, 2, 3], [4, 5, 6]]
    for text in ("1 2", "1 2 3 4", "1 2 3\n4 5 6\n", "1 2 3\n\n4 5 6", "1 2 3\r4 5 6"):
        assert parse_table(text, 2 if "4" in text else 1, 3) is None, text
    assert parse_table("root 1 2\nroot 3 4", 2, 2, skip=5).tolist() == [[1, 2], [3, 4]]


NAMES, COUNTS = ("root", "lfemur", "lhand", "rfoot"), (6, 3, 0, 2)


def _frame(n: int, values) -> list[str]:
    v = iter(values)
    lines = [str(n)]
    for name, k in zip(NAMES, COUNTS, strict=True):
        lines.append(" ".join([name] + [next(v) for _ in range(k)]))
    return lines


def _run(first: int = 7, frames: int = 3) -> tuple[list[str], np.ndarray]:
    rng = random.Random(first)
    values = [[f"{rng.uniform(-180, 180):.6f}" for _ in range(sum(COUNTS))] for _ in range(frames)]
    lines = [line for t, v in enumerate(values) for line in _frame(first + t, v)]
    return lines, np.array([[float(x) for x in v] for v in values])


def test_a_run_of_frames_reads_as_pythons_floats():
    lines, want = _run()
    got = read_run(lines, NAMES, COUNTS, 7)
    assert got is not None and got.tobytes() == want.tobytes()
    lines[0] = "  0007\t"  # blanks around the frame number, leading zeros: as the reader allows
    assert read_run(lines, NAMES, COUNTS, 7).tobytes() == want.tobytes()


@pytest.mark.parametrize(
    "mutate",
    [
        lambda ls: ls.__setitem__(0, "8"),  # a frame number that does not follow on
        lambda ls: ls.__setitem__(5, "10000000000000"),  # 14 digits
        lambda ls: ls.__setitem__(1, ls[1].replace(" ", "  ", 1)),  # two spaces
        lambda ls: ls.__setitem__(1, ls[1].replace(" ", "\t", 1)),  # a tab
        lambda ls: ls.__setitem__(1, ls[1] + " "),  # a trailing space
        lambda ls: ls.__setitem__(1, ls[1] + " 1.0"),  # a value too many
        lambda ls: ls.__setitem__(2, ls[2].rsplit(" ", 1)[0]),  # a value too few
        lambda ls: ls.__setitem__(2, "rfemur" + ls[2][6:]),  # another bone
        lambda ls: ls.__setitem__(3, "lhand 0"),  # values for a bone without
        lambda ls: ls.__setitem__(4, ls[4].replace("rfoot", "rfoöt")),  # not ASCII
        lambda ls: ls.__setitem__(4, ls[4].rsplit(" ", 1)[0] + " nan"),
        lambda ls: ls.__setitem__(9, ""),  # a blank line inside the run
        lambda ls: ls.pop(),  # a frame cut short
    ],
)
def test_a_run_not_laid_out_exactly_like_the_first_frame_is_refused(mutate):
    lines, _ = _run()
    mutate(lines)
    assert read_run(lines, NAMES, COUNTS, 7) is None
