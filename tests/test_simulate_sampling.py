"""The sampling tracker (``sim.simulate.sampling``): it keeps a walk up where the plain tracker
falls, with no assistance; it is deterministic given its seed; with no noise it is the plain
tracker."""

from __future__ import annotations

import numpy as np
import pytest

from sim.model.humanoid import canonical_skeleton
from sim.simulate.controller import Push, Weakening, track
from sim.simulate.model import sim_model
from sim.simulate.sampling import BALANCE, sample_track, search_offsets


@pytest.fixture(scope="module")
def model():
    return sim_model(canonical_skeleton())


@pytest.fixture(scope="module")
def walk_ref(trial_on_floor, model):
    """2 s of the walk 07_01 on the canonical body, on the floor (120 Hz)."""
    return trial_on_floor(model, "07_01")[:240]


def test_sampling_keeps_a_walk_up_where_the_plain_tracker_falls(model, walk_ref):
    plain = track(model, walk_ref, assist_limit=0.0)
    assert plain.fell  # the reason the sampler exists: without help the plain tracker falls
    r = sample_track(model, walk_ref, samples=64, keep=8)
    assert not r.fell and not r.unstable
    assert r.assistance.max() == 0.0 and r.mean_assistance_all == 0.0  # no hidden hand
    root_err = np.abs(r.qpos[:, :3] - walk_ref[::4, :3]).max()
    assert root_err < 1.0  # measured 0.80 m (the plain tracker: 1.2 m; no lookahead: 0.28)
    assert root_err < np.abs(plain.qpos[:, :3] - walk_ref[::4, :3]).max()
    # the torques stay within the human limits: the actuators clamp them
    lim = model.actuator_forcerange[:, 1]
    assert np.all(np.abs(r.joint_torque) <= lim * (1 + 1e-9))


def test_same_seed_same_result_other_seed_another(model, walk_ref):
    ref = walk_ref[:60]
    a = sample_track(model, ref, samples=6, keep=2, seed=1)
    b = sample_track(model, ref, samples=6, keep=2, seed=1)
    c = sample_track(model, ref, samples=6, keep=2, seed=2)
    assert np.array_equal(a.qpos, b.qpos) and np.array_equal(a.actions, b.actions)
    assert not np.array_equal(a.qpos, c.qpos)


def test_without_noise_it_is_the_plain_tracker(model, walk_ref):
    """With no noise the sampler is the plain tracker: without its balance feedback the bare
    one, with it ``track(balance=...)``, bit for bit."""
    ref = walk_ref[:60]
    r = sample_track(model, ref, samples=2, keep=1, torque_sigma=0.0, balance=None)
    p = track(model, ref, assist_limit=0.0)
    assert np.array_equal(r.qpos, p.qpos) and np.array_equal(r.joint_torque, p.joint_torque)
    r = sample_track(model, ref, samples=2, keep=1, torque_sigma=0.0)
    b = track(model, ref, assist_limit=0.0, balance=BALANCE)
    assert np.array_equal(r.qpos, b.qpos) and not np.array_equal(b.qpos, p.qpos)


def test_replay_reaches_the_rolled_out_states_under_pushes_and_a_weakening(model, walk_ref):
    """The rollouts meet the same pushes and weakening as the replay: ``track`` with the found
    offsets passes through the very states the search reached at each window's end (not the
    states its lookahead reached)."""
    ref = walk_ref[:72]
    pushes = (Push("thorax", 0.1, 0.15, (150.0, -80.0, 0.0)),)
    weakenings = (Weakening(0.2, 0.2, 0.5),)
    kw = dict(pushes=pushes, weakenings=weakenings)
    offsets, reached = search_offsets(
        model, ref, samples=6, keep=2, window=12, lookahead=12, seed=3, **kw
    )
    r = track(model, ref, assist_limit=0.0, offsets=offsets, record_every=1, balance=BALANCE, **kw)
    assert not r.fell
    np.testing.assert_allclose(r.qpos[12::12], reached[:-1], rtol=0, atol=1e-9)
    # a search blind to the perturbations would have reached other states
    _, blind = search_offsets(model, ref, samples=6, keep=2, window=12, seed=3)
    assert np.abs(blind[:-1] - r.qpos[12::12]).max() > 1e-3
    gain = model.actuator_gainprm[:, 0].copy()
    sample_track(model, ref[:24], samples=2, keep=1, **kw)
    assert np.array_equal(model.actuator_gainprm[:, 0], gain)  # the weakening was undone


