"""Adaptive binary range coding of small signed integers, channel by channel (numba).

The coder is LZMA's range coder (Pavlov; 32-bit range, 11-bit probabilities adapted by a shift
of 5, carry propagated through a cached byte), driven by a binarisation that suits prediction
residuals of smooth signals. Each integer ``r`` of channel ``c`` is sent as

* ``r == 0`` (one bit; context: the channel and whether its previous residual was zero),
* else the sign (context: the channel and the previous residual's sign), then ``|r| - 1`` in
  Elias-gamma form: the bit length ``k`` of ``|r|`` in unary (one adaptive context per unary
  position per channel, up to :data:`MAX_CLASS`), then the ``k - 1`` bits below the leading one,
  the first of them adaptive (context: channel and ``k``), the rest with a fixed probability 1/2.

Every channel has its own contexts, so channels of very different spread (a quiet spine, a busy
wrist) each get a code fitted to them as the stream goes. Residuals are limited to
``|r| < 2^MAX_CLASS``.

Decoding is bounded by construction: the caller gives the count of integers (checked against the
stream's limits first); reads past the end of the data see zero bytes, so corrupt input decodes to
some integers (caught by the container's checksum) and never reads out of bounds.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

import numba
import numpy as np
from numba.cpython.unsafe.numbers import leading_zeros

from sim.errors import UsageError

#: largest bit length of a residual's magnitude (|r| < 2^MAX_CLASS).
MAX_CLASS = 30
_PROB_BITS = 11
_PROB_INIT = 1 << (_PROB_BITS - 1)
_MOVE = 4
_TOP = 1 << 24
_MASK32 = 0xFFFFFFFF
# contexts per channel: zero flag (2), sign (3), unary (MAX_CLASS + 1), first mantissa bit
_ZERO, _SIGN, _UNARY, _MANT = 0, 2, 5, 5 + MAX_CLASS + 1
_PER_CHANNEL = _MANT + MAX_CLASS + 1
#: shared contexts (``kinds``): buckets of the expected magnitude, the running mean's
#: adaptation shift, its start (|r| = 2, x 16) and the largest |r| it counts.
SCALE_BUCKETS = 8
_SCALE_SHIFT = 2
_SCALE_START = 32
_SURPRISE_CAP = 1 << 20
#: the most kinds of shared contexts
MAX_KINDS = 16
# the most bytes one integer can add: its adaptive bits (zero flag, sign, unary, first mantissa
# bit) under 8 bits each (a probability adapted by a shift of _MOVE stays within [15, 2033] /
# 2048: log2(2048 / 15) < 7.1), its direct bits 1 bit each, and the 5 bytes of the final flush
_INTEGER_BYTES = ((2 + MAX_CLASS + 1) * 8 + MAX_CLASS) // 8 + 8


def _prior() -> np.ndarray:
    """Every context's starting probability of a 0 bit, in 1/2048: typical of the position
    coding's residuals (measured on the CMU trials of ``../shared``; each context then adapts),
    so short streams do not pay for learning the obvious."""
    p = np.full(_PER_CHANNEL, 0.5)
    p[_ZERO : _ZERO + 2] = (0.15, 0.49)  # zero flag after a non-zero / after a zero residual
    p[_SIGN : _SIGN + 3] = (0.57, 0.43, 0.5)  # sign after a positive / negative / zero one
    stop = (0.32, 0.39, 0.48, 0.57, 0.64, 0.69, 0.7)  # unary: P(|r| has u bits | >= u bits)
    p[_UNARY + 1 : _UNARY + 1 + len(stop)] = stop
    p[_UNARY + 1 + len(stop) : _UNARY + MAX_CLASS + 1] = 0.7
    p[_MANT + 2 : _MANT + 9] = (0.62, 0.63, 0.65, 0.68, 0.72, 0.72, 0.7)  # first mantissa bit
    return np.round(p * (1 << _PROB_BITS)).astype(np.int64)


_PRIOR = _prior()

#: the blocks :func:`encode_integers` coded last, by their inputs (all of them, compared whole):
#: a caller that sizes a block and then writes it (the position coding) codes it once. At most
#: :data:`_KEEP` kept (a block of 900 keyframes: about 0.4 MB).
_KEEP = 4
_CODED: OrderedDict = OrderedDict()
_LOCK = threading.Lock()


@numba.njit(cache=True, inline="always")
def _shift_low(low, cache, csize, pos, out):
    if low < 0xFF000000 or low > _MASK32:
        carry = low >> 32
        temp = cache
        while True:
            out[pos] = (temp + carry) & 0xFF
            pos += 1
            temp = 0xFF
            csize -= 1
            if csize == 0:
                break
        cache = (low >> 24) & 0xFF
    csize += 1
    low = (low & 0x00FFFFFF) << 8
    return low, cache, csize, pos


# The coded bits are as good as random to the processor: they pick values with masks rather than
# branches it would guess wrong half the time (the same integers).
@numba.njit(cache=True, inline="always")
def _bit(low, rng, cache, csize, pos, out, probs, i, bit):
    p = probs[i]
    bound = (rng >> _PROB_BITS) * p
    one = -np.int64(bit)  # all ones for a 1 bit, else 0
    low += bound & one
    rng = bound ^ ((bound ^ (rng - bound)) & one)  # 0: bound; 1: rng - bound
    up = p + (((1 << _PROB_BITS) - p) >> _MOVE)
    down = p - (p >> _MOVE)
    probs[i] = up ^ ((up ^ down) & one)
    while rng < _TOP:
        rng = (rng << 8) & _MASK32
        low, cache, csize, pos = _shift_low(low, cache, csize, pos, out)
    return low, rng, cache, csize, pos


@numba.njit(cache=True, inline="always")
def _direct(low, rng, cache, csize, pos, out, bit):
    rng = rng >> 1
    low += rng & -np.int64(bit)
    while rng < _TOP:
        rng = (rng << 8) & _MASK32
        low, cache, csize, pos = _shift_low(low, cache, csize, pos, out)
    return low, rng, cache, csize, pos


@numba.njit(cache=True)
def _initial_probs(contexts, prior):
    """(contexts * _PER_CHANNEL,) adaptive bit probabilities, every context starting at ``prior``
    (encoder and decoder must start alike)."""
    probs = np.empty(contexts * _PER_CHANNEL, dtype=np.int64)
    for j in range(contexts):
        probs[j * _PER_CHANNEL : (j + 1) * _PER_CHANNEL] = prior
    return probs


@numba.njit(cache=True, inline="always")
def _context_base(c, w, group, n_groups, kinds, sc, k, n):
    """Index of the first context of integer (c, w): the channel's own set (per column group),
    or with ``k = kinds[c] >= 0`` the set of its kind and its expected-magnitude bucket
    (:func:`_bucket`; ``n = sc[1]``)."""
    if k < 0:
        return (c * n_groups + group[w]) * _PER_CHANNEL
    C = kinds.shape[0]
    return (C * n_groups + k * SCALE_BUCKETS + _bucket(w, sc, n)) * _PER_CHANNEL


@numba.njit(cache=True, inline="always")
def _bucket(w, sc, n):
    """The expected-magnitude bucket of column w of the current channel: log2 of the channel's
    running mean |r| times the column's activity (the mean surprise of the channels coded
    before it at this column, 1 if none), integers only (encoder and decoder agree on every
    machine). ``sc``: [mean x 16, channels counted (``n``), column sums (W) of surprise x
    256]."""
    act = 256 if n == 0 else sc[2 + w] // n
    sig = (sc[0] * act) >> 8
    return min(max(_bit_length(sig + 4) - 2, 0), SCALE_BUCKETS - 1)


@numba.njit(cache=True, inline="always")
def _bit_length(a):
    """The bit length of ``a`` >= 0 (0 for 0), as ``int.bit_length``: one instruction."""
    return 64 - leading_zeros(np.int64(a))


@numba.njit(cache=True, inline="always")
def _after(w, a, sc):
    """Update the scale state ``sc`` (see :func:`_bucket`) with |r| = ``a`` at column w."""
    a16 = 16 * min(a, _SURPRISE_CAP)
    sc[2 + w] += ((a16 + 8) << 8) // (sc[0] + 8)
    sc[0] += (a16 - sc[0]) >> _SCALE_SHIFT


@numba.njit(cache=True, nogil=True)
def _encode_kernel(values, group, n_groups, prior, kinds):
    """values: (C, W) int64, sent channel by channel; group: (W,) context group of each column;
    kinds: (C,) -1 (own contexts) or a shared kind (see :func:`_context_base`).
    Returns the coded bytes."""
    C, W = values.shape
    out = np.empty(64 + C * W * 2, dtype=np.uint8)
    low, rng, cache, csize, pos = np.int64(0), np.int64(_MASK32), np.int64(0), np.int64(1), 0
    probs = _initial_probs(C * n_groups + (kinds.max() + 1) * SCALE_BUCKETS, prior)
    sc = np.zeros(2 + W, dtype=np.int64)
    for c in range(C):
        prev_zero = 0
        prev_sign = 2
        sc[0] = _SCALE_START
        kind, n = kinds[c], sc[1]  # read once: not told apart from the arrays written
        shared = (C * n_groups + kind * SCALE_BUCKETS) * _PER_CHANNEL  # kind >= 0: its sets
        for w in range(W):
            # room for one more integer: at most _INTEGER_BYTES plus the bytes the cache holds
            # back (a badly predicted large residual costs far more than its 8 raw bytes)
            if pos + csize + _INTEGER_BYTES > out.shape[0]:
                bigger = np.empty(2 * out.shape[0] + csize + _INTEGER_BYTES, dtype=np.uint8)
                bigger[:pos] = out[:pos]
                out = bigger
            r = values[c, w]
            if kind < 0:
                base = _context_base(c, w, group, n_groups, kinds, sc, kind, n)
            else:  # _context_base's, its channel's part worked out once
                base = shared + _bucket(w, sc, n) * _PER_CHANNEL
                _after(w, abs(r), sc)
            if r == 0:
                low, rng, cache, csize, pos = _bit(
                    low, rng, cache, csize, pos, out, probs, base + _ZERO + prev_zero, 0
                )
                prev_zero = 1
                prev_sign = 2
                continue
            low, rng, cache, csize, pos = _bit(
                low, rng, cache, csize, pos, out, probs, base + _ZERO + prev_zero, 1
            )
            prev_zero = 0
            neg = 1 if r < 0 else 0
            low, rng, cache, csize, pos = _bit(
                low, rng, cache, csize, pos, out, probs, base + _SIGN + prev_sign, neg
            )
            prev_sign = neg
            a = -r if neg else r
            k = _bit_length(a)
            for u in range(1, k):
                low, rng, cache, csize, pos = _bit(
                    low, rng, cache, csize, pos, out, probs, base + _UNARY + u, 1
                )
            if k < MAX_CLASS:
                low, rng, cache, csize, pos = _bit(
                    low, rng, cache, csize, pos, out, probs, base + _UNARY + k, 0
                )
            if k >= 2:
                low, rng, cache, csize, pos = _bit(
                    low, rng, cache, csize, pos, out, probs, base + _MANT + k, (a >> (k - 2)) & 1
                )
                for b in range(k - 3, -1, -1):
                    low, rng, cache, csize, pos = _direct(
                        low, rng, cache, csize, pos, out, (a >> b) & 1
                    )
        if kinds[c] >= 0:
            sc[1] += 1
    for _ in range(5):
        low, cache, csize, pos = _shift_low(low, cache, csize, pos, out)
    return out[:pos].copy()


@numba.njit(cache=True)
def _next_byte(data, st):
    pos = st[3]
    st[3] = pos + 1
    if pos < data.shape[0]:
        return np.int64(data[pos])
    return np.int64(0)


@numba.njit(cache=True)
def _decode_bit(data, st, probs, i):
    # st: [code, range, unused, pos]
    p = probs[i]
    bound = (st[1] >> _PROB_BITS) * p
    if st[0] < bound:
        st[1] = bound
        probs[i] = p + (((1 << _PROB_BITS) - p) >> _MOVE)
        bit = 0
    else:
        st[0] -= bound
        st[1] -= bound
        probs[i] = p - (p >> _MOVE)
        bit = 1
    while st[1] < _TOP:
        st[1] = (st[1] << 8) & _MASK32
        st[0] = ((st[0] << 8) | _next_byte(data, st)) & _MASK32
    return bit


@numba.njit(cache=True)
def _decode_direct(data, st):
    st[1] = st[1] >> 1
    bit = 0
    if st[0] >= st[1]:
        st[0] -= st[1]
        bit = 1
    while st[1] < _TOP:
        st[1] = (st[1] << 8) & _MASK32
        st[0] = ((st[0] << 8) | _next_byte(data, st)) & _MASK32
    return bit


@numba.njit(cache=True)
def _decode_kernel(data, C, W, group, n_groups, prior, kinds):
    values = np.zeros((C, W), dtype=np.int64)
    st = np.zeros(4, dtype=np.int64)
    st[1] = _MASK32
    for _ in range(5):
        st[0] = ((st[0] << 8) | _next_byte(data, st)) & _MASK32
    probs = _initial_probs(C * n_groups + (kinds.max() + 1) * SCALE_BUCKETS, prior)
    sc = np.zeros(2 + W, dtype=np.int64)
    for c in range(C):
        prev_zero = 0
        prev_sign = 2
        if c > 0 and kinds[c - 1] >= 0:
            sc[1] += 1
        sc[0] = _SCALE_START
        for w in range(W):
            base = _context_base(c, w, group, n_groups, kinds, sc, kinds[c], sc[1])
            if _decode_bit(data, st, probs, base + _ZERO + prev_zero) == 0:
                prev_zero = 1
                prev_sign = 2
                if kinds[c] >= 0:
                    _after(w, 0, sc)
                continue
            prev_zero = 0
            neg = _decode_bit(data, st, probs, base + _SIGN + prev_sign)
            prev_sign = neg
            k = 1
            while k < MAX_CLASS and _decode_bit(data, st, probs, base + _UNARY + k) == 1:
                k += 1
            a = 1
            if k >= 2:
                a = (a << 1) | _decode_bit(data, st, probs, base + _MANT + k)
                for _b in range(k - 3, -1, -1):
                    a = (a << 1) | _decode_direct(data, st)
            values[c, w] = -a if neg else a
            if kinds[c] >= 0:
                _after(w, a, sc)
    return values, st[3]


def _groups(group, W: int) -> tuple[np.ndarray, int]:
    if group is None:
        return np.zeros(W, dtype=np.int64), 1
    g = np.ascontiguousarray(group, dtype=np.int64)
    if g.shape != (W,) or (W and g.min() < 0):
        raise UsageError("group must be (W,) non-negative integers")
    return g, int(g.max()) + 1 if W else 1


def _kinds(kinds, C: int) -> np.ndarray:
    if kinds is None:
        return np.full(C, -1, dtype=np.int64)
    k = np.ascontiguousarray(kinds, dtype=np.int64)
    if k.shape != (C,) or (C and (k.min() < -1 or k.max() >= MAX_KINDS)):
        raise UsageError(f"kinds must be ({C},) integers in -1..{MAX_KINDS - 1}")
    return k


def encode_integers(
    values: np.ndarray, group: np.ndarray | None = None, kinds: np.ndarray | None = None
) -> bytes:
    """Range-code a (C, W) array of integers channel by channel (see the module docstring);
    ``group`` (W,) gives each column a context group (e.g. its level in a coarse-to-fine order),
    so columns of different spread learn separate statistics. ``kinds`` (C,): -1 for a channel
    with its own contexts (the default for all), or a kind k >= 0: the channel then shares the
    contexts of kind k, chosen by its expected magnitude (see the module docstring).

    Raises:
        ValueError: a value's magnitude reaches 2^MAX_CLASS.
    """
    v = np.ascontiguousarray(values, dtype=np.int64)
    if v.ndim != 2:
        raise UsageError(f"values must be (channels, count); got shape {v.shape}")
    if v.size and np.abs(v).max() >= (1 << MAX_CLASS):
        raise UsageError(f"residual beyond 2^{MAX_CLASS}")
    g, n = _groups(group, v.shape[1])
    k = _kinds(kinds, v.shape[0])
    key = (v.shape, v.tobytes(), g.tobytes(), k.tobytes())
    with _LOCK:
        if key in _CODED:
            _CODED.move_to_end(key)
            return _CODED[key]
    data = bytes(_encode_kernel(v, g, n, _PRIOR, k))
    with _LOCK:
        _CODED[key] = data
        while len(_CODED) > _KEEP:
            _CODED.popitem(last=False)
    return data


def decode_integers(
    data: bytes,
    n_channels: int,
    count: int,
    group: np.ndarray | None = None,
    kinds: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """The (n_channels, count) int64 array :func:`encode_integers` coded into ``data`` (with the
    same ``group`` and ``kinds``), and the number of bytes the decoder read (more than
    ``len(data)``: the data was short)."""
    buf = np.frombuffer(bytes(data), dtype=np.uint8)
    g, n = _groups(group, int(count))
    k = _kinds(kinds, int(n_channels))
    values, used = _decode_kernel(buf, int(n_channels), int(count), g, n, _PRIOR, k)
    return values, int(used)


#: bit length of each magnitude below 2^12 (most residuals): a table read instead of a loop
#: whose trip count the processor cannot predict.
_BIT_LENGTH = np.array([int(a).bit_length() for a in range(1 << 12)], dtype=np.int64)


@numba.njit(cache=True, nogil=True, inline="always")
def _row_bits(row, counts, total):
    """``total`` plus the estimated bits of one channel ``row`` (W,) (``counts``: scratch)."""
    W = row.shape[0]
    counts[:] = 0
    for w in range(W):
        a = abs(row[w])
        if a < _BIT_LENGTH.shape[0]:
            k = _BIT_LENGTH[a]
        else:
            k = 0
            while a > 0:
                k += 1
                a >>= 1
        counts[k] += 1
        if k > 0:
            total += k  # sign and the k - 1 bits below the leading one
    for k in range(MAX_CLASS + 1):
        if counts[k] > 0:
            n = np.float64(counts[k])
            total -= n * np.log2(n / W)
    return total


@numba.njit(cache=True, nogil=True)
def _estimate_bits(values):
    counts = np.zeros(MAX_CLASS + 1, dtype=np.int64)
    total = 0.0
    for c in range(values.shape[0]):
        total = _row_bits(values[c], counts, total)
    return total


@numba.njit(cache=True, nogil=True)
def _estimate_bits_split(first, rest):
    counts = np.zeros(MAX_CLASS + 1, dtype=np.int64)
    total = _row_bits(first, counts, 0.0)
    for c in range(rest.shape[0]):
        total = _row_bits(rest[c], counts, total)
    return total


def estimate_size(values: np.ndarray) -> float:
    """Estimated bytes of :func:`encode_integers` of a (C, W) array: per channel, the empirical
    entropy of each integer's bit-length class plus its sign and lower bits (a static model of
    what the adaptive coder learns; within a few per cent of the real size on motion residuals).
    O(C W), several times faster than coding."""
    v = np.ascontiguousarray(values, dtype=np.int64)
    return float(_estimate_bits(v)) / 8.0


def estimate_split(first: np.ndarray, rest: np.ndarray) -> float:
    """:func:`estimate_size` of the (C, W) array whose first row is ``first`` (W,) and whose
    others are ``rest`` (C - 1, W), the same float, without building it: ``rest`` may be a view
    (e.g. the transpose of a (W, C - 1) array), read in place. Both int64."""
    return float(_estimate_bits_split(first, rest)) / 8.0
