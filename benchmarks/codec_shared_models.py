"""Models shared across channels for the position coding's residuals: offline estimates.

    python benchmarks/codec_shared_models.py [--data ../shared/cmu] [--errors 1 3 10]

Each trial of ``--data`` (at least 60 frames) is encoded with ``--max-error E`` (coding 2); its
keyframes and residual codes are then coded again with one idea added, by the format's own range
coder (LZMA's binary coder, the same contexts; real bytes, not an entropy figure), and the bytes
compared over all trials. Nothing here is in the format. The ideas:

* **(a) fixed, leave one subject out**: each channel's residual code less the rounded linear
  prediction from every channel coded before it at the same keyframe (a lower-triangular matrix,
  i.e. a KLT as a sequence of predictions), the matrix fitted by ridge least squares on the trials
  of the *other* subjects (all error targets) and measured on this subject's: a basis the decoder
  would hold, never measured on what it was fitted on.
* **(a) ceilings**: the same matrix fitted on all the trials it is measured on, and the coding
  gain a Gaussian model of the codes promises from decorrelating them (bits a value).
* **(a) per stream**: the same with up to ``--partners`` partner channels per channel (coded before
  it, at the same keyframe or one either side), chosen greedily on the stream itself and sent:
  coefficients in 1/32 (8 bits), the partner (6 bits) and its keyframe shift (2 bits) counted.
* **(a) temporal, leave one subject out**: each channel's code predicted from every channel's last
  two decoded moves (each in its own steps), ridge fitted on the other subjects.
* **(b) joint coding of a bone's pair**: phi's contexts also split by its bone's theta residual
  class (0, 1, 2, more), and also phi's sign context by theta's sign (a vector quantiser of the
  pair could add at most the 2-D lattice's space-filling gain, 0.03 bits a value).
* **(c) slow channels at fewer keyframes**: the spine's channels (lowerback to head, 12 of 47)
  or only the neck and head (6) at every other keyframe of the encoder's plan, their values
  between from the stream's curve through those, every other bone aimed from the decoded
  (interpolated) spine; bytes by the size model (:func:`sidql.codec.entropy.estimate_size`) and
  the mean position error of every point and frame, both before and after.

Units: bytes; millimetres.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from results import load_trials  # noqa: E402

from sidql.codec import entropy as ent  # noqa: E402
from sidql.codec import format as sidq  # noqa: E402
from sidql.codec.dpcm import (  # noqa: E402
    MAX_PHI_STEP,
    SIN_FLOOR,
    _code,
    depth_order,
    same_branch,
    steps,
)
from sidql.codec.encode import encode_series  # noqa: E402
from sidql.codec.position_coding import AIM, _chart_arrays  # noqa: E402
from sidql.codec.position_format import channel_kinds, coded_rows  # noqa: E402
from sidql.codec.positions import position_errors  # noqa: E402
from sidql.keyframes.curves import interpolate  # noqa: E402
from sidql.keyframes.spherical import chart  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402

M, D = 22, 47
SPINE = (8, 9, 10, 11, 12, 13)  # lowerback .. head
NECK = (11, 12, 13)
_B = ent._PER_CHANNEL
_Z, _S, _U, _MT = ent._ZERO, ent._SIGN, ent._UNARY, ent._MANT


@numba.njit(cache=False)
def _coded_size(values, prior, kinds, ext, n_ext, sgn):
    """Bytes of the format's coder (:func:`sidql.codec.entropy.encode_integers` with ``kinds``)
    with each (kind, bucket) context set split in ``n_ext`` by ``ext`` (C, W), and the sign bit's
    context ``sgn`` (C, W) in 0..2 instead of the previous sign where ``sgn`` >= 0."""
    C, W = values.shape
    out = np.empty(64 + C * W * 8, dtype=np.uint8)
    low, rng, cache, csize, pos = np.int64(0), np.int64(ent._MASK32), np.int64(0), np.int64(1), 0
    probs = ent._initial_probs(C + (kinds.max() + 1) * ent.SCALE_BUCKETS * n_ext * 3, prior)
    sc = np.zeros(2 + W, dtype=np.int64)
    for c in range(C):
        prev_zero, prev_sign, sc[0], k_ = 0, 2, ent._SCALE_START, kinds[c]
        for w in range(W):
            base = c * _B
            if k_ >= 0:
                sub = (k_ * ent.SCALE_BUCKETS + ent._bucket(w, sc)) * n_ext + ext[c, w]
                base = (C + sub * 3 + max(sgn[c, w], 0)) * _B
                ent._after(w, abs(values[c, w]), sc)
            r = values[c, w]
            low, rng, cache, csize, pos = ent._bit(
                low, rng, cache, csize, pos, out, probs, base + _Z + prev_zero, int(r != 0)
            )
            prev_zero = int(r == 0)
            if r == 0:
                prev_sign = 2
                continue
            neg = int(r < 0)
            s_ctx = sgn[c, w] if sgn[c, w] >= 0 else prev_sign
            low, rng, cache, csize, pos = ent._bit(
                low, rng, cache, csize, pos, out, probs, base + _S + s_ctx, neg
            )
            prev_sign = neg
            a, k = abs(r), 0
            while a >> k:
                k += 1
            for u in range(1, k + (k < ent.MAX_CLASS)):
                low, rng, cache, csize, pos = ent._bit(
                    low, rng, cache, csize, pos, out, probs, base + _U + u, int(u < k)
                )
            if k >= 2:
                low, rng, cache, csize, pos = ent._bit(
                    low, rng, cache, csize, pos, out, probs, base + _MT + k, (a >> (k - 2)) & 1
                )
                for b in range(k - 3, -1, -1):
                    low, rng, cache, csize, pos = ent._direct(
                        low, rng, cache, csize, pos, out, (a >> b) & 1
                    )
        if k_ >= 0:
            sc[1] += 1
    for _ in range(5):
        low, cache, csize, pos = ent._shift_low(low, cache, csize, pos, out)
    return pos


def coded_bytes(keys, codes, ext=None, n_ext=1, sgn=None) -> int:
    """Bytes of the keyframe block (gap row and (W, D) ``codes``) by the format's coder, with
    optional extra contexts (see :func:`_coded_size`); rows as :func:`coded_rows`."""
    rows = coded_rows(keys, codes)
    ext = np.zeros(rows.shape, np.int64) if ext is None else ext
    sgn = np.full(rows.shape, -1, np.int64) if sgn is None else sgn
    return int(_coded_size(rows, ent._PRIOR, channel_kinds(M), ext, n_ext, sgn))


@numba.njit(cache=False)
def _forced_aimed(values, codes, keys, scale, rho, basis, lengths, parents, root_rho, kstep,
                  firsts, bones, forced, fmask):  # fmt: skip
    """:func:`sidql.codec.dpcm._aimed` (rows = keyframes) except that channels with ``fmask``
    decode to ``forced`` (W, D) (code 0, not sent) and the bones below aim from them."""
    W = codes.shape[0]
    out, err, pred = np.zeros((W, D)), np.zeros((M + 1, 3)), np.zeros(D)
    for w in range(W):
        v, ks = keys[w], kstep[w]
        for d in range(D):
            pred[d] = out[0, d] if w == 1 else 0.0
            if w >= 2:
                ratio = min((keys[w] - keys[w - 1]) / (keys[w - 1] - keys[w - 2]), 2.0)
                slope = root_rho if d >= 2 * M else rho
                pred[d] = out[w - 1, d] + slope * ratio * (out[w - 1, d] - out[w - 2, d])
        for c in range(3):
            d = 2 * M + c
            if w == 0:
                pred[d] = out[0, firsts[d]] if firsts[d] >= 0 else 0.0
            step = scale[d] * ks
            codes[w, d] = _code(values[v, d], pred[d], step)
            out[w, d] = pred[d] + codes[w, d] * step
            err[0, c] = out[w, d] - values[v, d]
        for b in bones:
            d, p, L = M + b, parents[b + 1], max(lengths[b], 1e-6)
            if w == 0:
                pred[b] = out[0, firsts[b]] if firsts[b] >= 0 else 0.0
                pred[d] = out[0, firsts[d]] if firsts[d] >= 0 else 0.0
            g = basis[v, b]
            dt = -(err[p, 0] * g[0] + err[p, 1] * g[1] + err[p, 2] * g[2]) / L
            dp = -(err[p, 0] * g[3] + err[p, 1] * g[4]) / (L * max(-g[2], SIN_FLOOR))
            step = scale[b] * ks
            codes[w, b] = _code(values[v, b] + min(max(dt, -0.5), 0.5), pred[b], step)
            out[w, b] = pred[b] + codes[w, b] * step
            if fmask[b]:
                out[w, b], codes[w, b] = forced[w, b], 0
            step = min(scale[d] * ks / max(np.sin(out[w, b]), SIN_FLOOR), MAX_PHI_STEP)
            codes[w, d] = _code(values[v, d] + min(max(dp, -0.5), 0.5), pred[d], step)
            out[w, d] = pred[d] + codes[w, d] * step
            if fmask[d]:
                out[w, d], codes[w, d] = forced[w, d], 0
            a = lengths[b] * (out[w, b] - values[v, b])
            f = -lengths[b] * g[2] * (out[w, d] - values[v, d])
            err[b + 1, 0] = err[p, 0] + a * g[0] + f * g[3]
            err[b + 1, 1] = err[p, 1] + a * g[1] + f * g[4]
            err[b + 1, 2] = err[p, 2] + a * g[2]
    return out


class Stream:
    """One trial encoded at one mean error target: its keyframes, codes and what re-coding
    needs."""

    def __init__(self, clip, series, e_mm: float):
        st = sidq.from_bytes(encode_series(series, max_error=e_mm).data)
        self.e, self.subject = e_mm, Path(clip.source).parent.name
        self.keys, self.q, self.recon = np.asarray(st.keyframes), st.quantiser, st.reconstruction
        self.values, self.truth, self.basis = _chart_arrays(series)
        self.lengths = np.ascontiguousarray(st.lengths, dtype=np.float64)
        self.parents = np.ascontiguousarray(st.parents, dtype=np.int64)
        self.codes, self.kv = self.encode(self.keys)
        assert np.array_equal(self.codes, np.asarray(st.pose_codes))
        self.bytes = coded_bytes(self.keys, self.codes)  # the format's coder, reproduced:
        assert self.bytes == len(
            ent.encode_integers(coded_rows(self.keys, self.codes), kinds=channel_kinds(M))
        )

    def encode(self, keys, forced=None, fmask=None):
        """(codes, decoded values) at ``keys``, optionally with forced channels."""
        if forced is None:
            return self.q.encode_keyframes(self.values, keys, AIM, self.basis, rows=keys)
        q, k = self.q, np.ascontiguousarray(keys, dtype=np.int64)
        codes = np.zeros((len(k), D), dtype=np.int64)
        kv = _forced_aimed(
            same_branch(self.values, q.firsts(), M, k), codes, k, q.scales(), float(q.rho),
            self.basis, self.lengths, self.parents, float(q.root_slope),
            steps(k, int(round(4 * q.gap_exponent))), q.firsts(), depth_order(self.parents, np.zeros(len(self.parents) - 1, bool))[0],
            forced, fmask,
        )  # fmt: skip
        return codes, kv

    def summed_error(self, kv) -> float:
        """Summed position error [mm] of every point and frame with decoded keyframe values kv."""
        E = position_errors(self.truth, self.keys, kv, self.recon, self.lengths, self.parents)
        return 1000.0 * float(E.sum())


def _lower_features(codes, c: int, shifts=(0,)) -> np.ndarray:
    """(W, c len(shifts)) the codes of channels 0..c-1 at keyframe w + s for s in ``shifts``."""
    cols = []
    for s in shifts:
        x = np.zeros((len(codes), c))
        if s >= 0:
            x[: len(codes) - s] = codes[s:, :c]
        else:
            x[-s:] = codes[:s, :c]
        cols.append(x)
    return np.hstack(cols)


def _triangular(train, ridge: float) -> list[np.ndarray]:
    """Per channel c >= 1 the ridge least-squares weights of channels 0..c-1's codes at the
    same keyframe predicting c's, over the streams ``train`` (first keyframes left out)."""
    A = []
    for c in range(1, D):
        X = np.vstack([_lower_features(s.codes, c)[1:] for s in train])
        y = np.concatenate([s.codes[1:, c] for s in train]).astype(float)
        A.append(np.linalg.solve(X.T @ X + ridge * np.eye(c), X.T @ y))
    return A


