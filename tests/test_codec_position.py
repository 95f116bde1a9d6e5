"""The position coding (coding 2, .sidq versions 2 to 6): range coder, position quantiser, the
encoder's error measure against the decoder, targets, the container and hostile bytes."""

from __future__ import annotations

import struct
import zlib
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from keyframe_synth import piecewise_clip, smooth_clip

from sidql.codec import format as sidq
from sidql.codec.decode import decode_to_reconstruction, decoded_chart, reconstruct_stream
from sidql.codec.dpcm import RDO_BAND
from sidql.codec.encode import encode_series
from sidql.codec.entropy import decode_integers, encode_integers, estimate_size
from sidql.codec.plan import plan, position_band_costs, position_weights, subtree_sizes
from sidql.codec.position_format import coded_rows, estimated_block
from sidql.codec.positions import chart_points, position_errors
from sidql.codec.quantise import PositionQuantiser, keyframe_steps
from sidql.commands.main import main
from sidql.keyframes.spherical import chart, protocol_indices
from sim.errors import MotionDataError, UnmetTargetError, UsageError
from sim.motion.ingest import load_motion


@pytest.fixture(scope="module")
def series():
    return chart(smooth_clip(N=150, fps=30.0, seed=5))


@pytest.fixture(scope="module")
def encoded(series):
    return encode_series(series, max_error=2.0)


def _points(clip):
    return clip.positions[:, protocol_indices(clip)]


# ------------------------------------------------------------------------------ range coder
@settings(max_examples=60, deadline=None)
@given(
    st.integers(1, 6),
    st.integers(1, 80),
    st.floats(0.0, 5000.0),
    st.integers(0, 2**32 - 1),
    st.booleans(),
    st.booleans(),
)
def test_range_coder_round_trips(C, W, scale, seed, grouped, shared):
    rng = np.random.default_rng(seed)
    v = np.rint(rng.laplace(0.0, scale + 1e-9, (C, W))).astype(np.int64)
    v[:, : min(W, 2)] = rng.integers(-(2**29), 2**29, (C, min(W, 2)))  # large first values
    group = rng.integers(0, 3, W) if grouped else None
    kinds = rng.integers(-1, 3, C) if shared else None  # own contexts, or shared by kind
    data = encode_integers(v, group, kinds)
    back, used = decode_integers(data, C, W, group, kinds)
    assert np.array_equal(back, v)
    assert used <= len(data) + 5


def test_a_block_coded_again_is_the_kept_bytes_of_exactly_those_inputs():
    # the coder keeps its last blocks by their inputs: a repeat gives the same bytes, and
    # inputs with the same bytes but another shape, grouping or kinds are coded afresh
    rng = np.random.default_rng(3)
    v = np.rint(rng.laplace(0.0, 20.0, (4, 6))).astype(np.int64)
    first = encode_integers(v)
    assert encode_integers(v.copy()) is first
    others = [
        (v.reshape(6, 4), None, None),
        (v.reshape(3, 8), None, None),
        (v, np.array([0, 0, 0, 1, 1, 1]), None),
        (v, None, np.array([0, 0, 1, 1])),
    ]
    for values, group, kinds in others:
        data = encode_integers(values, group, kinds)
        back, _ = decode_integers(data, *values.shape, group, kinds)
        assert np.array_equal(back, values) and data != first
    w = v.copy()
    w[2, 3] += 1
    assert np.array_equal(decode_integers(encode_integers(w), 4, 6)[0], w)


def test_the_range_coder_has_room_for_its_costliest_integers():
    """Large values each in a fresh context group (coded from the prior, predicted against)
    cost more than 8 bytes each: the coder once wrote past its buffer and lost the stream's
    tail (hypothesis found it: 6 channels, 2 columns of values near 2^29, grouped)."""
    group = np.arange(8)
    longest = np.full((4, 8), (1 << 30) - 1)  # the longest code the coder takes
    longest[1::2] *= -1
    data = encode_integers(longest, group)
    back, used = decode_integers(data, 4, 8, group)
    assert np.array_equal(back, longest) and used <= len(data) + 5
    rng = np.random.default_rng(0)
    for _ in range(50):
        v = rng.integers(-(2**29), 2**29, (6, 2))
        assert np.array_equal(decode_integers(encode_integers(v, group[:2]), 6, 2, group[:2])[0], v)