def test_forward_validation_carries_its_sampling_to_other_processes(model):
    import pickle

    from sim.simulate.validate import ForwardValidation

    fv = pickle.loads(pickle.dumps(ForwardValidation(model, ("root",), samples=8)))
    assert fv.samples == 8 and fv.names == ("root",)
    plain = ForwardValidation(model, ("root",), controller="plain")
    assert pickle.loads(pickle.dumps(plain)).samples == 0


def test_eval_samples_needs_simulate_and_a_positive_count(tmp_path, capsys):
    from sidql.commands import main as cli

    out = str(tmp_path / "r.json")
    argv = ["eval", "--data", str(tmp_path), "--physics", "--samples", "8", "--out", out]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["sidql eval: error: --samples needs --simulate"]
    for old in ("--samples", "--simulate-samples"):  # the old spelling is checked the same way
        with pytest.raises(SystemExit) as e:
            cli.main(["eval", "--data", str(tmp_path), old, "0", "--out", out])
        assert e.value.code == 2


def test_eval_threads_reach_the_simulated_bodies_and_need_simulate(tmp_path, capsys, cmu_dir):
    import pickle

    from sidql.commands import main as cli
    from sidql.evaluation.cases import load_cases
    from sidql.evaluation.trial_physics import simulate_setup

    out = str(tmp_path / "r.json")
    assert cli.main(["eval", "--data", str(tmp_path), "--threads", "2", "--out", out]) == 2
    assert capsys.readouterr().err.strip() == "sidql eval: error: --threads needs --simulate"
    cases = load_cases(cmu_dir, progress=False)[0][:1]
    (body,) = simulate_setup(cases, threads=2).values()
    assert body.threads == 2 and pickle.loads(pickle.dumps(body)).threads == 2  # to workers


def test_synth_with_samples_tracks_real_kinds_without_any_help(cmu_dir):
    """``synth --samples``: real-motion clips come from the sampler with no assistance at all
    (physical by construction, the sampler's seed recorded); procedural keeps its tracker."""
    from dataclasses import replace

    from sim.simulate.generate import SynthTask, generate

    amc, asf = str(cmu_dir / "07" / "07_01.amc"), str(cmu_dir / "07" / "07.asf")
    task = SynthTask("fall", seed=0, index=1, asf=asf, amc=amc, seconds=0.5, samples=4)
    clip, rec = generate(task)
    g = rec["generation"]
    assert g["assist_limit"] == 0.0 and g["sampling"]["samples"] == 4
    assert rec["physical"] and rec["mean_assistance"] == 0.0
    assert not rec["labels"]["sim_assist_wrench"].any()
    again, rec2 = generate(task)
    assert np.array_equal(clip.qpos, again.qpos) and rec2["generation"] == g
    plain, rec3 = generate(replace(task, samples=0, controller="plain"))  # no help either
    assert "sampling" not in rec3["generation"] and rec3["generation"]["assist_limit"] == 0
    assert rec3["generation"]["controller"] == "plain" and g["controller"] == "sampling"
    proc = generate(SynthTask("procedural", seed=0, index=2, seconds=0.5, samples=4))[1]
    assert "sampling" not in proc["generation"] and proc["generation"]["assist_limit"] == 1.0


def test_synth_samples_must_be_positive(tmp_path):
    from sidql.commands import main as cli

    with pytest.raises(SystemExit) as e:
        cli.main(["synth", "--kinds", "procedural", "--n", "1", "--out", str(tmp_path / "o"),
                  "--samples", "0"])  # fmt: skip
    assert e.value.code == 2


def test_threads_give_the_same_search_as_one_thread(model, walk_ref):
    """Every rollout starts from a full MuJoCo state on its thread's own ``MjData``: the offsets
    and the states reached do not depend on how many threads ran them."""
    ref = walk_ref[:48]
    one = search_offsets(model, ref, samples=6, keep=2, lookahead=12, seed=4)
    for threads in (2, 4):
        many = search_offsets(model, ref, samples=6, keep=2, lookahead=12, seed=4, threads=threads)
        assert np.array_equal(one[0], many[0]) and np.array_equal(one[1], many[1])