def fixed_triangular(streams, holdout: bool = True, ridge: float = 1.0) -> dict:
    """(a) fixed: {e: (bytes before, after)}, each subject's streams coded with the
    lower-triangular predictor fitted on the other subjects' streams (every target), or with
    ``holdout`` False on all streams (a ceiling no decoder could hold)."""
    out = {}
    every = None if holdout else _triangular(streams, ridge)
    for subject in sorted({s.subject for s in streams}):
        A = every or _triangular([s for s in streams if s.subject != subject], ridge)
        for s in streams:
            if s.subject == subject:
                new = s.codes.copy()
                for c in range(1, D):
                    p = np.round(_lower_features(s.codes, c) @ A[c - 1]).astype(np.int64)
                    new[1:, c] -= p[1:]
                b = out.setdefault(s.e, [0, 0])
                b[0], b[1] = b[0] + s.bytes, b[1] + coded_bytes(s.keys, new)
    return out


def gaussian_gain(streams) -> dict:
    """{e: bits per value} a Gaussian model of the codes promises from decorrelating the 47
    channels (the KLT's coding gain, covariance of all streams at e; first keyframes left out)."""
    out = {}
    for e in sorted({s.e for s in streams}):
        X = np.vstack([s.codes[1:] for s in streams if s.e == e]).astype(float)
        S = np.cov(X.T)
        out[e] = 0.5 * (np.sum(np.log2(np.diag(S))) - np.linalg.slogdet(S)[1] / np.log(2)) / D
    return out