def test_range_coder_beats_lzma_and_the_size_model_is_close():
    import lzma

    rng = np.random.default_rng(0)
    v = np.rint(rng.laplace(0.0, 3.0, (47, 1500))).astype(np.int64)
    real = len(encode_integers(v))
    assert real < len(lzma.compress(v.astype("<i2").tobytes(), preset=9 | lzma.PRESET_EXTREME))
    assert abs(estimate_size(v) / real - 1.0) < 0.05


def test_the_size_model_of_a_block_read_in_place_is_that_of_its_rows_bit_for_bit():
    rng = np.random.default_rng(4)
    for W in (1, 2, 37, 900):
        keys = np.sort(rng.choice(4 * W, W, replace=False))
        codes = np.rint(rng.laplace(0.0, rng.uniform(0.5, 3000.0), (W, 47))).astype(np.int64)
        rows = coded_rows(keys, codes)
        assert estimated_block(keys, codes) == estimate_size(rows)  # the same float
        bits = 0.0  # the model written out: per row, sign and lower bits plus the classes' entropy
        for row in rows:
            k = np.array([int(abs(x)).bit_length() for x in row])
            n = np.bincount(k).astype(float)
            n = n[n > 0]
            bits += k.sum() - (n * np.log2(n / W)).sum()
        assert estimated_block(keys, codes) == pytest.approx(bits / 8.0, rel=1e-12, abs=1e-9)


def test_shared_contexts_by_expected_magnitude_code_bursty_channels_in_fewer_bytes():
    """Channels of different spreads whose residuals grow together in some columns (a fast
    movement shakes every channel): contexts shared by kind and chosen by the channel's running
    magnitude times the column's activity so far learn that; one context set per channel
    cannot."""
    rng = np.random.default_rng(2)
    C, W = 47, 600
    activity = np.where(rng.random(W) < 0.2, 6.0, 1.0)  # a fifth of the columns are bursts
    spread = rng.uniform(0.5, 8.0, (C, 1))
    v = np.rint(rng.laplace(0.0, 1.0, (C, W)) * spread * activity).astype(np.int64)
    kinds = np.zeros(C, dtype=np.int64)
    shared = encode_integers(v, kinds=kinds)
    assert np.array_equal(decode_integers(shared, C, W, kinds=kinds)[0], v)
    assert len(shared) < 0.98 * len(encode_integers(v))  # 0.965 measured


def test_range_coder_refuses_bad_kinds():
    with pytest.raises(UsageError, match="kinds"):
        encode_integers(np.zeros((3, 4), dtype=np.int64), kinds=np.array([0, -2, 1]))
    with pytest.raises(UsageError, match="kinds"):
        decode_integers(b"", 3, 4, kinds=np.array([0, 1]))


def test_range_coder_refuses_values_beyond_its_range():
    with pytest.raises(ValueError, match="beyond"):
        encode_integers(np.array([[1 << 30]]))


@settings(max_examples=80, deadline=None)
@given(st.binary(max_size=300), st.integers(1, 48), st.integers(1, 400), st.booleans())
def test_range_decoder_of_garbage_is_bounded(data, C, W, shared):
    kinds = np.arange(C) % 4 - 1 if shared else None
    values, used = decode_integers(data, C, W, kinds=kinds)
    assert values.shape == (C, W) and np.abs(values).max(initial=0) < 2**30
    assert used >= 5


# ------------------------------------------------------------------------ position quantiser
def test_levers_are_length_times_points_below():
    parents = np.array([-1, 0, 1, 2, 0, 4])  # two chains of 3 bones from the root
    assert subtree_sizes(parents).tolist() == [6, 3, 2, 1, 2, 1]
    lengths = np.array([0.1, 0.2, 0.3, 0.4, 0.5])
    assert np.allclose(position_weights(lengths, parents), lengths * [3, 2, 1, 2, 1])


