"""Selection methods: the interface contract, determinism, greedy against a naive greedy."""

import sys

import numpy as np
import pytest
from keyframe_synth import smooth_clip

from sidql.keyframes import methods
from sidql.keyframes.spherical import chart
from sim.errors import UsageError


@pytest.fixture(scope="module")
def clip():
    return smooth_clip(60, 30.0, seed=21)


@pytest.mark.parametrize("name", ["random", "uniform", "greedy", "optimal", "pitch"])
@pytest.mark.parametrize("W", [2, 3, 5, 15, 60])
def test_every_method_returns_w_sorted_keyframes_with_both_ends(clip, name, W):
    k = methods.select(name, clip, W, seed=3)
    assert k.dtype == np.int64 and k.shape == (W,)
    assert k[0] == 0 and k[-1] == 59 and np.all(np.diff(k) > 0)


def test_random_is_reproducible_by_seed_and_varies_with_it(clip):
    a = methods.select("random", clip, 8, seed=1)
    assert np.array_equal(a, methods.select("random", clip, 8, seed=1))
    assert any(
        not np.array_equal(a, methods.select("random", clip, 8, seed=s)) for s in range(2, 6)
    )


def test_uniform_is_evenly_spaced(clip):
    k = methods.select("uniform", clip, 5)
    assert k.tolist() == [0, 15, 30, 44, 59]  # 59/4 = 14.75 -> 0, 14.75, 29.5, 44.25, 59
    assert np.ptp(np.diff(methods.uniform_indices(61, 7))) == 0


def test_greedy_equals_the_naive_greedy(clip):
    s = chart(clip)
    for W in (3, 6, 9):
        assert np.array_equal(methods.select("greedy", clip, W), methods.naive_greedy(s, W))


def test_register_adds_a_method_and_select_checks_its_output(clip):
    @methods.register("every_other_test")
    def every_other(c, W, *, seed=0):
        return np.arange(W)

    try:
        assert "every_other_test" in methods.available()
        with pytest.raises(UsageError, match="bad keyframes"):
            methods.select("every_other_test", clip, 4)
    finally:
        del methods.METHODS["every_other_test"]
    last = clip.n_frames - 1
    bad = {
        "unsorted": [0, 7, 5, last], "repeated": [0, 5, 5, last], "first not 0": [1, 5, 7, last],
        "too few": [0, 5, last], "too many": [0, 3, 5, 7, last], "two rows": [[0, 5], [7, last]],
        "one number": 0,
    }  # fmt: skip
    for what, keys in bad.items():
        methods.register("bad_test")(lambda c, W, *, seed=0, keys=keys: np.array(keys))
        try:
            with pytest.raises(UsageError, match="bad keyframes"):
                methods.select("bad_test", clip, 4)
                pytest.fail(f"{what} was not caught")
        finally:
            del methods.METHODS["bad_test"]
    methods.register("good_test")(lambda c, W, *, seed=0: np.array([0, 5, 7, last]))
    try:
        assert methods.select("good_test", clip, 4).tolist() == [0, 5, 7, last]
    finally:
        del methods.METHODS["good_test"]


def test_lazy_methods_are_imported_on_demand(clip, tmp_path, monkeypatch):
    (tmp_path / "lazy_kf_method.py").write_text(
        "import numpy as np\n"
        "from sidql.keyframes.methods import register, uniform_indices\n"
        "@register('lazy_test')\n"
        "def f(clip, W, *, seed=0):\n"
        "    return uniform_indices(clip.n_frames, W)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(methods.LAZY_METHODS, "lazy_test", "lazy_kf_method")
    try:
        assert methods.select("lazy_test", clip, 4).tolist() == [0, 20, 39, 59]
    finally:
        methods.METHODS.pop("lazy_test", None)
        sys.modules.pop("lazy_kf_method", None)


def test_unknown_names_and_bad_counts_are_clear_errors(clip):
    with pytest.raises(KeyError, match="known: .*greedy"):
        methods.select("nope", clip, 5)
    for W in (1, 61):
        with pytest.raises(UsageError, match=r"W must be in \[2, 60\]"):
            methods.select("uniform", clip, W)


def test_the_cartesian_baseline_is_named_cartesian_and_its_old_name_warns(clip):
    """Method ``cartesian`` (uniform keyframes for the ``cartesian`` reconstruction); its old
    name ``xyz`` still selects it, with a FutureWarning naming the new one."""
    assert "cartesian" in methods.available() and "xyz" not in methods.available()
    assert methods.reconstruction_of("cartesian") == "cartesian"
    keys = methods.select("cartesian", clip, 5)
    assert keys.tolist() == methods.select("uniform", clip, 5).tolist()
    with pytest.warns(FutureWarning, match="'xyz' is an old name; use 'cartesian'"):
        assert methods.select("xyz", clip, 5).tolist() == keys.tolist()
    with pytest.warns(FutureWarning):
        assert methods.reconstruction_of("xyz") == "cartesian"


def test_lazy_greedy_equals_greedy_over_the_full_cost_matrix():
    from sidql.keyframes.methods import greedy_from_costs
    from sidql.keyframes.segment_costs import greedy_keyframes, segment_cost_matrix

    for seed in range(3):
        s = chart(smooth_clip(40, 30.0, seed=60 + seed))
        for reconstruction in ("hermite", "linear"):
            C = segment_cost_matrix(s, reconstruction)
            for W in (2, 4, 9, 40):
                assert np.array_equal(
                    greedy_keyframes(s, W, reconstruction), greedy_from_costs(C, W)
                )
