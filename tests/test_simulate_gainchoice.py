"""The sampler choosing its feedback gains per window (``sim.simulate.gainchoice``): with no
share on the other gains it is the sampler bit for bit; the replay passes through the states
its rollouts reached, gains switching included; a window whose candidates all fall on the
other gains is tried again on the default ones and the replay uses them; the torques stay
within the human limits; the gains never change the body (masses, armature, limits)."""

from __future__ import annotations

import numpy as np
import pytest

from sim.errors import UsageError
from sim.model.humanoid import canonical_skeleton
from sim.simulate.controller import track
from sim.simulate.gainchoice import GainChoice, choice_search, choice_track, common_body
from sim.simulate.model import Gains, sim_model
from sim.simulate.sampling import BALANCE, search_offsets

STIFF = Gains(min_deflection=0.1, omega=2 * np.pi * 12.0)


@pytest.fixture(scope="module")
def bodies():
    """The canonical body with the default gains, the stiff ones, and a controller that cannot
    stand (its damping turned into anti-damping: it pushes every joint along its velocity)."""
    sk = canonical_skeleton()
    wild = sim_model(sk)
    wild.actuator_biasprm[:, 2] *= -1.0
    return common_body([sim_model(sk), sim_model(sk, gains=STIFF), wild])


@pytest.fixture(scope="module")
def walk(trial_on_floor, bodies):
    """0.8 s of the walk 07_01 on the canonical body, on the floor (120 Hz)."""
    return trial_on_floor(bodies[0], "07_01")[:96]


def test_the_gain_sets_share_one_body():
    sk = canonical_skeleton()
    default, stiff = sim_model(sk), sim_model(sk, gains=STIFF)
    assert (stiff.dof_armature > default.dof_armature).any()  # sim_spec raises it with kp
    a, b = common_body([default, stiff])
    np.testing.assert_array_equal(a.dof_armature, b.dof_armature)
    np.testing.assert_array_equal(a.dof_invweight0, b.dof_invweight0)  # recomputed from it
    np.testing.assert_array_equal(a.actuator_forcerange, b.actuator_forcerange)  # anatomy
    assert (b.actuator_gainprm[:, 0] > a.actuator_gainprm[:, 0]).any()  # only the gains differ
    heavy = sim_model(sk, body_mass_kg=90.0)
    with pytest.raises(UsageError, match="one body"):
        common_body([sim_model(sk), heavy])
    with pytest.raises(UsageError, match="share"):
        GainChoice(share=1.5)


def test_no_share_on_other_gains_is_the_sampler_bit_for_bit(bodies, walk):
    default, stiff, _ = bodies
    off, reached = search_offsets(default, walk, samples=6, keep=2, seed=3)
    got, sets, got_reached = choice_search(
        (default, stiff), walk, samples=6, keep=2, seed=3, choice=GainChoice(share=0.0)
    )
    np.testing.assert_array_equal(got, off)
    np.testing.assert_array_equal(got_reached, reached)
    assert not sets.any()


def test_mixed_gains_are_chosen_and_replayed_through_the_rolled_out_states(bodies, walk):
    default, stiff, _ = bodies
    kw = dict(samples=6, keep=2, seed=3, choice=GainChoice(share=0.5))
    off, sets, reached = choice_search((default, stiff), walk, **kw)
    assert set(np.unique(sets)) == {0, 1}  # both gain sets won some window (measured 4 of 8)
    assert np.all(sets.reshape(-1, 12) == sets[::12, None])  # one set per window
    r = track(default, walk, assist_limit=0.0, offsets=off, record_every=1, balance=BALANCE,
              switch=((default, stiff), sets))  # fmt: skip
    assert not r.fell
    np.testing.assert_array_equal(r.qpos[12::12], reached[:-1])  # the very states, bit for bit
    lim = default.actuator_forcerange[:, 1]
    assert np.all(np.abs(r.joint_torque) <= lim * (1 + 1e-9))  # human strength, any gains
    again = choice_track(default, walk, alternates=(stiff,), record_every=1, threads=2, **kw)
    np.testing.assert_array_equal(again.qpos, r.qpos)  # deterministic, any number of threads


def test_windows_whose_candidates_all_fall_fall_back_on_the_default_gains(bodies, walk):
    default, _, wild = bodies
    models = (default, wild)
    only = choice_track(default, walk, alternates=(wild,), samples=6, keep=2, seed=3,
                        choice=GainChoice(share=1.0))  # fmt: skip
    assert only.fell or only.unstable  # no candidate on the wild gains stays up
    off, sets, reached = choice_search(
        models, walk, samples=6, keep=2, seed=3, choice=GainChoice(share=1.0, fallback=True)
    )
    assert not sets.any()  # every window fell back on the default gains
    r = choice_track(default, walk, alternates=(wild,), samples=6, keep=2, seed=3,
                     choice=GainChoice(share=1.0, fallback=True), record_every=1)  # fmt: skip
    assert not r.fell and not r.unstable
    np.testing.assert_array_equal(r.qpos[12::12], reached[:-1])
    lim = default.actuator_forcerange[:, 1]
    assert np.all(np.abs(r.joint_torque) <= lim * (1 + 1e-9))


def test_forward_validation_chooses_gains_where_its_search_names_alternates(
    bodies, walk, monkeypatch
):
    import sim.simulate.validate as validate

    default, stiff, _ = bodies
    seen = []
    real = validate.choice_track

    def spy(model, ref, **kw):
        seen.append(kw["alternates"])
        return real(model, ref, **kw)

    monkeypatch.setattr(validate, "choice_track", spy)
    search = {"alternates": (stiff,), "choice": GainChoice(share=0.5)}
    row = validate.ForwardValidation(default, ("root",), samples=2, search=search).run(
        walk[::4][:8], 30.0
    )
    validate.ForwardValidation(default, ("root",), samples=2).run(walk[::4][:8], 30.0)
    assert seen == [(stiff,)] and row["sim_fell"] == 0  # the plain sampler without them


def test_eval_default_body_chooses_between_its_gains_and_the_stiff_ones():
    from sim.simulate.validate import DEFAULT_GAIN_CHOICE, STIFF_GAINS, forward_validation

    sk = canonical_skeleton()
    fv = forward_validation(sk, ("root",))
    (stiff,) = fv.search["alternates"]
    assert fv.search["choice"] == DEFAULT_GAIN_CHOICE and DEFAULT_GAIN_CHOICE.share == 0.5
    want = sim_model(sk, gains=STIFF_GAINS, lean=True)
    np.testing.assert_array_equal(stiff.actuator_gainprm, want.actuator_gainprm)
    np.testing.assert_array_equal(fv.model.dof_armature, stiff.dof_armature)  # one body
    np.testing.assert_array_equal(fv.model.actuator_forcerange, want.actuator_forcerange)
    assert forward_validation(sk, ("root",), gain_choice=None).search == {}
    assert forward_validation(sk, ("root",), controller="plain").search == {}
    assert forward_validation(sk, ("root",), gain_choice=GainChoice(share=0.0)).search == {}
