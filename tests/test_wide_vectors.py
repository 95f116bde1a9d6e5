"""``wide_vectors()`` marks the kernel that calls it for the processor's widest vectors, and the
single-precision segment costs it is used in keep their numbers to the last bit."""

from __future__ import annotations

import types

import numba
import numpy as np
import pytest

from sidql.keyframes.segment_costs import clip_stacked
from sidql.keyframes.single_costs import (
    _CONTRACT,
    _turn_distance,
    single_cost_matrix,
    turn_rates,
    weights_of,
)
from sidql.keyframes.wide_vectors import ATTRIBUTES, wide_vectors


def _has_avx512() -> bool:
    import llvmlite.binding as ll

    return bool(ll.get_host_cpu_features().get("avx512f", False))


@numba.njit
def _scaled(x, s):
    wide_vectors()
    out = np.empty_like(x)
    for k in range(x.shape[0]):
        out[k] = x[k] * s + 1.0
    return out


def test_the_calling_kernel_carries_the_attributes_and_computes_as_without():
    x = np.linspace(-3.0, 3.0, 1001).astype(np.float32)
    np.testing.assert_array_equal(_scaled(x, np.float32(2.5)), x * np.float32(2.5) + 1.0)
    ir = _scaled.inspect_llvm(_scaled.signatures[0])  # the optimised module: LLVM drops
    assert ATTRIBUTES[0] in ir  # min-legal-vector-width once the vectors are chosen


@pytest.mark.skipif(not _has_avx512(), reason="needs a processor with AVX-512")
def test_on_avx512_the_segment_costs_use_512_bit_registers():
    fresh = numba.njit(fastmath=_CONTRACT)(single_cost_matrix.py_func)  # uncached: its assembly
    X = np.zeros((8, 4))
    fresh(X, turn_rates(X), weights_of(8))
    assert "zmm" in fresh.inspect_asm(fresh.signatures[0])


def _default_width_kernel():
    """single_cost_matrix compiled from its own source with wide_vectors a no-op (the default
    vector width), no cache."""

    @numba.njit
    def noop():
        return None

    fn = single_cost_matrix.py_func
    globs = {**fn.__globals__, "wide_vectors": noop}
    plain = types.FunctionType(fn.__code__, globs, fn.__name__, fn.__defaults__, fn.__closure__)
    return numba.njit(fastmath=_CONTRACT)(plain)


def test_the_wide_segment_costs_are_the_default_width_ones_to_the_last_bit(walk_clip):
    plain = _default_width_kernel()
    rng = np.random.default_rng(3)
    X0, R0 = clip_stacked(walk_clip)
    for X, R in (
        (X0, R0),
        (X0[:37], R0[:37]),  # a length whose rows are not whole vectors
        (X0 + rng.normal(0, 2.0, X0.shape), R0 * 3.0),  # wraps around often
        (X0[:, :41], R0[:, :41]),  # channels padded to a multiple of 8, not of 16
    ):
        X, R = np.ascontiguousarray(X), np.ascontiguousarray(R)
        args = (X, turn_rates(R), weights_of(len(X)))
        assert np.array_equal(single_cost_matrix(*args), plain(*args))


def test_the_protocol_width_compiled_as_a_constant_keeps_the_bits_of_the_runtime_width(walk_clip):
    """single_cost_matrix passes the protocol's 48 channels to its loops as a constant; the
    same loops compiled for a width known only at run time give the same numbers."""
    from sidql.keyframes.single_costs import PROTOCOL_LANES, _cost_passes

    rng = np.random.default_rng(5)
    X0, R0 = clip_stacked(walk_clip)
    for X, R in ((X0, R0), (X0 + rng.normal(0, 2.0, X0.shape), R0 * 3.0)):
        X, R = np.ascontiguousarray(X), np.ascontiguousarray(R)
        args = (X, turn_rates(R), weights_of(len(X)))
        assert args[1].shape[1] == PROTOCOL_LANES
        runtime_width = int(np.int64(args[1].shape[1]))  # a plain argument: not a constant
        assert np.array_equal(single_cost_matrix(*args), _cost_passes(*args, runtime_width))


@numba.njit
def _distances(v):
    out = np.empty_like(v)
    for k in range(v.shape[0]):
        out[k] = _turn_distance(v[k])
    return out


def test_the_turn_distance_is_the_add_and_subtract_rounding_it_replaced():
    """|v - rint(v)| in float32 equals |v - ((v + 1.5 2^23) - 1.5 2^23)| (numpy's float32
    arithmetic, the rounding the costs used before) for |v| < 2^22, ties included."""
    rng = np.random.default_rng(7)
    ties = np.arange(-40, 40, dtype=np.float32) + np.float32(0.5)
    v = np.concatenate([
        ties, rng.normal(0, 3, 4000), rng.uniform(-(2.0**22), 2.0**22, 4000),
        [0.0, -0.0, 2.0**22 - 0.5, -(2.0**22) + 0.5, 1e-30, 0.49999997],
    ]).astype(np.float32)  # fmt: skip
    big = np.float32(1.5 * 2**23)
    assert np.array_equal(_distances(v), np.abs(v - ((v + big) - big)))
