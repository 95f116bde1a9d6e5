"""16-bit quantisation of the chart's keyframe values, shared by the encoder and the decoder.

Channels (D = 2 M + 3 = 47 for M = 22 bones), in this order: ``theta[0..M)``, ``phi[0..M)``,
``root[0..3)`` (root position, CMU axes [m]). Codes are unsigned 16-bit for the pose:

The pose has ``b`` bits per channel (``bits``, 8..16; 16 by default), ``Q = 2^b``:

* ``theta`` in [0, pi]: ``code = round(theta / theta_step)``, ``theta_step = pi / (Q - 1)``;
* ``phi`` (any branch): ``code = round(phi / phi_step) mod Q``, ``phi_step = 2 pi / Q``;
  the decoder picks, keyframe by keyframe, the branch ``code * phi_step + 2 pi k`` nearest the
  previous keyframe's value (the first keyframe: k = 0), so the decoded azimuth follows the
  motion as long as it turns less than pi between keyframes;
* root axis ``a``: ``code = clip(round((x - origin[a]) / step[a]), 0, Q - 1)`` with ``origin``,
  ``step`` float32 numbers in the stream header (the trial's range over about Q - 2 steps).

Rates (Hermite only) are signed 16-bit: ``code = clip(round(rate / rate_step[d]), -32767, 32767)``
with ``rate_step[d]`` (float32, per channel, in the header) the 99.9th percentile of ``|rate|``
over the trial divided by 32767 (rates beyond it, e.g. ``phi`` rates at the chart's poles, are
clipped; the clipping is part of the measured error).

Every dequantised value is computed in float64 from the stored float32 parameters, by the same
function on both sides, so the encoder knows exactly what the decoder will see.

:class:`PositionQuantiser` is the position coding's (coding 2): a step per channel from its effect
on point positions, values predicted along the keyframes in closed loop (:mod:`sidql.codec.dpcm`,
one compiled function for both directions), integer residuals of any size.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from sidql.codec.cones import cone_array
from sidql.codec.dpcm import PARTNER_RATE, PARTNER_WEIGHTS, dpcm, steps
from sidql.codec.plan import subtree_sizes
from sim.errors import UsageError

THETA_STEP = np.pi / 65535.0  # at 16 bits
PHI_STEP = 2.0 * np.pi / 65536.0  # at 16 bits
RATE_PERCENTILE = 99.9
BITS = tuple(range(8, 17))


@dataclass(frozen=True)
class Quantiser:
    """Parameters of one stream's quantisation (see the module docstring).

    Attributes:
        n_bones: M.
        root_origin, root_step: (3,) float32 root offset [m] and step [m] per axis.
        rate_step: (2 M + 3,) float32 rate step per channel [unit/s], or None (no rates sent).
        bits: bits per pose channel (8..16).
    """

    n_bones: int
    root_origin: np.ndarray
    root_step: np.ndarray
    rate_step: np.ndarray | None = None
    bits: int = 16

    @property
    def levels(self) -> int:
        return 1 << self.bits

    @property
    def theta_step(self) -> float:
        return np.pi / (self.levels - 1)

    @property
    def phi_step(self) -> float:
        return 2.0 * np.pi / self.levels

    @property
    def n_channels(self) -> int:
        return 2 * self.n_bones + 3

    def encode_pose(self, values: np.ndarray) -> np.ndarray:
        """(W, D) float pose [theta | phi | root] -> (W, D) uint16 codes."""
        M = self.n_bones
        v = np.asarray(values, dtype=np.float64)
        out = np.empty(v.shape, dtype=np.uint16)
        top = self.levels - 1
        out[:, :M] = np.clip(np.rint(v[:, :M] / self.theta_step), 0, top)
        phi = np.rint(v[:, M : 2 * M] / self.phi_step)
        out[:, M : 2 * M] = np.mod(phi, self.levels).astype(np.int64)
        o = self.root_origin.astype(np.float64)
        s = self.root_step.astype(np.float64)
        out[:, 2 * M :] = np.clip(np.rint((v[:, 2 * M :] - o) / s), 0, top)
        return out

    def decode_pose(self, codes: np.ndarray) -> np.ndarray:
        """(W, D) uint16 codes -> (W, D) float64 pose; ``phi`` unwrapped along the keyframes."""
        M = self.n_bones
        c = np.asarray(codes).astype(np.float64)
        out = np.empty(c.shape)
        out[:, :M] = c[:, :M] * self.theta_step
        out[:, M : 2 * M] = np.unwrap(c[:, M : 2 * M] * self.phi_step, axis=0)
        o = self.root_origin.astype(np.float64)
        s = self.root_step.astype(np.float64)
        out[:, 2 * M :] = o + c[:, 2 * M :] * s
        return out

    def grid_pose(self, values: np.ndarray) -> np.ndarray:
        """(N, D) pose rounded to the grid, ``phi`` kept on the input's branch: what the decoder
        rebuilds at a keyframe, up to a multiple of 2 pi per bone in ``phi``."""
        M = self.n_bones
        v = np.asarray(values, dtype=np.float64)
        out = v.copy()
        top = self.levels - 1
        ts, ps = self.theta_step, self.phi_step
        out[:, :M] = np.clip(np.rint(v[:, :M] / ts), 0, top) * ts
        out[:, M : 2 * M] = np.rint(v[:, M : 2 * M] / ps) * ps
        o = self.root_origin.astype(np.float64)
        s = self.root_step.astype(np.float64)
        out[:, 2 * M :] = o + np.clip(np.rint((v[:, 2 * M :] - o) / s), 0, top) * s
        return out

    def encode_rates(self, rates: np.ndarray) -> np.ndarray:
        """(W, D) rates [unit/s] -> (W, D) int16 codes."""
        s = self.rate_step.astype(np.float64)
        return np.clip(np.rint(np.asarray(rates, np.float64) / s), -32767, 32767).astype(np.int16)

    def decode_rates(self, codes: np.ndarray) -> np.ndarray:
        """(W, D) int16 codes -> (W, D) float64 rates [unit/s]."""
        return np.asarray(codes).astype(np.float64) * self.rate_step.astype(np.float64)

    def grid_rates(self, rates: np.ndarray) -> np.ndarray:
        """(N, D) rates clipped and rounded to the grid (what the decoder rebuilds)."""
        return self.decode_rates(self.encode_rates(rates))


def fit_quantiser(
    values: np.ndarray, rates: np.ndarray | None, n_bones: int, bits: int = 16
) -> Quantiser:
    """The quantiser of one trial.

    Args:
        values: (N, 2 M + 3) pose [theta | phi | root] of every frame.
        rates: (N, 2 M + 3) their rates [unit/s], or None when the stream carries no rates.
        n_bones: M; bits: bits per pose channel (8..16).
    """
    if bits not in BITS:
        raise UsageError(f"bits must be in 8..16; got {bits}")
    root = np.asarray(values, dtype=np.float64)[:, 2 * n_bones :]
    lo = root.min(axis=0).astype(np.float32)
    span = root.max(axis=0) - lo.astype(np.float64)
    # a step a little above span / (Q - 1) so float32 rounding never pushes the top past Q - 1
    step = np.maximum(span / ((1 << bits) - 2.0), 1e-7).astype(np.float32)
    rate_step = None
    if rates is not None:
        top = np.percentile(np.abs(np.asarray(rates, np.float64)), RATE_PERCENTILE, axis=0)
        rate_step = np.maximum(top / 32767.0, 1e-9).astype(np.float32)
    return Quantiser(n_bones, lo, step, rate_step, bits)


#: exponent of the subtree size n_b in a channel's lever (see :class:`PositionQuantiser`) when
#: the stream does not say (version 2 streams): with each value quantised on its own, the errors
#: of the bones above a point add like independent noise, so a point's error grows with the
#: square root of their number. Version 3 streams carry their exponent.
SUBTREE_EXPONENT = 0.5


def keyframe_steps(keys: np.ndarray, gap_exponent: float) -> np.ndarray:
    """(W,) each keyframe's step factor ``(mean_w / w_w)^g``, ``w_w = (gap before + gap after) / 2``
    (1 beyond either end) the frames its value moves, ``mean_w = N / W``; g = k / 4, k in 0..4.
    From integers by a division and square roots (correctly rounded): every machine agrees."""
    return steps(np.ascontiguousarray(keys, dtype=np.int64), int(round(4 * gap_exponent)))


def aim_basis(values: np.ndarray, n_bones: int) -> np.ndarray:
    """(W, M, 5) per bone the unit vectors (CMU axes) a point moves along when the bone's theta
    and phi grow: ``(cos t cos p, cos t sin p, -sin t)`` and ``(-sin p, cos p)`` (its z is 0), of
    the (W, 2 M + 3) values [theta | phi | root]."""
    M = n_bones
    v = np.asarray(values, dtype=np.float64)
    st, ct = np.sin(v[:, :M]), np.cos(v[:, :M])
    sp, cp = np.sin(v[:, M : 2 * M]), np.cos(v[:, M : 2 * M])
    return np.ascontiguousarray(np.stack([ct * cp, ct * sp, -st, -sp, cp], axis=-1))


@functools.lru_cache(maxsize=64)
def _parent_channels(parents: tuple) -> np.ndarray:
    """(2 M + 3,) per channel the parent bone's same angle (-1: none); read-only, shared."""
    p = np.asarray(parents, dtype=np.int64)[1:] - 1  # parent bone of each bone
    M = len(p)
    out = np.r_[np.where(p >= 0, p, -1), np.where(p >= 0, M + p, -1), -np.ones(3, np.int64)]
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class PositionQuantiser:
    """Keyframe values quantised by their effect on point positions (coding 2).

    A bone's direction error moves the bone's own point and every point below it, by its length
    times the angle (phi: times sin theta), so each channel's step is ``step`` [m] divided by that
    lever: theta of bone b ``step / (L_b n_b^e)``, phi ``step / (L_b n_b^e sin theta)``, root
    ``step / J^e`` (all J points move with the root), n_b the points at or below b and e =
    ``exponent`` (1/2 for errors that add along the chain like independent noise; the encoder
    aims each bone from its decoded parent point, which cancels most of that, and uses less).
    Values are predicted along the keyframes (:mod:`sidql.codec.dpcm`) and the integer residuals
    range-coded (:mod:`sidql.codec.entropy`).

    Attributes:
        n_bones: M; lengths: (M,) bone lengths [m] as stored; parents: (M + 1,) parent indices.
        step: the position step [m] (float32 in the stream); rho: the predictor's slope weight.
        exponent: e, the subtree size's exponent in the levers (k / 16 for k in 0..16).
        root_rho: the root channels' slope weight (None: ``rho``).
        gap_exponent: g, each keyframe's step times :func:`keyframe_steps` (k / 4 for k in 0..4).
        partner: True (versions 2 to 4): each prediction adds the parent bone's innovation;
            False (versions 5 and 6): it does not (with aiming that cost bytes), and the first
            keyframe of a bone is predicted from its parent's (:meth:`firsts`).
        cones: (version 6) per bone its cone (alpha, r, beta) or None, or None for no bone
            (:mod:`sidql.codec.cones`): such a bone is predicted on its cones.
    """

    n_bones: int
    lengths: np.ndarray
    parents: np.ndarray
    step: float
    rho: float = 0.5
    bits: int = 0  # no fixed bit depth: codes are residuals of any size
    exponent: float = SUBTREE_EXPONENT
    root_rho: float | None = None
    gap_exponent: float = 0.0
    partner: bool = True
    cones: tuple | None = None

    def cone_array(self) -> np.ndarray:
        """(M, 3) per bone its cone (alpha, r, beta), all -1 for none (:mod:`sidql.codec.cones`)."""
        return cone_array(self.cones, self.n_bones)

    @property
    def root_slope(self) -> float:
        """The root channels' slope weight (``rho`` unless ``root_rho`` says otherwise)."""
        return self.rho if self.root_rho is None else self.root_rho

    @property
    def n_channels(self) -> int:
        return 2 * self.n_bones + 3

    def scales(self) -> np.ndarray:
        """(2 M + 3,) per-channel steps before phi's sin theta division [rad, rad, m]."""

        n = subtree_sizes(self.parents).astype(np.float64) ** self.exponent
        lever = np.maximum(np.asarray(self.lengths, dtype=np.float64) * n[1:], 1e-6)
        s = np.float64(np.float32(self.step))
        return np.concatenate([s / lever, s / lever, np.full(3, s / n[0])])

    def _parent_channels(self) -> np.ndarray:
        """(2 M + 3,) per channel the parent bone's same angle (-1: none; the root's children
        and the root)."""
        return _parent_channels(tuple(np.asarray(self.parents, dtype=np.int64).tolist())).copy()

    def partners(self) -> np.ndarray:
        """(2 M + 3, 1) per channel, the channel decoded before it whose innovation predicts
        its own (with ``partner``): the parent bone's same angle (-1: none)."""
        out = self._parent_channels()[:, None]
        return out if self.partner else np.full_like(out, -1)

    def firsts(self) -> np.ndarray:
        """(2 M + 3,) per channel, the channel whose decoded first keyframe predicts its own
        (without ``partner``, version 5): the parent bone's same angle (-1: none, predicted 0)."""
        out = self._parent_channels()
        return np.full_like(out, -1) if self.partner else out

    def _tree(self):
        return (
            np.ascontiguousarray(self.lengths, dtype=np.float64),
            np.ascontiguousarray(self.parents, dtype=np.int64),
        )

    def encode_keyframes(
        self, values: np.ndarray, keys: np.ndarray, aim: bool = False, basis=None, rows=None
    ):
        """(W, D) keyframe values -> ((W, D) int64 residual codes, (W, D) decoded values).

        ``aim``: each bone aims from its decoded parent point at its true point (see
        :mod:`sidql.codec.dpcm`) instead of quantising its own angles; ``basis``:
        ``aim_basis(values)`` if the caller has it. ``rows``: (W,) the keyframes' rows of
        ``values`` and ``basis`` when they are a whole chart's (N, D), (N, M, 5) (no copies)."""
        v = np.ascontiguousarray(values, dtype=np.float64)
        k = np.ascontiguousarray(keys, dtype=np.int64)
        r = np.arange(len(k)) if rows is None else np.ascontiguousarray(rows, dtype=np.int64)
        codes = np.zeros((len(k), v.shape[1]), dtype=np.int64)
        M = self.n_bones
        if not aim:
            basis = np.zeros((0, M, 5))
        elif basis is None:
            basis = aim_basis(v, M)
        out = dpcm(
            v,
            codes,
            k,
            self.scales(),
            self.n_bones,
            float(self.rho),
            True,
            self.partners(),
            PARTNER_RATE,
            *PARTNER_WEIGHTS,
            np.ascontiguousarray(basis, dtype=np.float64),
            *self._tree(),
            float(self.root_slope),
            int(round(4 * self.gap_exponent)),
            self.firsts(),
            r,
            self.cone_array(),
        )
        return codes, out

    def decode_keyframes(self, codes: np.ndarray, keys: np.ndarray) -> np.ndarray:
        """(W, D) residual codes -> (W, D) decoded keyframe values [rad, rad, m]."""
        c = np.ascontiguousarray(codes, dtype=np.int64)
        k = np.ascontiguousarray(keys, dtype=np.int64)
        return dpcm(
            np.zeros(c.shape),
            c,
            k,
            self.scales(),
            self.n_bones,
            float(self.rho),
            False,
            self.partners(),
            PARTNER_RATE,
            *PARTNER_WEIGHTS,
            np.zeros((0, self.n_bones, 5)),
            *self._tree(),
            float(self.root_slope),
            int(round(4 * self.gap_exponent)),
            self.firsts(),
            np.arange(len(k)),
            self.cone_array(),
        )