def _greedy(codes, c: int, partners: int, shifts, param_bits: int):
    """(residuals of channel c, partners chosen) by greedy choice of up to ``partners`` (channel,
    shift) of those coded before c, each kept only where it saves more than its bits."""
    y = codes[1:, c]
    X = _lower_features(codes, c, shifts)[1:].astype(float)
    chosen, best, cur = [], 8 * ent.estimate_size(y[None]), y
    for _ in range(partners):
        trial = None
        for j in range(X.shape[1]):
            if j in chosen:
                continue
            Xj = X[:, chosen + [j]]
            a = np.clip(np.round(32 * np.linalg.lstsq(Xj, y, rcond=None)[0]), -128, 127) / 32
            r = y - np.round(Xj @ a).astype(np.int64)
            bits = 8 * ent.estimate_size(r[None]) + param_bits * (len(chosen) + 1)
            if bits < best and (trial is None or bits < trial[0]):
                trial = (bits, j, r)
        if trial is None:
            break
        best, j, cur = trial
        chosen.append(j)
    return cur, len(chosen)


def per_stream(streams, partners: int, shifts=(-1, 0, 1)) -> dict:
    """(a) per stream: {e: (bytes before, after with the partners' parameters)}."""
    param_bits = 8 + 6 + (2 if len(shifts) > 1 else 0)
    out = {}
    for s in streams:
        new, n = s.codes.copy(), 0
        for c in range(1, D):
            new[1:, c], k = _greedy(s.codes, c, partners, shifts, param_bits)
            n += k
        b = out.setdefault(s.e, [0, 0])
        b[0] += s.bytes
        b[1] += coded_bytes(s.keys, new) + (n * param_bits + D + 7) // 8
    return out


