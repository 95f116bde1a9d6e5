"""The codec's mathematics: quantiser, container, whole-trial programme, rate control, streaming."""

from __future__ import annotations

import itertools
import struct
import zlib
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from keyframe_synth import smooth_clip

from sidql.codec import format as sidq
from sidql.codec.decode import decoded_chart, reconstruct_stream
from sidql.codec.encode import encode_series
from sidql.codec.encoded import measure
from sidql.codec.plan import band_costs, plan
from sidql.codec.quantise import PHI_STEP, THETA_STEP, fit_quantiser
from sidql.codec.stream import frame_delays, horizon, plan_stream
from sidql.keyframes.curves import CURVES
from sidql.keyframes.segment_costs import segment_cost_matrix, stacked
from sidql.keyframes.spherical import chart
from sim.errors import MotionDataError, UnmetTargetError
from sim.model.angles import wrap_angle


@pytest.fixture(scope="module")
def series():
    return chart(smooth_clip(N=150, fps=30.0, seed=3))


@pytest.fixture(scope="module")
def encoded(series):
    return encode_series(series, rate=1500.0, reconstruction="catmull_rom", objective="angle")


@pytest.fixture(scope="module")
def live(series):
    """A coding-0 (fixed records) Hermite stream."""
    return encode_series(series, rate=5000.0, reconstruction="hermite", latency=10)


def _values(s):
    return np.concatenate([s.theta, s.phi, s.root_pos], axis=1)


def _rates(s):
    return np.concatenate([s.dtheta, s.dphi, s.root_vel], axis=1)


@pytest.mark.parametrize("bits", [9, 12, 16])
def test_quantiser_error_is_half_a_step_and_phi_follows_the_branch(series, bits):
    v = _values(series)
    q = fit_quantiser(v, _rates(series), series.n_bones, bits)
    theta_step, phi_step = THETA_STEP * 65535 / (2**bits - 1), PHI_STEP * 2 ** (16 - bits)
    M = series.n_bones
    codes = q.encode_pose(v)
    assert codes.max() < 2**bits
    back = q.decode_pose(codes)
    assert np.abs(back[:, :M] - v[:, :M]).max() <= theta_step / 2 + 1e-12
    # phi: decoded on the first frame's branch, so off by one constant multiple of 2 pi per bone
    shift = (back[:, M : 2 * M] - v[:, M : 2 * M]) / (2 * np.pi)
    k = np.rint(shift[0])
    assert np.abs(shift - k).max() * 2 * np.pi <= phi_step / 2 + 1e-9
    step = q.root_step.astype(float)
    assert np.all(np.abs(back[:, 2 * M :] - v[:, 2 * M :]) <= step / 2 + 1e-6)
    g = q.grid_pose(v)
    assert np.allclose(np.cos(g[:, M : 2 * M]), np.cos(back[:, M : 2 * M]), atol=1e-12)
    r = _rates(series)
    assert np.abs(
        q.grid_rates(r) - np.clip(r, -32767 * q.rate_step, 32767 * q.rate_step)
    ).max() <= (q.rate_step.max() / 2 + 1e-9)


@pytest.mark.parametrize("reconstruction", ["hermite", "linear"])
def test_band_costs_match_the_project_segment_cost_matrix(series, reconstruction):
    """Unquantised, the band table is a band of sidql.keyframes' (N, N) matrix."""
    sub = series.frames(slice(0, 40))
    X, R = stacked(sub)
    full = segment_cost_matrix(sub, reconstruction)
    C = band_costs(X, X, R if reconstruction == "hermite" else None, 7, reconstruction)
    for i in range(40):
        for g in range(1, 8):
            if i + g < 40:
                assert C[i, g] == pytest.approx(full[i, i + g], rel=1e-9, abs=1e-9)


