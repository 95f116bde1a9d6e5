"""Bones on cones (sidql.codec.cones, .sidq version 6): found in a chart whose bones are tied
together as the CMU skeletons' are, predicted on them by the kernel as an oracle built from
rotations predicts them, decoded bit for bit, cheaper than their own past, and the cone section
written, read and refused."""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import replace

import numpy as np
import pytest
from keyframe_synth import smooth_clip
from test_codec_dpcm import _run, oracle

from sidql.codec import format as sidq
from sidql.codec.cones import CONE_UNIT, cone_array, cone_bytes, read_cones, rigid_cones
from sidql.codec.decode import decoded_chart
from sidql.codec.dpcm import dpcm, followers
from sidql.codec.encode import encode_series
from sidql.codec.quantise import PositionQuantiser, aim_basis
from sidql.keyframes.spherical import SphericalSeries, chart
from sim.errors import MotionDataError

# bone indices (point - 1) of the protocol skeleton
LHIP, RHIP, THORAX, LCLAV, LRADIUS, LWRIST, RCLAV, RRADIUS, RWRIST = (
    0,
    4,
    10,
    14,
    16,
    17,
    18,
    20,
    21,
)


def _frame(u):
    """(N, 3, 3) rows u, e1, e2: an orthonormal frame per row of the unit vectors u (N, 3)."""
    helper = np.where(np.abs(u[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return np.stack([u, e1, np.cross(u, e1)], axis=1)


def _on_cone(u, angle, psi):
    """(N, 3) directions at ``angle`` from u (N, 3), azimuth psi (N,) about it."""
    f = _frame(u)
    ring = np.cos(psi)[:, None] * f[:, 1] + np.sin(psi)[:, None] * f[:, 2]
    return math.cos(angle) * u + math.sin(angle) * ring


def coned_series(seed: int = 5, N: int = 120):
    """A smooth chart whose wrists lie along their forearms, whose left clavicle keeps 1.2 rad to
    the thorax, whose right clavicle is fixed to the thorax and the left clavicle, and whose
    right hip joint keeps 1.3 rad to the left one (the CMU skeletons' ties). Returns the series
    and the expected cones."""
    s = chart(smooth_clip(N=N, fps=30.0, seed=seed))
    M = s.n_bones
    th, ph = s.theta.copy(), s.phi.copy()
    u = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1)
    t = np.arange(N) / 30.0
    u[:, LWRIST], u[:, RWRIST] = u[:, LRADIUS], u[:, RRADIUS]
    u[:, LCLAV] = _on_cone(u[:, THORAX], 1.2, 0.8 * np.sin(1.3 * t))
    f = np.stack([u[:, THORAX], u[:, LCLAV] - np.cos(1.2) * u[:, THORAX]], axis=1)
    f[:, 1] /= np.linalg.norm(f[:, 1], axis=1, keepdims=True)
    k = np.array([0.3, -0.5, 0.6])
    k /= np.linalg.norm(k)  # fixed in the frame (thorax, its normal towards lclavicle, third)
    u[:, RCLAV] = k[0] * f[:, 0] + k[1] * f[:, 1] + k[2] * np.cross(f[:, 0], f[:, 1])
    u[:, RHIP] = _on_cone(u[:, LHIP], 1.3, 0.5 + 0.4 * np.cos(0.9 * t))
    theta = np.arccos(np.clip(u[..., 2], -1, 1))
    phi = np.unwrap(np.arctan2(u[..., 1], u[..., 0]), axis=0)
    series = SphericalSeries(theta=theta, phi=phi, dtheta=np.zeros_like(theta),
                             dphi=np.zeros_like(phi), root_pos=s.root_pos,
                             root_vel=np.zeros_like(s.root_pos), lengths=s.lengths,
                             parents=s.parents, dt=s.dt)  # fmt: skip
    beta = math.acos(k[0] * math.cos(1.2) + k[1] * math.sin(1.2))  # rclavicle to lclavicle
    expected = {LWRIST: (0.0, -1, None), RWRIST: (0.0, -1, None), LCLAV: (1.2, -1, None),
                RCLAV: (math.acos(k[0]), LCLAV, beta), RHIP: (None, LHIP, 1.3)}  # fmt: skip
    assert M == 22
    return series, expected


def test_the_cones_of_a_tied_skeleton_are_found_on_their_grid():
    series, expected = coned_series()
    values, _ = series.channels()
    cones = rigid_cones(values, series.n_bones, series.parents)
    found = {b: c for b, c in enumerate(cones) if c is not None}
    assert sorted(found) == sorted(expected)
    for b, (alpha, r, beta) in expected.items():
        a, rr, bb = found[b]
        assert rr == r
        if alpha is None:
            assert a == -1.0
        else:
            assert abs(a - alpha) <= CONE_UNIT / 2 + 1e-9 and round(a / CONE_UNIT) * CONE_UNIT == a
        if beta is not None:
            assert abs(bb - beta) <= CONE_UNIT / 2 + 1e-9
    # an untied chart has none
    plain = chart(smooth_clip(N=120, fps=30.0, seed=5))
    assert rigid_cones(plain.channels()[0], plain.n_bones, plain.parents) is None


def _quantiser(series, cones, step=0.004):
    return PositionQuantiser(series.n_bones, series.lengths, series.parents, step, 0.5,
                             exponent=0.125, root_rho=1.0, gap_exponent=0.25, partner=False,
                             cones=cones)  # fmt: skip


@pytest.mark.parametrize("aim", [True, False])
def test_the_kernel_predicts_on_cones_as_rotations_do(aim):
    series, _ = coned_series(seed=7)
    values, _ = series.channels()
    q = _quantiser(series, rigid_cones(values, series.n_bones, series.parents))
    keys = np.arange(0, len(values), 3)
    codes, out = _run(dpcm, values[keys], keys, q, True, aim=aim)
    ref_codes, ref_out = _run(oracle, values[keys], keys, q, True, aim=aim)
    # the oracle's rotations round differently in the last bits: the same codes, values to 1e-9
    assert np.array_equal(codes, ref_codes)
    assert np.allclose(out, ref_out, rtol=0, atol=1e-9)
    decoded = q.decode_keyframes(codes, keys)
    assert np.array_equal(decoded, out)  # the decoder rebuilds the encoder's values, bit for bit


def test_bones_on_cones_cost_less_than_their_own_past_predicts():
    series, expected = coned_series()
    values, _ = series.channels()
    cones = rigid_cones(values, series.n_bones, series.parents)
    keys = np.arange(0, len(values), 2)
    basis = aim_basis(values, series.n_bones)
    M = series.n_bones
    tied = sorted(expected)
    cols = tied + [M + b for b in tied]
    size = {}
    for name, c in (("cones", cones), ("plain", None)):
        codes, kv = _quantiser(series, c).encode_keyframes(values, keys, True, basis, rows=keys)
        size[name] = np.abs(codes[1:, cols]).mean()
        assert np.abs(kv - values[keys])[:, 2 * M :].max() < 0.004  # the root: within a step
    assert size["cones"] < 0.5 * size["plain"]
    # a wrist along its forearm is left at its prediction (nothing sent: the forearm aims at the
    # wrist point), so it decodes to the forearm's direction
    wrists = [LWRIST, RWRIST, M + LWRIST, M + RWRIST]
    codes, kv = _quantiser(series, cones).encode_keyframes(values, keys, True, basis, rows=keys)
    assert not codes[:, wrists].any()
    assert np.array_equal(kv[:, [LWRIST, M + LWRIST]], kv[:, [LRADIUS, M + LRADIUS]])


def test_followers_are_the_bones_along_their_parent_and_reach_to_their_far_end():
    series, _ = coned_series(N=60)
    values, _ = series.channels()
    cones = cone_array(rigid_cones(values, series.n_bones, series.parents), series.n_bones)
    lengths = np.asarray(series.lengths, dtype=np.float64)
    silent, reach = followers(cones, np.asarray(series.parents, dtype=np.int64), lengths)
    assert np.flatnonzero(silent).tolist() == [LWRIST, RWRIST]
    far = lengths.copy()
    far[[LRADIUS, RRADIUS]] += lengths[[LWRIST, RWRIST]]
    assert np.array_equal(reach, far)


def test_a_coned_stream_round_trips_and_older_versions_cannot_carry_it():
    series, _ = coned_series()
    enc = encode_series(series, max_error=3.0)
    s = sidq.from_bytes(enc.data, "c.sidq")
    assert enc.data[4] == 6 and s.quantiser.cones == enc.stream.quantiser.cones
    assert sum(c is not None for c in s.quantiser.cones) == 5
    assert sidq.to_bytes(s) == enc.data
    assert np.array_equal(decoded_chart(s)["values"], decoded_chart(enc.stream)["values"])
    assert abs(enc.mean_error_mm - 3.0) < 0.5
    with pytest.raises(Exception, match="cannot carry"):
        sidq.to_bytes(s, position_version=5)
    # the same codes without the cones are other values
    bare = replace(s, quantiser=replace(s.quantiser, cones=None))
    assert not np.array_equal(decoded_chart(bare)["values"], decoded_chart(s)["values"])


def _section(entries):
    out = bytes([len(entries)])
    for b, r, a, beta in entries:
        out += struct.pack("<BBH", b, r, a) + (struct.pack("<H", beta) if r != 255 else b"")
    return out


def _reader(data: bytes):
    pos = [0]

    def take(n, what):
        if pos[0] + n > len(data):
            raise MotionDataError("t", None, f"truncated stream: {what} missing")
        pos[0] += n
        return data[pos[0] - n : pos[0]]

    return take


def test_the_cone_section_round_trips():
    series, _ = coned_series()
    values, _ = series.channels()
    cones = rigid_cones(values, series.n_bones, series.parents)
    data = cone_bytes(cones)
    assert len(data) == 1 + 4 + 4 + 4 + 6 + 6  # K, two wrists, lclavicle, rclavicle, rhipjoint
    assert read_cones(_reader(data), "t", series.n_bones, series.parents) == cones
    assert cone_bytes(None) == b"\x00"
    assert read_cones(_reader(b"\x00"), "t", series.n_bones, series.parents) is None


@pytest.mark.parametrize(
    "entries",
    [
        [(17, 255, 0, 0), (14, 255, 100, 0)],  # bones out of order
        [(0, 255, 100, 0)],  # alpha for a child of the root (no parent bone)
        [(17, 255, 65535, 0)],  # neither alpha nor a second bone
        [(18, 8, 100, 100)],  # a second bone of another depth (lowerback)
        [(18, 18, 100, 100)],  # itself
        [(14, 18, 100, 100), (18, 14, 100, 100)],  # a second bone that is deferred itself
        [(18, 14, 100, 65535)],  # beta off the grid
        [(30, 255, 0, 0)],  # no such bone
    ],
)
def test_a_bad_cone_section_is_one_line(entries):
    series, _ = coned_series(N=60)
    with pytest.raises(MotionDataError, match=r"^t: bad cone of bone"):
        read_cones(_reader(_section(entries)), "t", series.n_bones, series.parents)


def test_a_stream_with_a_bad_cone_is_refused_in_one_line():
    series, _ = coned_series(N=60)
    enc = encode_series(series, max_error=5.0)
    raw = bytearray(enc.data[:-4])
    at = raw.index(cone_bytes(enc.stream.quantiser.cones))
    raw[at + 1] = 0  # the first bone on a cone becomes lhipjoint, with an alpha: refused
    raw += struct.pack("<I", zlib.crc32(bytes(raw)))
    with pytest.raises(MotionDataError, match=r"^bad\.sidq: bad cone of bone 0"):
        sidq.from_bytes(bytes(raw), "bad.sidq")