def test_quantiser_round_trip_and_error_bound(series):
    values, _ = series.channels()
    keys = np.arange(0, series.n_frames, 3)
    keys[-1] = series.n_frames - 1
    q = PositionQuantiser(series.n_bones, series.lengths, series.parents, 0.004, 0.5)
    codes, dec = q.encode_keyframes(values[keys], keys)
    assert np.array_equal(q.decode_keyframes(codes, keys), dec)
    M = series.n_bones
    scale = q.scales()
    err = np.abs(dec - values[keys])
    # theta and root within half a step (and the band of residuals rounded towards zero); phi
    # within that of its (sin theta scaled) step
    half = 0.5 + RDO_BAND
    assert np.all(err[:, :M] <= half * scale[:M] + 1e-12)
    assert np.all(err[:, 2 * M :] <= half * scale[2 * M :] + 1e-12)
    phi_step = np.minimum(scale[M : 2 * M] / np.maximum(np.sin(dec[:, :M]), 0.05), 0.5)
    assert np.all(err[:, M : 2 * M] <= half * phi_step + 1e-12)
    assert np.mean(err[:, :M] <= 0.5 * scale[:M] + 1e-12) > 0.9  # most values: the nearest
    # a channel's step moves the points it carries by about the same amount: lever x step
    lever = position_weights(series.lengths, series.parents) / np.sqrt(
        subtree_sizes(series.parents)[1:]
    )
    assert np.allclose(lever * scale[:M], scale[2 * M] * np.sqrt(len(series.parents)))


def test_aimed_keyframes_do_not_pile_errors_up_down_the_chain(series):
    """Aiming each bone from its decoded parent point at its true point keeps the deepest points
    (wrists, feet, head) about as close as the shallow ones, where quantising each angle on its
    own lets the errors of every bone above them add up; the decoder rebuilds the same values
    whichever way the encoder chose them."""
    values, _ = series.channels()
    keys = np.arange(series.n_frames)
    q = PositionQuantiser(series.n_bones, series.lengths, series.parents, 0.004, 0.5, exponent=0)
    truth = chart_points(values, series.lengths, series.parents)
    depth = np.zeros(len(series.parents), dtype=int)
    for j in range(1, len(series.parents)):
        depth[j] = depth[series.parents[j]] + 1
    deep = depth >= depth.max() - 1
    errors = {}
    for aim in (False, True):
        codes, dec = q.encode_keyframes(values, keys, aim)
        assert np.array_equal(q.decode_keyframes(codes, keys), dec)
        pts = chart_points(dec, series.lengths, series.parents)
        errors[aim] = np.linalg.norm(pts - truth, axis=-1)
    assert errors[True][:, deep].mean() < 0.7 * errors[False][:, deep].mean()
    # each point's error stays near one step, not the chain's sum of steps
    assert errors[True][:, deep].mean() < 1.5 * errors[True][:, ~deep].mean()


# -------------------------------------------------------------------------- error measure
@pytest.mark.parametrize("reconstruction", ["linear", "catmull_rom"])
def test_encoder_error_is_the_decoded_error(series, reconstruction):
    """The compiled error measure the encoder searches with equals the error of the decoder's
    own output (decoded chart, then points) to rounding."""
    values, _ = series.channels()
    truth = chart_points(values, series.lengths, series.parents)
    enc = encode_series(series, max_error=1.5, reconstruction=reconstruction)
    s = enc.stream
    kv = s.quantiser.decode_keyframes(s.pose_codes, s.keyframes)
    mine = position_errors(truth, s.keyframes, kv, reconstruction, s.lengths, s.parents)
    decoded = chart_points(decoded_chart(s)["values"], s.lengths, s.parents)
    assert np.allclose(mine, np.linalg.norm(decoded - truth, axis=-1), atol=1e-12)
    assert enc.mean_error_mm == pytest.approx(1000.0 * mine.mean())


@pytest.mark.parametrize(
    ("reconstruction", "keys"),
    [("linear", [0, 9, 25, 40, 59]), ("catmull_rom", [0, 59])],  # Catmull-Rom: one straight line
)
def test_motion_the_curve_represents_costs_nothing_between_its_keyframes(reconstruction, keys):
    """Angles and root moving on the reconstruction's own curve between keyframes give zero
    segment costs there; the plan finds exactly those keyframes."""
    keys = np.array(keys)
    clip = piecewise_clip(keys, 60, 30.0, seed=2, curve="linear")
    s = chart(clip)
    values, _ = s.channels()
    C = position_band_costs(values, values, None, 60, reconstruction, s.lengths, s.parents)
    for a, b in zip(keys[:-1], keys[1:], strict=True):
        assert C[a, b - a] < 1e-9
    assert plan(C, 1e-3).keyframes.tolist() == keys.tolist()


