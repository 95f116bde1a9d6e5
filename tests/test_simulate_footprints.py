"""Footprints (``sim.simulate.footprints``): a sole down where the reference stands on it pays
its squared horizontal distance from the reference's sole (by hand), the reference itself and
a sole in the air or lifted by the reference pay nothing, the landing variant pays once per
touch-down, terrain boxes are the support under a sole; in the sampler, the term weighted 0
(or too little to move a sum) is today's search bit for bit, and weighted it is another,
deterministic search, also where the gains are chosen per window."""

from __future__ import annotations

import numpy as np
import pytest
from sole_tracks import reference_sole_boxes, still_soles

from sim.model.humanoid import canonical_skeleton
from sim.simulate.footholding import reference_soles, sole_ids
from sim.simulate.footprints import footprint_cost, sole_costs, window_footprint_costs
from sim.simulate.gainchoice import GainChoice, choice_search, common_body
from sim.simulate.model import Gains, sim_model
from sim.simulate.reference import contact_consistent
from sim.simulate.sampling import CostWeights, search_offsets
from sim.simulate.terrain import Box, boxes_terrain

SIZE = np.array([[0.045, 0.13, 0.01], [0.045, 0.13, 0.01]])  # sole half sizes [m]


@pytest.fixture(scope="module")
def model():
    return sim_model(canonical_skeleton())


def test_a_sole_down_off_the_reference_s_pays_its_squared_distance():
    K = 12
    ref = still_soles(K)
    both = np.ones((K, 2), dtype=bool)
    assert footprint_cost(ref, ref, both, both) == 0.0  # the reference itself
    off = ref.copy()
    off[:, 0, 0] += 0.1  # the left sole 10 cm in front of the reference's
    off[:, 1, 1] += 0.2  # the right 20 cm to the side
    assert footprint_cost(off, ref, both, both) == pytest.approx(0.01 + 0.04, rel=1e-12)
    half = both.copy()
    half[6:, 1] = False  # the right sole in the air on the last 6 ticks
    assert footprint_cost(off, ref, both, half) == pytest.approx(0.01 + 0.02, rel=1e-12)
    lifted = both.copy()
    lifted[:, 0] = False  # the reference lifts its left foot: the left sole pays nothing
    assert footprint_cost(off, ref, lifted, both) == pytest.approx(0.04, rel=1e-12)
    assert footprint_cost(off, ref, both, ~both) == 0.0  # both in the air


def test_the_landing_variant_pays_once_per_touch_down():
    K = 12
    ref = still_soles(K)
    off = ref.copy()
    off[:, 0, 0] += 0.1 * np.arange(1, K + 1)  # the left sole 0.1 m further each tick
    stance = np.ones((K, 2), dtype=bool)
    touch = np.zeros((K, 2), dtype=bool)
    touch[4:, 0] = True  # the left sole lands at tick 4 (0.5 m off) and stays down
    assert footprint_cost(off, ref, stance, touch, landing=True) == pytest.approx(0.25)
    # averaged over the window's ticks instead: (0.5^2 + ... + 1.2^2) / 12
    by_hand = sum((0.1 * k) ** 2 for k in range(5, K + 1)) / K
    assert footprint_cost(off, ref, stance, touch) == pytest.approx(by_hand, rel=1e-12)
    down = np.ones((K, 2), dtype=bool)
    before = np.array([True, True])
    assert footprint_cost(off, ref, stance, down, landing=True, before=before) == 0.0  # down before
    # the reference puts its foot down at tick 7 under a sole already there: it counts from then
    late = stance.copy()
    late[:7, 0] = False
    assert footprint_cost(off, ref, late, down, True, before) == pytest.approx(0.8**2)


def test_many_motions_at_once_cost_what_each_costs_alone():
    rng = np.random.default_rng(0)
    S, K = 4, 9
    sim = rng.normal(size=(S, K, 2, 2))
    ref = rng.normal(size=(K, 2, 2))
    stance = rng.random((K, 2)) < 0.7
    touch = rng.random((S, K, 2)) < 0.6
    before = rng.random((S, 2)) < 0.5
    for landing in (False, True):
        many = footprint_cost(sim, ref, stance, touch, landing, before)
        one = [footprint_cost(sim[s], ref, stance, touch[s], landing, before[s]) for s in range(S)]
        np.testing.assert_allclose(many, one, rtol=1e-12)


def _records(S: int, K: int, lift: float = 0.0) -> tuple:
    """Flat soles 0.3 m apart at rest, their bottoms ``lift`` [m] above z = 0, at K + 1 instants
    (the window's start and its K ticks): positions, orientations, centre of mass."""
    pos = np.zeros((S, K + 1, 2, 3))
    pos[..., 1, 1] = 0.3
    pos[..., 2] = 0.01 + lift
    mat = np.broadcast_to(np.eye(3).reshape(9), (S, K + 1, 2, 9)).copy()
    return pos, mat, np.zeros((S, K + 1, 3))