def test_a_rollout_stops_where_the_plain_tracker_falls(model, walk_ref):
    """The search sees the falls ``sim.simulate.falls`` defines: with no offset, a rollout from
    the start reports a fall within a tick of where ``track`` finds it, and stops there."""
    import mujoco

    from sim.simulate.sampling import _problem, _rollout

    plain = track(model, walk_ref, assist_limit=0.0, record_every=1)
    assert plain.fell
    data = mujoco.MjData(model)
    prob = _problem(model, walk_ref, data, 0.3, ())
    mujoco.mj_resetData(model, data)
    data.qpos[:], data.qvel[:] = walk_ref[0], prob.ref_qvel[0]
    mujoco.mj_forward(model, data)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    keep = np.empty(mujoco.mj_stateSize(model, spec)), np.empty(model.nq), spec, None
    end = _rollout(model, data, prob, np.zeros(model.nu), (0, 12, len(walk_ref)), ((), ()), keep)
    assert end < 0 and abs(-end - plain.fall_tick) <= 1
    assert data.time == pytest.approx(-end * 4 * model.opt.timestep)  # stopped at the fall


def test_forward_validation_carries_its_search_and_threads_to_other_processes(model):
    import pickle

    from sim.simulate.sampling import CostWeights
    from sim.simulate.validate import DEFAULT_SAMPLES, ForwardValidation

    search = {"lookahead": 24, "weights": CostWeights(fall=0.0)}
    fv = ForwardValidation(model, ("root",), samples=8, search=search, threads=3)
    again = pickle.loads(pickle.dumps(fv))
    assert again.search == search and again.threads == 3 and again.samples == 8
    chosen = ForwardValidation(model, ("root",), controller="sampling")  # no count given
    assert chosen.samples == DEFAULT_SAMPLES > 0


def test_recentred_search_is_deterministic_and_another_search(model, walk_ref):
    """``recentre``: children start between their parent's offset and the cheapest kept
    state's, so the search takes another path than from the parents alone (same seed), and
    the same one again."""
    ref = walk_ref[:36]
    kw = dict(samples=8, keep=4, window=12, lookahead=0, persistence=1.0, seed=5)
    plain = search_offsets(model, ref, recentre=0.0, **kw)[0]
    centred = search_offsets(model, ref, recentre=1.0, **kw)[0]
    again = search_offsets(model, ref, recentre=1.0, **kw)[0]
    assert np.array_equal(centred, again) and not np.array_equal(plain, centred)


def test_elites_go_on_with_their_parents_offset(model, walk_ref):
    """Every candidate an elite: each goes on with its parent's offset, which starts at zero, so
    the search never leaves the uncorrected targets whatever the noise (the replay is then
    ``track`` with the balance feedback, bit for bit); one elite in six is another search."""
    ref = walk_ref[:48]
    kw = dict(window=12, lookahead=12, torque_sigma=0.3, seed=5)
    offsets, _ = search_offsets(model, ref, samples=2, keep=2, elite=2, **kw)
    assert not offsets.any()
    r = sample_track(model, ref, samples=2, keep=2, elite=2, **kw)
    b = track(model, ref, assist_limit=0.0, balance=BALANCE)
    assert np.array_equal(r.qpos, b.qpos)
    plain, _ = search_offsets(model, ref, samples=6, keep=2, **kw)
    one, _ = search_offsets(model, ref, samples=6, keep=2, elite=1, **kw)
    assert plain.any() and not np.array_equal(plain, one)