def test_a_frame_cap_removes_exactly_the_segments_with_a_frame_beyond_it(series):
    """Segments of the capped table are those of the uncapped one whose every inner frame's
    first-order displacement bound (recomputed here for linear segments) is within the cap."""
    values, _ = series.channels()
    L, par = series.lengths, series.parents
    free = position_band_costs(values, values, None, 12, "linear", L, par)
    capped = position_band_costs(values, values, None, 12, "linear", L, par, frame_cap_mm=4.0)
    M, J = series.n_bones, len(par)
    weight = np.asarray(L) * subtree_sizes(par)[1:]
    removed = kept = 0
    for i in range(0, len(values) - 12, 7):
        beyond = False  # a frame of this segment or a shorter one from i passes the cap
        for g in range(1, 13):
            if not np.isfinite(free[i, g]):
                continue
            t = (np.arange(i + 1, i + g) - i)[:, None] / g
            e = values[i] + t * (values[i + g] - values[i]) - values[i + 1 : i + g]
            e[:, : 2 * M] = (e[:, : 2 * M] + np.pi) % (2 * np.pi) - np.pi
            sin = np.sin(values[i + 1 : i + g, :M])
            per_frame = (weight * np.hypot(e[:, :M], sin * e[:, M : 2 * M])).sum(1)
            per_frame += J * np.linalg.norm(e[:, 2 * M :], axis=1)
            beyond = beyond or 1000.0 * per_frame.max(initial=0.0) / J > 4.0 + 1e-9
            if np.isfinite(capped[i, g]):
                assert not beyond and capped[i, g] == pytest.approx(free[i, g])
                kept += 1
            else:
                assert beyond
                removed += 1
    assert removed and kept
    assert np.isfinite(capped[:-1, 1]).all()  # one-frame segments always allowed


# --------------------------------------------------------------------------------- targets
def test_max_error_is_met_and_tighter_costs_more(series):
    clip_points = chart_points(series.channels()[0], series.lengths, series.parents)
    sizes = []
    for e in (4.0, 1.0):
        enc = encode_series(series, max_error=e)
        rec = reconstruct_stream(sidq.from_bytes(enc.data))
        assert rec.positions.shape[0] == series.n_frames
        assert enc.mean_error_mm <= e
        sizes.append(len(enc.data))
    assert sizes[1] > sizes[0]
    assert clip_points.shape == (series.n_frames, 23, 3)


def test_rate_is_met_and_error_falls_with_rate(series):
    duration = series.n_frames * series.dt
    errors = []
    for rate in (300.0, 900.0):
        enc = encode_series(series, rate=rate)
        assert enc.stream.coding == 2
        assert len(enc.data) <= rate * duration
        errors.append(enc.mean_error_mm)
    assert errors[1] < errors[0]


@pytest.mark.parametrize("n", [2, 3, 7])
def test_the_shortest_trials_encode_within_their_budget(series, n):
    sub = series.frames(slice(0, n))
    budget = 5000.0 * n * series.dt
    enc = encode_series(sub, rate=5000.0)
    assert len(enc.data) <= budget and enc.stream.n_frames == n
    assert encode_series(sub, max_error=1.0).mean_error_mm <= 1.0 + 1e-9


def test_an_unreachable_error_says_what_can_be_reached(series):
    with pytest.raises(UnmetTargetError, match="cannot reach 1e-05 mm: the finest stream has"):
        encode_series(series, max_error=1e-5)


def test_max_error_needs_an_offline_position_stream(series):
    with pytest.raises(ValueError, match="offline"):
        encode_series(series, max_error=2.0, latency=5)
    with pytest.raises(ValueError, match="exactly one"):
        encode_series(series, max_error=2.0, rate=500.0)