def test_a_window_counts_soles_on_the_floor_or_on_a_box():
    S, K = 2, 12
    pos, mat, com = _records(S, K)
    pos[1, :, 0, 0] += 0.1  # the second rollout's left sole 10 cm off
    ref = (still_soles(K + 1), np.ones((K + 1, 2), dtype=bool))
    got = window_footprint_costs((pos, mat), SIZE, ref, None, False)
    np.testing.assert_allclose(got, [0.0, 0.01], atol=1e-15)
    up = _records(S, K, lift=0.3)[0]
    up[1, :, 0, 0] += 0.1
    assert not window_footprint_costs((up, mat), SIZE, ref, None, False).any()  # in the air
    # a 0.3 m box under the left sole: it stands there
    box = Box(centre=np.array([0.0, 0.0, 0.15]), half=np.array([0.3, 0.1, 0.15]), yaw=0.0)
    terrain = boxes_terrain([box])
    np.testing.assert_allclose(
        window_footprint_costs((up, mat), SIZE, ref, terrain, False), [0.0, 0.01], atol=1e-15
    )
    stopped = pos.copy()
    stopped[1, 5:] = np.nan  # the rollout stopped after 4 ticks: 4 of 12 count
    got = window_footprint_costs((stopped, mat), SIZE, ref, None, False)
    np.testing.assert_allclose(got, [0.0, 0.01 * 4 / 12], atol=1e-15)
    # landing: the sole was down at the window's start, so no touch-down in the window
    np.testing.assert_allclose(window_footprint_costs((pos, mat), SIZE, ref, None, True), 0.0)


def test_the_reference_s_own_soles_cost_nothing_and_a_shift_costs_its_square(trial_on_floor, model):
    ref_qpos = contact_consistent(model, trial_on_floor(model, "07_01")[:37])
    ids = sole_ids(model)
    pos, mat = reference_sole_boxes(model, ref_qpos, ids)
    ref = reference_soles(model, ref_qpos, ids)
    size = model.geom_size[ids]
    assert window_footprint_costs((pos, mat), size, ref, None, False)[0] == 0.0
    moved = pos + np.array([0.03, 0.04, 0.0])  # the whole body 5 cm off
    low = pos[0, 1:, :, 2] - np.sum(np.abs(mat[0, 1:, :, 6:9]) * size, axis=-1)
    counted = (low <= 0.01) & ref[1][1:]
    assert counted.any()  # the walk stands on its soles
    want = 0.05**2 * counted.sum() / (len(ref_qpos) - 1)
    got = window_footprint_costs((moved, mat), size, ref, None, False)[0]
    assert got == pytest.approx(want, rel=1e-9)


def test_sole_costs_weigh_the_footprints_and_nothing_else_where_hold_is_off(model):
    K = 12
    pos, mat, com = _records(3, K)
    pos[1:, :, 0, 0] += 0.1
    ids = sole_ids(model)

    class Prob:  # what sole_costs reads of sampling._Problem
        base = np.zeros((40, 1))
        soles = slice(int(ids[0]), int(ids[1]) + 1, int(ids[1] - ids[0]))
        ref_soles = (still_soles(40), np.ones((40, 2), dtype=bool), np.ones(40, dtype=bool))

    got = sole_costs(model, Prob, CostWeights(footprint=30.0), (8, 8 + K), (pos, mat, com))
    np.testing.assert_allclose(got, [0.0, 0.3, 0.3], atol=1e-12)


#: each sole term (``footprints.sole_costs``) at a weight that moves the search
SOLE_TERMS = [("footprint", 2000.0), ("clearance", 1e5), ("pivot", 10.0)]


@pytest.mark.parametrize(("term", "heavy"), SOLE_TERMS)
def test_the_sampler_with_a_sole_term_off_is_today_s_search_bit_for_bit(
    trial_on_floor, model, term, heavy
):
    ref = trial_on_floor(model, "07_01")[:48]
    kw = dict(samples=6, keep=2, window=12, lookahead=12, seed=4)
    base, rb = search_offsets(model, ref, **kw)
    # soles recorded (their kinematics at each rollout's start too), the term too small to move
    # a sum: the same rollouts, the same choices
    tiny, rt = search_offsets(model, ref, weights=CostWeights(**{term: 1e-300}), **kw)
    np.testing.assert_array_equal(tiny, base)
    np.testing.assert_array_equal(rt, rb)
    a, ra = search_offsets(model, ref, weights=CostWeights(**{term: heavy}), **kw)
    b, _ = search_offsets(model, ref, weights=CostWeights(**{term: heavy}), **kw)
    np.testing.assert_array_equal(a, b)  # deterministic
    assert not np.array_equal(a, base)  # the term changes which candidates are kept


@pytest.mark.parametrize(("term", "heavy"), SOLE_TERMS)
def test_the_gain_choosing_sampler_costs_every_sole_term_too(trial_on_floor, term, heavy):
    sk = canonical_skeleton()
    models = common_body([sim_model(sk), sim_model(sk, gains=Gains(min_deflection=0.1))])
    ref = trial_on_floor(models[0], "07_01")[:48]
    kw = dict(samples=6, keep=2, window=12, lookahead=12, seed=4, choice=GainChoice(share=0.5))
    base = choice_search(models, ref, **kw)
    tiny = choice_search(models, ref, weights=CostWeights(**{term: 1e-300}), **kw)
    for x, y in zip(base, tiny, strict=True):
        np.testing.assert_array_equal(x, y)
    heavy_search = choice_search(models, ref, weights=CostWeights(**{term: heavy}), **kw)
    assert not np.array_equal(heavy_search[0], base[0])


def test_the_sampler_looking_at_the_lookahead_s_footprints_is_another_search(trial_on_floor, model):
    ref = trial_on_floor(model, "07_01")[:48]
    kw = dict(samples=6, keep=2, window=12, lookahead=12, seed=4)
    base, rb = search_offsets(model, ref, **kw)
    look = dict(footprint_lookahead=True)
    tiny, rt = search_offsets(model, ref, weights=CostWeights(footprint=1e-300, **look), **kw)
    np.testing.assert_array_equal(tiny, base)
    np.testing.assert_array_equal(rt, rb)
    a, _ = search_offsets(model, ref, weights=CostWeights(footprint=2000.0, **look), **kw)
    w, _ = search_offsets(model, ref, weights=CostWeights(footprint=2000.0), **kw)
    assert not np.array_equal(a, base) and not np.array_equal(a, w)