def test_drift_rate_leads_the_root_velocity_target_by_the_position_error():
    """``CostWeights.drift_rate``: zero on the reference; a root ``d`` off the reference's path
    and as fast as the reference pays ``root_xy |d|^2`` plus ``root_vel (rate |d|)^2`` (its
    velocity target leads by ``rate (ref - sim)``), the lead's length clipped to ``rate
    drift_max``; a root already heading back at that lead pays for the position only."""
    from sim.simulate.sampling import CostWeights, Features, window_cost

    ref = Features(z=0.9, xy=np.array([1.0, 2.0]), quat=np.array([1.0, 0.0, 0.0, 0.0]),
                   hinges=np.zeros(3), ee=np.zeros((2, 3)), balance=np.zeros(2),
                   vel=np.array([1.2, 0.0, 0.1]))  # fmt: skip
    w = CostWeights(drift_rate=2.0, drift_max=0.3, root_vel=5.0)
    hinge_w = np.full(3, 1 / 3)
    assert window_cost(ref, ref, w, hinge_w) == 0.0

    def moved(d, dv=(0.0, 0.0, 0.0)):
        return Features(**{**ref.__dict__, "xy": ref.xy + d, "vel": ref.vel + np.array(dv)})

    behind = moved(np.array([-0.1, 0.0]))  # 10 cm behind, as fast: target 0.2 m/s faster
    assert window_cost(behind, ref, w, hinge_w) == pytest.approx(20 * 0.01 + 5 * 0.2**2)
    assert window_cost(behind, ref, CostWeights(), hinge_w) == pytest.approx(20 * 0.01)
    back = moved(np.array([-0.1, 0.0]), (0.2, 0.0, 0.0))  # heading back at the lead
    assert window_cost(back, ref, w, hinge_w) == pytest.approx(20 * 0.01)
    far = moved(np.array([0.0, 0.5]))  # 50 cm aside: the lead 2 x 0.3 m/s towards the path
    assert window_cost(far, ref, w, hinge_w) == pytest.approx(20 * 0.25 + 5 * 0.6**2)


def _spy_on_the_sampler(monkeypatch, key: str):
    """``validate.sample_track`` replaced by a spy that records its keyword ``key`` ("absent"
    where not given) and raises the returned exception type: (the record, the type)."""
    import sim.simulate.validate as validate

    seen = []

    class Stop(Exception):
        pass

    def fake(model, ref, **kw):
        seen.append(kw.get(key, "absent"))
        raise Stop

    monkeypatch.setattr(validate, "sample_track", fake)
    return seen, Stop


def test_forward_validation_tracks_with_the_drift_lead_unless_its_search_names_a_feedback(
    model, walk_ref, monkeypatch
):
    """eval's sampler gets ``DEFAULT_BALANCE`` (the feedback with the drift lead); a search that
    names its own feedback (or none) keeps it."""
    import sim.simulate.validate as validate
    from sim.simulate.balance import Balance

    seen, Stop = _spy_on_the_sampler(monkeypatch, "balance")
    qpos = walk_ref[::4][:8]  # 30 fps
    for search in ({}, {"balance": None}, {"balance": Balance()}):
        with pytest.raises(Stop):
            validate.ForwardValidation(model, ("root",), samples=2, search=search).run(qpos, 30.0)
    assert seen == [validate.DEFAULT_BALANCE, None, Balance()]
    assert validate.DEFAULT_BALANCE.k_drift > 0 and BALANCE.k_drift == 0  # synth keeps its own


def _standing(model, ticks: int = 24) -> np.ndarray:
    """(ticks, nq) the rest pose upright, 1 m up (a reference that needs no data)."""
    ref = np.tile(model.qpos0, (ticks, 1))
    ref[:, 2] = 1.0
    ref[:, 3:7] = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]  # y up -> z up
    return ref


def test_noise_deflection_keeps_the_default_bodys_angles_on_a_stiffer_body(model):
    """The offsets' noise is a share of peak torque over the stiffness: a stiffer body (cap 0.1
    rad) gets smaller angles where its stiffness grew; with ``noise_deflection`` 0.25 (the
    default cap) the stiffer body's noise is the default body's, joint by joint."""
    import mujoco

    from sim.simulate.model import MIN_DEFLECTION, Gains
    from sim.simulate.sampling import _problem

    stiff = sim_model(canonical_skeleton(), gains=Gains(min_deflection=0.1))
    ref = _standing(model)
    base = _problem(model, ref, mujoco.MjData(model), 0.3, (), falls=False).sigma
    own = _problem(stiff, ref, mujoco.MjData(stiff), 0.3, (), falls=False).sigma
    kept = _problem(stiff, ref, mujoco.MjData(stiff), 0.3, (), falls=False,
                    noise_deflection=MIN_DEFLECTION).sigma  # fmt: skip
    grew = stiff.actuator_gainprm[:, 0] > model.actuator_gainprm[:, 0] * 1.5
    assert (grew & (base > 0)).sum() >= 6  # the hips and the spine
    ratio = model.actuator_gainprm[:, 0] / stiff.actuator_gainprm[:, 0]
    np.testing.assert_allclose(own, base * ratio)  # the same torque share: smaller angles
    np.testing.assert_allclose(kept, base)
    lim = model.actuator_forcerange[:, 1]
    assert np.all(base <= 0.3 * lim / model.actuator_gainprm[:, 0] + 1e-12)