# ------------------------------------------------------------------------------- container
def test_container_round_trip(encoded):
    s = sidq.from_bytes(encoded.data)
    assert encoded.data[4] == sidq.VERSION_POSITION and s.coding == 2
    assert np.array_equal(s.keyframes, encoded.stream.keyframes)
    assert np.array_equal(s.pose_codes, encoded.stream.pose_codes)
    assert np.array_equal(s.lengths, encoded.stream.lengths)
    assert sidq.to_bytes(s) == encoded.data
    a = decoded_chart(s)["values"]
    b = decoded_chart(encoded.stream)["values"]
    assert np.array_equal(a, b)


@pytest.mark.parametrize("version", [2, 3, 4])
def test_version_2_to_4_streams_still_decode(encoded, version):
    s = encoded.stream
    # versions 2 to 4: the parent's innovation in the prediction, one step for all keyframes
    q = replace(s.quantiser, partner=True, gap_exponent=0.0)
    if version < 4:  # versions 2 and 3: the root predicted like angles
        q = replace(q, root_rho=None, exponent=0.5 if version == 2 else q.exponent)
    old = replace(s, quantiser=q)
    data = sidq.to_bytes(old, position_version=version)
    assert data[4] == version and len(data) != len(encoded.data)  # another coded block
    back = sidq.from_bytes(data, "old.sidq")
    assert back.quantiser.exponent == q.exponent and back.quantiser.root_rho == q.root_rho
    assert back.quantiser.partner and back.quantiser.gap_exponent == 0
    assert np.array_equal(back.pose_codes, old.pose_codes)
    values = decoded_chart(back)["values"]
    assert np.array_equal(values, decoded_chart(old)["values"])
    # the same codes read as version 5 (no partner term, steps by gap) are other values
    as_v5 = decoded_chart(replace(s, pose_codes=old.pose_codes))["values"]
    assert not np.array_equal(values, as_v5)


def test_a_version_the_quantiser_does_not_fit_is_not_written(encoded):
    with pytest.raises(UsageError, match="cannot carry"):
        sidq.to_bytes(encoded.stream, position_version=3)  # its root slope is not rho
    with pytest.raises(UsageError, match="cannot carry"):
        sidq.to_bytes(encoded.stream, position_version=4)  # its steps follow the gaps
    q4 = replace(encoded.stream.quantiser, partner=True, gap_exponent=0.0)
    with pytest.raises(UsageError, match="cannot carry"):  # version 5 has no partner term
        sidq.to_bytes(replace(encoded.stream, quantiser=q4), position_version=5)


def test_keyframe_steps_follow_the_frames_each_keyframe_moves():
    """Keyframes 0, 1, 3, 7 of 8 frames move (1 + 1) / 2, (1 + 2) / 2, (2 + 4) / 2 and
    (4 + 1) / 2 frames, 2 on average: their steps are (2 / w)^g."""
    keys = np.array([0, 1, 3, 7])
    w = np.array([1.0, 1.5, 3.0, 2.5])
    for g in (0.25, 0.5, 0.75, 1.0):
        assert np.allclose(keyframe_steps(keys, g), (2.0 / w) ** g, rtol=1e-15)
    assert np.array_equal(keyframe_steps(keys, 0.0), np.ones(4))
    assert np.array_equal(keyframe_steps(np.arange(9), 0.25), np.ones(9))  # every frame: 1


def test_a_first_keyframe_is_predicted_from_the_parent_bone_on_any_branch(series):
    """Version 5: a bone's first keyframe is predicted from its parent's decoded angles, so a
    chain that starts straight costs next to nothing past its first bone (predicted from 0, as
    before, hundreds of steps), and a phi moved by whole turns codes to the same residuals and
    the same points."""
    M = series.n_bones
    values, _ = series.channels()
    keys = np.arange(0, 150, 5)
    q = PositionQuantiser(M, series.lengths, series.parents, 0.004, 0.5, exponent=0.125,
                          root_rho=1.0, partner=False)  # fmt: skip
    bones = [b for b in range(M) if series.parents[b + 1] > 0]  # bones with a parent bone
    straight = values[keys].copy()
    for b in bones:  # every bone with a parent bone points like it, on the grid of 0
        p = series.parents[b + 1] - 1
        straight[:, b], straight[:, M + b] = straight[:, p], straight[:, M + p]
    codes, _ = q.encode_keyframes(straight, keys)
    old, _ = replace(q, partner=True).encode_keyframes(straight, keys)
    chained = [d for b in bones for d in (b, M + b)]
    assert np.abs(codes[0, chained]).max() <= 1 and np.median(np.abs(old[0, chained])) > 50
    turned = values[keys].copy()
    turned[:, M + 3] += 4 * np.pi  # a whole number of turns on one bone's phi
    c1, v1 = q.encode_keyframes(values[keys], keys)
    c2, v2 = q.encode_keyframes(turned, keys)
    assert np.array_equal(c1, c2)
    assert np.allclose(q.decode_keyframes(c2, keys), v1, atol=1e-9)


