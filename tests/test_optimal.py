"""Segment costs and the exact optimum: against full reconstruction and brute force."""

import itertools

import numpy as np
import pytest
from keyframe_synth import smooth_clip

from sidql.keyframes.methods import greedy_from_costs, uniform_indices
from sidql.keyframes.metrics import q_error
from sidql.keyframes.optimal import optimal_table, solve
from sidql.keyframes.segment_costs import segment_cost_matrix
from sidql.keyframes.spherical import chart


@pytest.fixture(scope="module")
def series():
    return chart(smooth_clip(60, 30.0, seed=11))


@pytest.mark.parametrize("reconstruction", ["hermite", "linear"])
def test_segment_costs_sum_to_q_of_full_reconstruction(series, reconstruction):
    C = segment_cost_matrix(series, reconstruction)
    N, M = series.n_frames, series.n_bones
    rng = np.random.default_rng(0)
    for W in (2, 3, 7, 20, 60):
        k = np.sort(np.concatenate([[0, N - 1], rng.choice(np.arange(1, N - 1), W - 2, False)]))
        assert C[k[:-1], k[1:]].sum() / (N * M) == pytest.approx(
            q_error(series, k, reconstruction), 1e-12
        )
    assert np.all(np.diag(C, 1) == 0) and np.all(np.tril(C) == 0) and np.all(C >= 0)


def test_segment_costs_wrap_phi_differences():
    """Adding multiples of 2 pi to phi strictly inside a segment leaves its cost unchanged."""
    s = chart(smooth_clip(20, 30.0, seed=12))
    from dataclasses import replace

    shift = 2 * np.pi * np.random.default_rng(1).integers(-2, 3, s.phi.shape)
    shift[[0, -1]] = 0
    shifted = replace(s, phi=s.phi + shift)
    assert segment_cost_matrix(shifted)[0, -1] == pytest.approx(segment_cost_matrix(s)[0, -1])
    assert segment_cost_matrix(shifted)[0, -1] > 0


@pytest.mark.parametrize("reconstruction", ["hermite", "linear"])
def test_optimum_equals_brute_force_enumeration(reconstruction):
    s = chart(smooth_clip(60, 30.0, seed=13))
    # a short clip keeps the enumeration small: first 13 frames

    n = 13
    small = s.frames(slice(0, n))
    table = optimal_table(small, reconstruction)
    for W in range(2, 8):
        best = min(
            q_error(small, np.array((0, *inner, n - 1)), reconstruction)
            for inner in itertools.combinations(range(1, n - 1), W - 2)
        )
        k = table.keyframes(W)
        assert len(k) == W and k[0] == 0 and k[-1] == n - 1
        assert table.q(W) == pytest.approx(best, rel=1e-12)
        assert q_error(small, k, reconstruction) == pytest.approx(best, rel=1e-12)


@pytest.mark.parametrize("source", ["synthetic", "real walk"])
def test_optimum_is_never_worse_than_greedy_or_uniform(series, source, request):
    s = series
    if source == "real walk":
        s = chart(request.getfixturevalue("walk_clip").slice(20, 80))
    C = segment_cost_matrix(s)
    table = solve(C, s.n_bones)
    N = s.n_frames
    prev = np.inf
    for W in range(2, N + 1):
        q_opt = table.q(W)
        assert q_opt <= q_error(s, greedy_from_costs(C, W)) + 1e-12
        assert q_opt <= q_error(s, uniform_indices(N, W)) + 1e-12
        assert q_opt <= prev + 1e-12
        prev = q_opt
    assert table.q(N) == 0.0
    rows = table.all_keyframes()
    for W in (2, 5, N):
        assert np.array_equal(rows[W, :W], table.keyframes(W)) and np.all(rows[W, W:] == -1)


def test_solve_rejects_bad_sizes(series):
    C = segment_cost_matrix(series)
    with pytest.raises(ValueError):
        solve(C, 22, w_max=1)
    with pytest.raises(ValueError):
        solve(C, 22, w_max=5).keyframes(6)


def test_catmull_rom_optimum_equals_brute_force_enumeration():
    """The triple-state programme against enumeration, with Q from full reconstruction."""

    from sidql.keyframes.optimal import catmull_rom_optimal

    s = chart(smooth_clip(60, 30.0, seed=14))
    n = 12
    small = s.frames(slice(0, n))
    table = catmull_rom_optimal(small, 7)
    for W in range(2, 8):
        best = min(
            q_error(small, np.array((0, *inner, n - 1)), "catmull_rom")
            for inner in itertools.combinations(range(1, n - 1), W - 2)
        )
        k = table.keyframes(W)
        assert len(k) == W and k[0] == 0 and k[-1] == n - 1
        assert table.q(W) == pytest.approx(best, rel=1e-12)
        assert q_error(small, k, "catmull_rom") == pytest.approx(best, rel=1e-12)


def plain_programme(C, w_max):
    """The programme of the module docstring as a scan over predecessors per frame, in Python:
    (D, P) with P the least predecessor reaching the minimum (-1 where all are inf)."""
    N = len(C)
    D = np.full((w_max + 1, N), np.inf)
    P = np.full((w_max + 1, N), -1)
    D[1, 0] = 0.0
    for w in range(2, w_max + 1):
        for j in range(w - 1, N):
            for i in range(w - 2, j):
                if D[w - 1, i] + C[i, j] < D[w, j]:
                    D[w, j], P[w, j] = D[w - 1, i] + C[i, j], i
    return D, P


@pytest.mark.parametrize("kind", ["plain", "ties", "infs"])
def test_the_programme_equals_a_plain_scan_ties_and_infs_included(kind):
    from sidql.keyframes.optimal import _dp

    rng = np.random.default_rng({"plain": 1, "ties": 2, "infs": 3}[kind])
    for _ in range(20):
        n = int(rng.integers(2, 25))
        w_max = int(rng.integers(2, n + 1))
        C = np.triu(rng.uniform(0, 1, (n, n)), 1)
        if kind == "ties":
            C = np.round(C * 3) / 3  # many equal sums: the least predecessor must win
        if kind == "infs":
            C[rng.uniform(size=C.shape) < 0.6] = np.inf
        D, P = _dp(C, w_max)
        want_D, want_P = plain_programme(C, w_max)
        assert np.array_equal(D, want_D) and np.array_equal(P, want_P)
        reach = int(rng.integers(2, n + 1))  # a band: the entries beyond it inf, not read
        band = np.where(np.subtract.outer(np.arange(n), np.arange(n)) > -reach, C, np.inf)
        want_D, want_P = plain_programme(band, w_max)
        D, P = _dp(band, w_max, reach)
        assert np.array_equal(D, want_D) and np.array_equal(P, want_P)
