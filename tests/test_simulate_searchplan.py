"""How the gain-choosing sampler spends its rollouts (``sim.simulate.searchplan``): a recovery
backs up and searches again only within its budget, and the replay still passes through the
states its rollouts reached; a staged window rolls out the rest of its candidates only where one
of the first fell; the window-end cost is the tracking cost of the state kept; narrow candidates
are exactly their share, drawn at random, or a window's first stage, and search with their noise
narrowed; every option is deterministic whatever the number of threads."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import sim.simulate.gainchoice as gainchoice
from sim.errors import UsageError
from sim.model.humanoid import canonical_skeleton
from sim.simulate.controller import track
from sim.simulate.gainchoice import GainChoice, choice_search, common_body
from sim.simulate.model import Gains, sim_model
from sim.simulate.sampling import BALANCE, CostWeights, _problem
from sim.simulate.searchplan import SearchPlan, narrowed, window_end_costs

STIFF = Gains(min_deflection=0.1, omega=2 * np.pi * 12.0)
#: every candidate of every window counts as fallen (its cost is never below this)
ALWAYS_FALLEN = CostWeights(fall=1e-9)
SEARCH = dict(samples=6, keep=2, seed=3, choice=GainChoice(share=0.5))


@pytest.fixture(scope="module")
def bodies():
    """The canonical body with the default gains and the stiff ones (one body)."""
    sk = canonical_skeleton()
    return common_body([sim_model(sk), sim_model(sk, gains=STIFF)])


@pytest.fixture(scope="module")
def walk(trial_on_floor, bodies):
    """0.8 s of the walk 07_01 on the canonical body, on the floor (120 Hz): 8 windows."""
    return trial_on_floor(bodies[0], "07_01")[:96]


@pytest.fixture
def rollouts(monkeypatch):
    """A list that gets the number of candidates of every batch of rollouts the search runs."""
    seen = []
    real = gainchoice._costs

    def counting(models, datas, probs, search, parents, offs, *rest):
        seen.append(len(offs))
        return real(models, datas, probs, search, parents, offs, *rest)

    monkeypatch.setattr(gainchoice, "_costs", counting)
    return seen


def test_the_plan_refuses_values_it_cannot_use():
    for bad in ({"recover": -1}, {"boost": 0.5}, {"extra": -0.1}, {"end_cost": -1.0}):
        with pytest.raises(UsageError, match="SearchPlan"):
            SearchPlan(**bad)
    for first in (0.0, 1.5):
        with pytest.raises(UsageError, match="first"):
            SearchPlan(first=first)


def test_a_recovery_the_budget_cannot_hold_changes_nothing(bodies, walk, rollouts):
    plain = choice_search(bodies, walk, weights=ALWAYS_FALLEN, **SEARCH)
    assert sum(rollouts) == 6 * 8  # 6 candidates in each of the 8 windows
    rollouts.clear()
    plan = SearchPlan(recover=1, extra=0.0)
    got = choice_search(bodies, walk, weights=ALWAYS_FALLEN, plan=plan, **SEARCH)
    assert sum(rollouts) == 6 * 8
    for a, b in zip(got, plain, strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_recovery_backs_up_within_its_budget_and_the_replay_meets_its_states(
    bodies, walk, rollouts
):
    plan = SearchPlan(recover=1, boost=2.0, extra=0.5)
    off, sets, reached = choice_search(bodies, walk, weights=ALWAYS_FALLEN, plan=plan, **SEARCH)
    # budget 1.5 x 6 x 8 = 72: window 0 falls (6), is searched again with 12 (its recovery
    # needs 12 + 7 x 6 = 54 more: 60 <= 72); every later window's recovery would pass 72
    assert sum(rollouts) == 6 + 12 + 7 * 6
    r = track(bodies[0], walk, assist_limit=0.0, offsets=off, record_every=1, balance=BALANCE,
              switch=(bodies, sets))  # fmt: skip
    assert not r.fell
    np.testing.assert_array_equal(r.qpos[12::12], reached[:-1])  # the very states
    lim = bodies[0].actuator_forcerange[:, 1]
    assert np.all(np.abs(r.joint_torque) <= lim * (1 + 1e-9))  # human strength


def test_a_staged_window_rolls_out_the_rest_only_where_one_of_the_first_fell(
    bodies, walk, rollouts
):
    plan = SearchPlan(first=0.5)
    search = {**SEARCH, "samples": 8}
    choice_search(bodies, walk, weights=ALWAYS_FALLEN, plan=plan, **search)
    assert rollouts == [4, 4] * 8  # every window hard: all 8, in two stages
    rollouts.clear()
    choice_search(bodies, walk, weights=CostWeights(fall=0.0), plan=plan, **search)
    assert rollouts == [4] * 8  # no fall looked for: every window easy


def test_every_plan_gives_the_same_search_on_any_number_of_threads(bodies, walk):
    plan = SearchPlan(recover=1, extra=0.5, first=0.5, end_cost=1.0, adapt=0.5)
    kw = dict(SEARCH, samples=8, weights=ALWAYS_FALLEN, plan=plan)
    one = choice_search(bodies, walk, threads=1, **kw)
    two = choice_search(bodies, walk, threads=3, **kw)
    for a, b in zip(one, two, strict=True):
        np.testing.assert_array_equal(a, b)
    other = choice_search(bodies, walk, threads=1, **{**kw, "plan": SearchPlan()})
    assert not np.array_equal(one[0], other[0])  # the plan does change the search


def test_the_window_end_cost_is_the_tracking_cost_of_the_state_kept(bodies, walk):
    model = bodies[0]
    data = mujoco.MjData(model)
    prob = _problem(model, walk, data, 0.3, ())
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    k1, dz = 24, 0.02
    states = np.empty((2, mujoco.mj_stateSize(model, spec)))
    for s, lift in enumerate((0.0, dz)):  # the reference's own state, and it lifted by dz
        mujoco.mj_resetData(model, data)
        data.qpos[:], data.qvel[:] = walk[k1], prob.ref_qvel[k1]
        data.qpos[2] += lift
        mujoco.mj_getState(model, data, states[s], spec)
    w = CostWeights()
    got = window_end_costs(model, data, prob, states, spec, k1, w, np.zeros(2))
    # a lift moves the root alone: end effectors, balance and velocity relative to it unchanged
    np.testing.assert_allclose(got, [0.0, w.height * dz**2], atol=1e-12)
    diverged = window_end_costs(model, data, prob, states, spec, k1, w, np.full(2, 1e15))
    np.testing.assert_array_equal(diverged, [0.0, 0.0])


def test_the_noise_widens_where_the_kept_took_larger_steps_and_narrows_where_smaller():
    from sim.simulate.searchplan import SCALE_RANGE, adapted_scale

    scale = np.array([1.0, 1.0, 1.0, 2.0])
    kept = np.array([[2.0, 0.5, 1.0, 0.0], [-2.0, -0.5, -1.0, 0.0]])  # mean squares 4, 1/4, 1, 0
    got = adapted_scale(scale, kept, 0.5)
    np.testing.assert_allclose(got, scale * np.exp(0.25 * np.array([3.0, -0.75, 0.0, -1.0])))
    np.testing.assert_array_equal(adapted_scale(scale, kept, 0.0), scale)  # off
    assert adapted_scale(np.full(4, 3.9), np.full((2, 4), 10.0), 1.0).max() == SCALE_RANGE[1]


def test_narrowed_draws_exactly_its_share_at_random_and_nothing_where_off():
    rng = np.random.default_rng(5)
    factor = narrowed(SearchPlan(narrow=0.5, narrow_share=0.25), rng, 8)
    assert factor.shape == (8, 1)
    assert sorted(factor[:, 0]) == [0.5, 0.5] + [1.0] * 6  # round(0.25 * 8) narrow
    picks = {tuple(narrowed(SearchPlan(narrow=0.5, narrow_share=0.25), rng, 8)[:, 0])
             for _ in range(20)}  # fmt: skip
    assert len(picks) > 1  # chosen at random, not always the same candidates
    for off in (SearchPlan(), SearchPlan(narrow=0.5), SearchPlan(narrow=1.0, narrow_share=0.5)):
        before = rng.bit_generator.state
        assert narrowed(off, rng, 8) is None
        assert rng.bit_generator.state == before  # the default's draws untouched
    for bad in ({"narrow": 0.0}, {"narrow_share": -0.1}, {"narrow_share": 1.5}):
        with pytest.raises(UsageError, match="narrow"):
            SearchPlan(**bad)


def test_narrow_candidates_search_with_their_noise_narrowed(bodies, walk):
    default = choice_search(bodies, walk, **SEARCH)
    off = choice_search(bodies, walk, plan=SearchPlan(narrow=1.0, narrow_share=0.5), **SEARCH)
    for a, b in zip(default, off, strict=True):
        np.testing.assert_array_equal(a, b)  # a factor of 1: the search bit for bit
    tiny = choice_search(bodies, walk, plan=SearchPlan(narrow=1e-9, narrow_share=1.0), **SEARCH)
    assert np.abs(default[0]).max() > 1e-2
    assert np.abs(tiny[0]).max() < 1e-6  # every candidate's noise 1e-9 times: no offset grows
    half = choice_search(bodies, walk, plan=SearchPlan(narrow=1e-9, narrow_share=0.5), **SEARCH)
    assert not np.array_equal(half[0], default[0])


def test_narrow_first_narrows_the_first_stage_and_widens_where_one_of_it_fell(bodies, walk):
    rng = np.random.default_rng(5)
    plan = SearchPlan(first=0.5, narrow=1e-9, narrow_first=True)
    before = rng.bit_generator.state
    np.testing.assert_array_equal(narrowed(plan, rng, 4), np.full((4, 1), 1e-9))
    assert narrowed(plan, rng, 4, first=False) is None  # the rest at full noise
    assert rng.bit_generator.state == before
    easy = choice_search(bodies, walk, plan=plan, weights=CostWeights(fall=0.0), **SEARCH)
    assert np.abs(easy[0]).max() < 1e-6  # no fall looked for: the first stage alone, narrow
    hard = choice_search(bodies, walk, plan=plan, weights=ALWAYS_FALLEN, **SEARCH)
    assert np.abs(hard[0]).max() > 1e-2  # every window hard: the wide rest kept too
