"""The range coder's bytes never change with its speed: the compiled encoder writes what a plain
Python transcription of the coder (sidql.codec.entropy's module docstring, LZMA's range coder)
writes, integer for integer, and two blocks keep the digests they had before its branch-free
form."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from sidql.codec import entropy as E
from sidql.codec.entropy import encode_integers


class _Coder:
    """LZMA's range encoder in plain Python (32-bit range, carry through a cached byte)."""

    def __init__(self):
        self.low, self.rng, self.cache, self.csize, self.out = 0, 0xFFFFFFFF, 0, 1, bytearray()

    def _shift(self):
        if self.low < 0xFF000000 or self.low > 0xFFFFFFFF:
            carry, temp = self.low >> 32, self.cache
            while True:
                self.out.append((temp + carry) & 0xFF)
                temp = 0xFF
                self.csize -= 1
                if self.csize == 0:
                    break
            self.cache = (self.low >> 24) & 0xFF
        self.csize += 1
        self.low = (self.low & 0x00FFFFFF) << 8

    def _normalise(self):
        while self.rng < 1 << 24:
            self.rng = (self.rng << 8) & 0xFFFFFFFF
            self._shift()

    def bit(self, probs, i, bit):
        bound = (self.rng >> 11) * probs[i]
        if bit:
            self.low += bound
            self.rng -= bound
            probs[i] -= probs[i] >> 4
        else:
            self.rng = bound
            probs[i] += (2048 - probs[i]) >> 4
        self._normalise()

    def direct(self, bit):
        self.rng >>= 1
        self.low += self.rng if bit else 0
        self._normalise()

    def finish(self) -> bytes:
        for _ in range(5):
            self._shift()
        return bytes(self.out)


def reference(values: np.ndarray, kinds: np.ndarray) -> bytes:
    """The module docstring's binarisation, one channel after the other, in plain Python."""
    C, W = values.shape
    per = E._PER_CHANNEL
    probs = list(E._PRIOR) * (C + (max(kinds.max(), -1) + 1) * E.SCALE_BUCKETS)
    column, counted, coder = [0] * W, 0, _Coder()
    for c in range(C):
        prev_zero, prev_sign, mean = 0, 2, E._SCALE_START
        for w in range(W):
            r = int(values[c, w])
            if kinds[c] < 0:
                base = c * per
            else:
                act = 256 if counted == 0 else column[w] // counted
                bucket = min(max((((mean * act) >> 8) + 4).bit_length() - 2, 0), 7)
                base = (C + kinds[c] * E.SCALE_BUCKETS + bucket) * per
                a16 = 16 * min(abs(r), E._SURPRISE_CAP)
                column[w] += ((a16 + 8) << 8) // (mean + 8)
                mean += (a16 - mean) >> 2
            coder.bit(probs, base + prev_zero, r != 0)
            if r == 0:
                prev_zero, prev_sign = 1, 2
                continue
            neg = int(r < 0)
            coder.bit(probs, base + 2 + prev_sign, neg)
            prev_zero, prev_sign, a = 0, neg, abs(r)
            k = a.bit_length()
            for u in range(1, k):
                coder.bit(probs, base + 5 + u, 1)
            if k < E.MAX_CLASS:
                coder.bit(probs, base + 5 + k, 0)
            if k >= 2:
                coder.bit(probs, base + 5 + E.MAX_CLASS + 1 + k, (a >> (k - 2)) & 1)
                for b in range(k - 3, -1, -1):
                    coder.direct((a >> b) & 1)
        counted += int(kinds[c] >= 0)
    return coder.finish()


@pytest.mark.parametrize("seed", range(12))
def test_the_compiled_coder_writes_what_the_plain_one_does(seed):
    rng = np.random.default_rng(seed)
    C, W = int(rng.integers(1, 6)), int(rng.integers(1, 90))
    scale = [0.2, 2.0, 40.0, 5000.0][seed % 4]
    values = np.round(rng.standard_cauchy((C, W)) * scale).astype(np.int64)
    values = values.clip(-(2**29), 2**29)
    kinds = rng.integers(-1, 3, C).astype(np.int64) if seed % 3 else np.full(C, -1)
    E._CODED.clear()  # coded afresh, not the kept bytes of an earlier call
    assert encode_integers(values, kinds=kinds) == reference(values, kinds)


def test_two_blocks_keep_their_bytes():
    rng = np.random.default_rng(2026)
    kinds = np.r_[-1, np.zeros(22), np.ones(22), np.full(3, 2)].astype(np.int64)
    v = np.round(rng.standard_t(2, (48, 700)) * rng.uniform(0.2, 60, (48, 1))).astype(np.int64)
    v[:, ::7] = 0
    w = np.round(rng.standard_cauchy((5, 300)) * 4000).astype(np.int64).clip(-(2**29), 2**29)
    E._CODED.clear()
    digests = [
        hashlib.sha256(encode_integers(v, kinds=kinds)).hexdigest(),
        hashlib.sha256(encode_integers(w, group=rng.integers(0, 3, 300))).hexdigest(),
    ]
    assert digests == [
        "13ba58136505034acaab94f1bc5899003767bf2def9a0d482fa53dc68bf95dba",
        "a80bb5f2c3026a3ff26b70631d6f8a87ff1c43a417451fa0e4b880921d4d13af",
    ]