def test_a_keyframe_a_long_gap_leans_on_is_quantised_finer(series):
    """With a gap exponent the same values at the same step are rebuilt closer where the gaps
    around a keyframe are long, and coarser where they are short."""
    values, _ = series.channels()
    keys = np.r_[np.arange(0, 40), np.arange(40, 150, 10), 149]
    keys = np.unique(keys)
    M = series.n_bones
    q = PositionQuantiser(M, series.lengths, series.parents, 0.01, 0.5, exponent=0.125,
                          root_rho=1.0, partner=False)  # fmt: skip
    err = {}
    for g in (0.0, 0.5):
        _, kv = replace(q, gap_exponent=g).encode_keyframes(values[keys], keys)
        err[g] = np.abs(kv[:, 2 * M :] - values[keys, 2 * M :]).mean(axis=1)  # the root [m]
    dense, sparse = keys < 38, (keys > 45) & (keys < 140)
    assert err[0.5][sparse].mean() < 0.8 * err[0.0][sparse].mean()
    assert err[0.5][dense].mean() > 1.1 * err[0.0][dense].mean()


#: a version-2 stream written by the version-2 encoder (24 frames of ``smooth_clip(N=24, seed=3)``
#: at 4 mm), and the SHA-256 of the float64 chart its decoder rebuilt
V2_STREAM = bytes.fromhex(
    "534944510202020000000000f041000000000000000000efc36556b6047f26ba57835d3a787458cc4c8d32df"
    "d6194f5f1ab720a67d8c89a118cd97a5ac89cb8c13a2f05b0ad7233c040600000000189bc5b68c74f5a950b2"
    "efcc28e72c5d4651c2e1fbe7312db881b8476a79e63037c8c7f5990748ebfb256121dc52325fb5749f62084f"
    "d5d7c359db69b48df711b09e66155005ba7045e4d6a82c1f10712500a8468c0a49020ad2cbb71c62acc5ac0a"
    "98eff127bb6293e7a185beb3d75e289c579da4e695d50a28575290b1812527256c3bcda000cc5eca268ae7d6"
    "7463481f71feb52aa96904883d08ef24dad47e4ca18a51a5c8d575cee06e3752ee9f23bc86f1363ae8b973d6"
    "a4bf76832e3d6a35a5c5fef74d0f487a90cec7b4c1dcc0aa4b588d9ee547a67433a8ff629c0875dca4ecf9c8"
)
V2_CHART_SHA256 = "408a962f1e5ba1c38317d96152e48857669e5c3084c9215e673770cdfeae59c0"


def test_a_stream_of_the_version_2_encoder_decodes_bit_for_bit():
    import hashlib

    s = sidq.from_bytes(V2_STREAM, "old.sidq")
    assert V2_STREAM[4] == 2 and s.quantiser.exponent == 0.5
    values = np.ascontiguousarray(decoded_chart(s)["values"])
    assert hashlib.sha256(values.tobytes()).hexdigest() == V2_CHART_SHA256


#: a version-4 stream written by the version-4 encoder (``smooth_clip(N=24, seed=3)`` at 4 mm),
#: and the SHA-256 of the float64 chart its decoder rebuilt: the bit stream stays decodable
V4_STREAM = bytes.fromhex(
    "534944510402020000000000f041000000000000000000efc36556b6047f26ba57835d3a787458cc4c8d32df"
    "d6194f5f1ab720a67d8c89a118cd97a5ac89cb8c13a2f05ba69bc43b0402080500000000194d324cee4d240f"
    "a22680505ebf7c3f22cd490b242064496f8a55e4ec62e541ee4fc4a5c6086e0cdda1abb990ba801b8d3608e1"
    "cab784eb71b77940e4d27f0150b7cf454e45b48cf7f95c7a90f3e2d7ec8c7575c18c295b1600750d3976099a"
    "f204a07dc38dbbe4066e54b4b23a5ac7c0eea6d6dd689c30d29cd777fa388a30f37e8b5f70634c24260a6201"
    "2f856cacf3ee796a7813165d453b8deddb864814261f6488424c9c6cdd2b86ed8bf71fc92c7c81ed235a6895"
    "45b6ac449acb1db09deb17006ca70c98"
)
V4_CHART_SHA256 = "fab152e360fb4d568f3b1e770da704c32efe37836033e8a2ced342869c3abf1e"


