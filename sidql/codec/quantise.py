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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
        raise ValueError(f"bits must be in 8..16; got {bits}")
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