def test_forward_validation_builds_its_body_with_the_default_gains(monkeypatch):
    """eval's and report's body (``forward_validation``) has ``validate.DEFAULT_GAINS`` (one
    place to change them), unless the caller names gains; its sampler gets
    ``DEFAULT_NOISE_DEFLECTION`` unless its search names one."""
    import sim.simulate.validate as validate
    from sim.simulate.model import Gains

    skeleton = canonical_skeleton()
    stiff = Gains(min_deflection=0.1)
    monkeypatch.setattr(validate, "DEFAULT_GAINS", stiff)
    fv = validate.forward_validation(skeleton, ("root",))
    want = sim_model(skeleton, gains=stiff).actuator_gainprm[:, 0]
    np.testing.assert_array_equal(fv.model.actuator_gainprm[:, 0], want)
    named = validate.validation_model(skeleton, gains=Gains())
    plain = sim_model(skeleton).actuator_gainprm[:, 0]
    np.testing.assert_array_equal(named.actuator_gainprm[:, 0], plain)
    assert not np.allclose(want, plain)

    seen, Stop = _spy_on_the_sampler(monkeypatch, "noise_deflection")
    monkeypatch.setattr(validate, "DEFAULT_NOISE_DEFLECTION", 0.25)
    ref = _standing(fv.model, 8)
    for search in ({}, {"noise_deflection": 0.0}):
        with pytest.raises(Stop):
            validate.ForwardValidation(fv.model, ("root",), samples=2, search=search).run(
                ref, 120.0
            )
    assert seen == [0.25, 0.0]


def test_a_rollout_that_diverges_stops_and_is_never_kept(model, walk_ref):
    """MuJoCo resets a diverging state to the model's initial pose and goes on; a rollout that
    diverges stops at that tick, and its candidate costs DIVERGED_COST, so the search never
    keeps a reset (teleported) state. The plain tracker reports it as unstable."""
    import mujoco

    from sim.simulate.sampling import (
        DIVERGED_COST,
        CostWeights,
        _candidate_costs,
        _problem,
        _rollout,
    )
    from sim.simulate.tracking import divergences

    data = mujoco.MjData(model)
    prob = _problem(model, walk_ref, data, 0.3, ())
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    states = np.empty((2, mujoco.mj_stateSize(model, spec)))
    for i, speed in enumerate((None, 1e12)):  # a sane state and one that must diverge
        mujoco.mj_resetData(model, data)
        data.qpos[:], data.qvel[:] = walk_ref[0], prob.ref_qvel[0]
        if speed is not None:
            data.qvel[6:] = speed
        mujoco.mj_getState(model, data, states[i], spec)
    keep = np.empty(states.shape[1]), np.empty(model.nq), spec, None
    for _ in range(2):  # MuJoCo's reset clears its counts: a second divergence is seen too
        mujoco.mj_setState(model, data, states[1], spec)
        end = _rollout(model, data, prob, np.zeros(model.nu), (0, 12, 48), ((), ()), keep)
        assert divergences(data) > 0 and end == -1  # stopped at its first tick
    offs = np.zeros((2, model.nu))
    out = np.empty((2, states.shape[1])), np.empty((2, model.nq))
    search = (states, CostWeights(), ((), ()), spec)
    cost = _candidate_costs(model, [data], prob, search, np.array([0, 1]), offs, (0, 12, 48),
                            out, None)  # fmt: skip
    assert cost[1] == DIVERGED_COST and cost[0] < DIVERGED_COST / 1e6