def _moves(s: Stream) -> np.ndarray:
    """(W, 2 D + 1) each channel's last two decoded moves in its own steps, and 1."""
    kv = s.kv
    stp = np.outer(steps(s.keys, int(round(4 * s.q.gap_exponent))), s.q.scales())
    phi = stp[:, M : 2 * M] / np.maximum(np.sin(kv[:, :M]), SIN_FLOOR)
    stp[:, M : 2 * M] = np.minimum(phi, MAX_PHI_STEP)
    mv = np.zeros(kv.shape)
    mv[1:] = np.diff(kv, axis=0) / stp[1:]
    X = np.zeros((len(kv), 2 * D + 1))
    X[3:, :D], X[3:, D : 2 * D], X[:, -1] = mv[2:-1], mv[1:-2], 1.0
    return np.clip(X, -50.0, 50.0)


def temporal_loso(streams, ridge: float = 10.0) -> dict:
    """(a) temporal: {e: (bytes before, after)} with the predictor of every channel's code from
    every channel's last two moves, fitted on the other subjects."""
    feats = {id(s): _moves(s) for s in streams}
    out = {}
    for subject in sorted({s.subject for s in streams}):
        train = [s for s in streams if s.subject != subject]
        X = np.vstack([feats[id(s)][3:] for s in train])
        Y = np.vstack([s.codes[3:] for s in train]).astype(float)
        A = np.linalg.solve(X.T @ X + ridge * np.eye(X.shape[1]), X.T @ Y)
        for s in streams:
            if s.subject == subject:
                p = np.round(feats[id(s)] @ A).astype(np.int64)
                p[:3] = 0
                b = out.setdefault(s.e, [0, 0])
                b[0], b[1] = b[0] + s.bytes, b[1] + coded_bytes(s.keys, s.codes - p)
    return out