def test_programme_matches_brute_force():
    rng = np.random.default_rng(0)
    N, G = 11, 4
    C = np.full((N, G + 1), np.inf)
    C[:, 0] = 0
    for i in range(N):
        for g in range(1, G + 1):
            if i + g < N:
                C[i, g] = rng.uniform(0, 3) * (g - 1) ** 1.5
    for lam in (0.0, 0.3, 1.0, 5.0):
        best, arg = np.inf, None
        for r in range(N - 1):
            for inner in itertools.combinations(range(1, N - 1), r):
                k = (0, *inner, N - 1)
                gaps = np.diff(k)
                if gaps.max() > G:
                    continue
                cost = sum(C[a, b - a] for a, b in itertools.pairwise(k)) + lam * len(k)
                if cost < best - 1e-12:
                    best, arg = cost, k
        p = plan(C, lam)
        got = sum(C[a, b - a] for a, b in itertools.pairwise(p.keyframes)) + lam * len(p.keyframes)
        assert got == pytest.approx(best)
        assert np.diff(p.keyframes).max() <= G
        assert p.distortion == pytest.approx(best - lam * len(arg))


@pytest.mark.parametrize("reconstruction", ["hermite", "linear"])
def test_programme_distortion_is_the_decoded_error(series, reconstruction):
    """For the separable reconstructions the table's distortion is what the decoder's output measures
    (up to the quantisation error at the keyframes themselves)."""
    enc = encode_series(series, rate=2500.0, reconstruction=reconstruction, objective="angle")
    s = enc.stream
    v, r = _values(series), _rates(series)
    M = series.n_bones
    Xq = s.quantiser.grid_pose(v)
    Rq = s.quantiser.grid_rates(r) * series.dt if reconstruction == "hermite" else None
    C = band_costs(
        v[:, : 2 * M], Xq[:, : 2 * M], None if Rq is None else Rq[:, : 2 * M], 60, reconstruction
    )
    k = s.keyframes
    dist = sum(C[a, b - a] for a, b in itertools.pairwise(k))
    at_keys = np.abs(wrap_angle(Xq[k, : 2 * M] - v[k, : 2 * M])).sum()  # quantisation at keyframes
    want = (dist + at_keys) / (series.n_frames * M)
    assert measure(series, s) == pytest.approx(want, rel=1e-9, abs=1e-12)


def test_rate_control_meets_the_budget_and_error_falls_with_rate(series):
    duration = series.n_frames * series.dt
    qs = []
    for rate in (250.0, 500.0, 1000.0):
        enc = encode_series(series, rate=rate, reconstruction="catmull_rom")
        assert len(enc.data) <= rate * duration
        assert len(enc.data) > 0.8 * rate * duration  # the control uses most of the budget
        qs.append(enc.q)
    assert qs[0] > qs[1] > qs[2]


def test_max_q_is_met_with_fewer_bytes_for_a_looser_target(series):
    tight = encode_series(series, max_q=0.01, reconstruction="auto")
    loose = encode_series(series, max_q=0.04, reconstruction="auto")
    assert tight.q <= 0.01 + 1e-12 and loose.q <= 0.04 + 1e-12
    assert len(loose.data) < len(tight.data)


def test_auto_picks_the_least_error(series):
    enc = encode_series(series, rate=1500.0, reconstruction="auto", objective="angle")
    assert {k.split("/")[0] for k in enc.candidates} == set(CURVES)
    assert enc.q == min(q for q, _ in enc.candidates.values())
    assert f"{enc.stream.reconstruction}/{enc.stream.quantiser.bits}" in enc.candidates


def test_a_stream_names_its_curve_by_its_index_in_the_one_curve_list(series):
    assert CURVES[:3] == ("hermite", "linear", "catmull_rom")  # codes of version-1 files
    for code, curve in enumerate(CURVES):
        data = encode_series(series, rate=2500.0, reconstruction=curve).data
        assert data[5] == code and sidq.from_bytes(data).reconstruction == curve


def test_rate_below_the_max_gap_floor_is_a_clean_error(series):
    with pytest.raises(UnmetTargetError, match="rate too low"):
        encode_series(series, rate=10.0, reconstruction="linear", max_gap=10)


@pytest.mark.parametrize("which", ["encoded", "live"])
def test_container_round_trip_and_determinism(which, request):
    encoded = request.getfixturevalue(which)
    data = encoded.data
    s = sidq.from_bytes(data)
    assert sidq.to_bytes(s) == data
    assert np.array_equal(s.keyframes, encoded.stream.keyframes)
    a, b = reconstruct_stream(s), reconstruct_stream(sidq.from_bytes(data))
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.velocities, b.velocities)
    assert a.positions.shape == (150, 23, 3)