def test_a_stream_of_the_version_4_encoder_decodes_bit_for_bit():
    import hashlib

    s = sidq.from_bytes(V4_STREAM, "v4.sidq")
    assert V4_STREAM[4] == 4 and s.quantiser.root_rho == 1.0 and s.quantiser.exponent == 0.125
    values = np.ascontiguousarray(decoded_chart(s)["values"])
    assert hashlib.sha256(values.tobytes()).hexdigest() == V4_CHART_SHA256


#: a version-5 stream written by the version-5 encoder (``smooth_clip(N=24, seed=3)`` at 4 mm),
#: and the SHA-256 of the float64 chart its decoder rebuilt: the bit stream stays decodable
V5_STREAM = bytes.fromhex(
    "534944510502020000000000f041000000000000000000efc36556b6047f26ba57835d3a787458cc4c8d32df"
    "d6194f5f1ab720a67d8c89a118cd97a5ac89cb8c13a2f05ba69bc43b040208010500000000194d323b6aa2f8"
    "6addcc4143a86d11e3ffb38be1fe861cfd99d57f37c09616f24330185b5c41db09006de83098cb8f215ecbcf"
    "bff480715a88aeb48bae92a8449066abdac9bdc41347cef5aa7bc513c6819743698748aa8d1bd6e66e3743d1"
    "7e932652deb9a1b8ab056f892d74142720aa0de5dd4eb048dec2ea0d8b179e927e65e9c0c5e1c8f0beba9fd8"
    "54aa4cf19b5387e9211ae23bd2a1675dd2abf517e125f10f570275f180340016f4fc735dd3bf10683cc8a132"
    "74f97f9cf700f1f29dd2"
)
V5_CHART_SHA256 = "e54c7d9301815f0a4a45277f143805901274b56ca9a163d06a6134539b985ff8"


def test_a_stream_of_the_version_5_encoder_decodes_bit_for_bit():
    import hashlib

    s = sidq.from_bytes(V5_STREAM, "v5.sidq")
    q = s.quantiser
    assert V5_STREAM[4] == 5 and q.gap_exponent == 0.25 and not q.partner
    assert q.root_rho == 1.0 and q.exponent == 0.125
    values = np.ascontiguousarray(decoded_chart(s)["values"])
    assert hashlib.sha256(values.tobytes()).hexdigest() == V5_CHART_SHA256
    assert sidq.to_bytes(s, position_version=5) == V5_STREAM
    v6 = sidq.to_bytes(s)  # version 6 adds only the cone count (0) after the gap exponent
    assert v6[4] == 6 and len(v6) == len(V5_STREAM) + 1
    assert np.array_equal(decoded_chart(sidq.from_bytes(v6))["values"], values)


def test_a_root_at_constant_velocity_costs_no_residuals_after_two_keyframes():
    """The root channels are predicted by linear extrapolation (rho_root = 1): a pelvis gliding
    at constant velocity through a still pose leaves zero residuals from the third keyframe on;
    the angles' half slope (rho = 0.5) would not."""
    M, W = 22, 12
    parents = np.asarray(chart(smooth_clip(N=8, seed=1)).parents)
    values = np.zeros((W, 2 * M + 3))
    values[:, :M] = 1.0
    keys = np.arange(W) * 2
    q = PositionQuantiser(M, np.full(M, 0.2), parents, 0.001, 0.5, exponent=0.125, root_rho=1.0)
    root_step = q.scales()[2 * M]  # on the grid, so that only the predictor decides
    values[:, 2 * M :] = np.arange(W)[:, None] * np.array([19, -31, 6]) * root_step
    codes, _ = q.encode_keyframes(values, keys)
    assert not codes[2:, 2 * M :].any() and codes[1, 2 * M :].any()
    half = replace(q, root_rho=0.5).encode_keyframes(values, keys)[0]
    assert np.abs(half[2:, 2 * M :]).min() > 0