def pair_contexts(streams) -> dict:
    """(b): {e: (bytes before, with phi's contexts split by theta's class, and also its sign
    context by theta's sign)}."""
    out = {}
    for s in streams:
        rows = coded_rows(s.keys, s.codes)
        theta = rows[1 : 1 + M]
        ext = np.zeros(rows.shape, np.int64)
        ext[1 + M : 1 + 2 * M] = np.minimum(np.abs(theta), 3)  # 0, 1, 2, more (|r| >= 3)
        sgn = np.full(rows.shape, -1, np.int64)
        sgn[1 + M : 1 + 2 * M] = np.sign(theta) + 1
        b = out.setdefault(s.e, [0, 0, 0])
        b[0] += s.bytes
        b[1] += coded_bytes(s.keys, s.codes, ext, 4)
        b[2] += coded_bytes(s.keys, s.codes, ext, 4, sgn)
    return out


def fewer_keyframes(s: Stream, bones) -> tuple[float, float, float, float, int]:
    """(c) for one stream: estimated bytes before and after coding ``bones``' theta and phi at
    every other keyframe (and the last), the rest aimed from them; the summed point error [mm]
    before and after; the number of errors summed (points times frames)."""
    ch = np.r_[bones, np.asarray(bones) + M]
    rest = np.setdiff1d(np.arange(D), ch)
    half = s.keys[::2] if (len(s.keys) - 1) % 2 == 0 else np.r_[s.keys[::2], s.keys[-1]]
    hcodes, hkv = s.encode(half)
    curve = "linear" if s.recon == "linear" else "catmull_rom"
    tmp = np.zeros((len(s.values), len(ch)))
    tmp[half] = hkv[:, ch]
    between, _ = interpolate(tmp, None, half, 1.0, curve)
    forced = np.zeros((len(s.keys), D))
    forced[:, ch] = between[s.keys]
    fmask = np.zeros(D, dtype=np.bool_)
    fmask[ch] = True
    codes, kv = s.encode(s.keys, forced, fmask)
    before = ent.estimate_size(s.codes.T)
    after = ent.estimate_size(codes[:, rest].T) + ent.estimate_size(hcodes[:, ch].T)
    return (
        before,
        after,
        s.summed_error(s.kv),
        s.summed_error(kv),
        s.truth.shape[0] * s.truth.shape[1],
    )


def _report(title: str, sums: dict, labels=("after",)) -> None:
    for e, b in sorted(sums.items()):
        parts = ", ".join(
            f"{lab} {x} ({x / b[0] - 1:+.1%})" for lab, x in zip(labels, b[1:], strict=True)
        )
        print(f"{title}, {e:g} mm: before {b[0]} B, {parts}", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--errors", type=float, nargs="+", default=[1.0, 3.0, 10.0])
    ap.add_argument("--partners", type=int, default=4)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    clips, _ = load_trials(args.data or default_data_dir() / "cmu")
    streams = []
    for clip in clips:
        series = chart(clip)
        streams += [Stream(clip, series, e) for e in args.errors]
    print(f"{len(clips)} trials, {len({s.subject for s in streams})} subjects", flush=True)
    for e, g in gaussian_gain(streams).items():
        b = sum(s.bytes for s in streams if s.e == e)
        n = sum(s.codes[1:].size for s in streams if s.e == e)
        print(f"(a) Gaussian KLT gain, {e:g} mm: {g:.3f} bits a value of {8 * b / n:.2f}")
    _report("(a) fixed lower-triangular, leave one subject out", fixed_triangular(streams))
    _report("(a) fixed lower-triangular, fitted on all (ceiling)", fixed_triangular(streams, False))
    _report("(a) temporal, leave one subject out", temporal_loso(streams))
    _report(f"(a) per stream, up to {args.partners} partners", per_stream(streams, args.partners))
    _report("(b) phi contexts by theta", pair_contexts(streams), ("class", "class and sign"))
    for name, bones in (("spine", SPINE), ("neck and head", NECK)):
        for e in args.errors:
            r = np.array([fewer_keyframes(s, bones) for s in streams if s.e == e]).sum(axis=0)
            n = r[4]
            print(f"(c) {name} at every other keyframe, {e:g} mm: estimated bytes "
                  f"{r[1] / r[0] - 1:+.1%}, mean error {r[2] / n:.3f} -> {r[3] / n:.3f} mm "
                  f"({r[3] / r[2] - 1:+.1%})", flush=True)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