@settings(max_examples=150, deadline=None)
@given(st.data())
def test_fuzzed_streams_fail_cleanly(encoded, live, data):
    assert encoded.stream.coding == 1 and live.stream.coding == 0
    raw = bytearray(data.draw(st.sampled_from([encoded, live])).data)
    kind = data.draw(st.sampled_from(["truncate", "flip", "garbage", "recrc"]))
    if kind == "truncate":
        raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
    elif kind == "flip":
        i = data.draw(st.integers(0, len(raw) - 1))
        raw[i] ^= data.draw(st.integers(1, 255))
    elif kind == "garbage":
        raw = bytearray(data.draw(st.binary(max_size=600)))
        if data.draw(st.booleans()):
            raw[:5] = b"SIDQ\x01"
            raw += struct.pack("<I", zlib.crc32(bytes(raw)))
    else:  # a defect behind a valid checksum: only the parser's checks can catch it
        i = data.draw(st.integers(4, len(raw) - 5))
        raw[i] ^= data.draw(st.integers(1, 255))
        raw[-4:] = struct.pack("<I", zlib.crc32(bytes(raw[:-4])))
    try:
        s = sidq.from_bytes(bytes(raw), "fuzz.sidq")
    except MotionDataError as e:
        assert "\n" not in str(e) and str(e).startswith("fuzz.sidq")
        return
    assert kind == "recrc"  # a corrupt value behind a valid checksum may still parse...
    rec = reconstruct_stream(s)  # ...and then it must still decode to finite frames
    assert rec.positions.shape[0] == s.n_frames and np.isfinite(rec.positions).all()


@pytest.mark.parametrize("reconstruction", ["hermite", "linear", "catmull_rom"])
@pytest.mark.parametrize("latency", [4, 9, 20])
def test_streaming_delay_is_bounded_by_the_latency(series, reconstruction, latency):
    enc = encode_series(series, rate=4000.0, reconstruction=reconstruction, latency=latency)
    s = enc.stream
    assert s.latency == latency
    # replay the fixed-lag plan to get the decision times and check every frame's wait
    v, r = _values(series), _rates(series)
    M = series.n_bones
    q = fit_quantiser(v, r if reconstruction == "hermite" else None, M)
    Xq = q.grid_pose(v)
    Rq = q.grid_rates(r) * series.dt if reconstruction == "hermite" else None
    H = horizon(latency, reconstruction)
    C = band_costs(
        v[:, : 2 * M],
        Xq[:, : 2 * M],
        None if Rq is None else Rq[:, : 2 * M],
        min(60, H),
        reconstruction,
    )
    p = plan_stream(C, 1.0, H)
    d = frame_delays(p.keyframes, p.decided_at, reconstruction)
    assert d.max() < latency and d.min() >= 0
    assert np.diff(s.keyframes).max() <= H


@pytest.mark.parametrize("reconstruction", ["hermite", "linear", "catmull_rom"])
def test_decoder_is_causal(series, reconstruction):
    """Frames up to a keyframe (Catmull-Rom: up to the one before it) decode identically from the
    records received so far: a live decoder can emit them without the rest of the stream."""
    s = encode_series(series, rate=1500.0, reconstruction=reconstruction).stream
    full = decoded_chart(s)["values"]
    for w in (2, 4, len(s.keyframes) // 2):
        part = replace(
            s,
            keyframes=s.keyframes[: w + 1],
            pose_codes=s.pose_codes[: w + 1],
            rate_codes=None if s.rate_codes is None else s.rate_codes[: w + 1],
        )
        got = decoded_chart(part)["values"]
        upto = s.keyframes[w - 1 if reconstruction == "catmull_rom" else w]
        assert np.array_equal(got[:upto], full[:upto])
        # the last received keyframe ends a segment (s = 1) rather than starting one: one ulp
        np.testing.assert_allclose(got[upto], full[upto], rtol=0, atol=1e-12)