@pytest.mark.parametrize(
    "offset, what", [(1, "lever exponent"), (2, "root predictor"), (3, "gap exponent")]
)
def test_a_bad_lever_exponent_root_predictor_or_gap_exponent_is_one_line(encoded, offset, what):
    raw = bytearray(encoded.data[:-4])
    at = 23 + 1 + 2 * 22 + 4 + offset  # header, length unit and codes, step, then rho
    q = encoded.stream.quantiser
    byte = (16 * q.exponent, 8 * q.root_slope, 4 * q.gap_exponent)[offset - 1]
    assert raw[4] == sidq.VERSION_POSITION and raw[at] == round(byte)
    raw[at] = 17
    raw += struct.pack("<I", zlib.crc32(bytes(raw)))
    with pytest.raises(MotionDataError, match=rf"^bad\.sidq: bad position step .*{what} 17"):
        sidq.from_bytes(bytes(raw), "bad.sidq")


def test_stored_lengths_code_to_themselves():
    rng = np.random.default_rng(1)
    for top in (0.01, 0.45, 3.0):
        L = rng.uniform(0.0, top, 22)
        stored = sidq.position_lengths(L)
        assert np.array_equal(sidq.position_lengths(stored), stored)
        assert np.abs(stored - L).max() <= top / 65535.0


@settings(max_examples=150, deadline=None)
@given(st.data())
def test_fuzzed_position_streams_fail_cleanly(encoded, data):
    raw = bytearray(encoded.data)
    kind = data.draw(st.sampled_from(["truncate", "flip", "garbage", "recrc"]))
    if kind == "truncate":
        raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
    elif kind == "flip":
        i = data.draw(st.integers(0, len(raw) - 1))
        raw[i] ^= data.draw(st.integers(1, 255))
    elif kind == "garbage":
        raw = bytearray(b"SIDQ\x02\x02\x02\x00" + data.draw(st.binary(max_size=400)))
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
    assert kind in ("recrc", "garbage")  # a corrupt value behind a valid checksum may parse...
    rec = reconstruct_stream(s)  # ...and must then decode to finite frames within the limit
    assert rec.positions.shape[0] == s.n_frames <= sidq.MAX_FRAMES
    assert np.isfinite(rec.positions).all()


def test_residuals_that_run_away_are_refused(encoded):
    """A stream whose residuals drive the predictor to overflow (no encoder writes one, a hostile
    sender can) is one clean error, not infinite points."""
    s = encoded.stream
    W = 600
    keys = np.arange(W, dtype=np.int64)
    huge = np.zeros((W, s.pose_codes.shape[1]), dtype=np.int64)
    huge[1::2], huge[2::2] = (1 << 29) - 1, -((1 << 29) - 1)  # alternating: the slope explodes
    hostile = replace(s, keyframes=keys, pose_codes=huge, quantiser=replace(s.quantiser, rho=2.0))
    data = sidq.to_bytes(hostile)
    with pytest.raises(MotionDataError, match="implausible"):
        sidq.from_bytes(data, "hostile.sidq")


# --------------------------------------------------------------------------------- real data
def test_cli_max_error_on_a_real_trial(cmu_dir, tmp_path, capsys):
    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    out = tmp_path / "walk.sidq"
    assert main(["encode", str(asf), str(amc), "--out", str(out), "--max-error", "3"]) == 0
    assert "position      mean error" in capsys.readouterr().out
    rec = decode_to_reconstruction(out)
    truth = _points(load_motion(asf, amc))  # MuJoCo's kinematics, not the codec's
    err = 1000.0 * np.linalg.norm(rec.positions - truth, axis=-1)
    assert err.mean() <= 3.0 + 1e-6
    with pytest.raises(SystemExit) as e:
        main(
            ["encode", str(asf), str(amc), "--out", str(out), "--max-error", "3", "--latency", "4"]
        )
    assert e.value.code == 2
    err_line = capsys.readouterr().err.strip()
    assert err_line.startswith("sidql encode: error:") and "--max-error" in err_line
