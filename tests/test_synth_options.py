"""``synth``'s sampler options (``SynthTask.drift``, ``contact_reference``, ``lean``): each
episode records what it used, the stored MJCF is the body simulated (the lean flags in its
options) and replays bit for bit, the contact-consistent reference stands on the floor, and a
run with options resumes as itself and only as itself."""

from __future__ import annotations

import json
from dataclasses import asdict, replace

import mujoco
import numpy as np
import pytest
from synth_replay import oracle_replay

from sim.motion.clip import load_extra, load_npz
from sim.simulate.episode import array_text
from sim.simulate.model import LEAN_DISABLED, human_torque_limit
from sim.simulate.sampling import BALANCE
from sim.simulate.validate import DEFAULT_BALANCE

SHORT = 0.5  # [s]
ALL_ON = {"drift": True, "contact_reference": True, "lean": True}


def _task(cmu_dir, kind="track", **kw):
    from sim.simulate.generate import SynthTask

    amc, asf = str(cmu_dir / "07" / "07_01.amc"), str(cmu_dir / "07" / "07.asf")
    return SynthTask(kind, seed=3, index=1, asf=asf, amc=amc, seconds=SHORT, samples=4, **kw)


def _reference(task, ticks: int):
    """(p, model, ref): ``task``'s drawn parameters, its episode body and the reference the
    sampler tracks (``ticks`` control ticks), built by the generator's own functions."""
    from sim.model.humanoid import canonical_skeleton
    from sim.simulate.episode_scene import episode_setup
    from sim.simulate.generate import draw_parameters, episode_rng, episode_seed
    from sim.simulate.model import scaled_skeleton

    rng = episode_rng(episode_seed(task))
    p = draw_parameters(task, rng)
    skeleton = scaled_skeleton(canonical_skeleton(), p["scale"])
    models, _, _, ref = episode_setup(task, p, skeleton, (), ticks, rng)
    return p, models[0], ref


@pytest.fixture(scope="module")
def optioned_run(cmu_dir, tmp_path_factory):
    from sim.simulate.dataset import synthesize

    out = tmp_path_factory.mktemp("options")
    s = synthesize(cmu_dir, out, 2, kinds=("track", "fall"), seconds=SHORT, seed=3, samples=4,
                   workers=1, progress=False, **ALL_ON)  # fmt: skip
    assert not s.skipped and len(s.written) == 2
    return out, s.written


def test_the_options_are_recorded_and_the_stored_lean_body_replays_bit_for_bit(optioned_run):
    out, written = optioned_run
    index = json.loads((out / "index.json").read_text())["synthetic"]
    assert all(index[k] is True for k in ALL_ON)
    assert DEFAULT_BALANCE != BALANCE and DEFAULT_BALANCE.k_drift > 0  # the premise
    for r in written:
        g = r["generation"]
        assert all(r["task"][k] is True for k in ALL_ON)
        assert g["sampling"]["balance"] == asdict(DEFAULT_BALANCE)
        assert g["reference"] == "contact-consistent" and g["lean"] is True
        labels = load_extra(out / r["file"], "sim_")
        assert json.loads(array_text(labels["sim_generation"])) == g
        mass = 75.0 * g["scale"] ** 3
        limits = np.array(
            [human_torque_limit(n, mass) for n in load_npz(out / r["file"]).joint_names]
        )
        q, v, worst, model = oracle_replay(labels, limits)
        assert model.opt.disableflags & LEAN_DISABLED == LEAN_DISABLED  # the lean body's MJCF
        assert np.array_equal(q, labels["sim_tick_qpos"]) and np.array_equal(
            v, labels["sim_tick_qvel"]
        )
        assert worst <= 1 + 1e-12


def test_without_options_the_record_says_so(cmu_dir):
    from sim.simulate.generate import generate, task_dict

    task = _task(cmu_dir)
    assert not any(k in task_dict(task) for k in ALL_ON)  # a run written before them resumes
    rec = generate(task)[1]
    g = rec["generation"]
    assert g["sampling"]["balance"] == asdict(BALANCE) and g["reference"] == "lifted"
    assert g["lean"] is False
    model = mujoco.MjModel.from_xml_string(array_text(rec["labels"]["sim_mjcf"]))
    assert model.opt.disableflags & LEAN_DISABLED == 0
    plain = generate(replace(task, samples=0, controller="plain", contact_reference=True))[1]
    assert plain["generation"]["reference"] == "lifted"  # the option is the sampler's


def test_the_lean_body_moves_as_the_full_one_bit_for_bit(cmu_dir):
    from sim.simulate.generate import generate

    full = generate(_task(cmu_dir, "fall"))[1]["labels"]
    lean = generate(_task(cmu_dir, "fall", lean=True))[1]["labels"]
    assert array_text(full["sim_mjcf"]) != array_text(lean["sim_mjcf"])
    for k in ("sim_actions", "sim_tick_qpos", "sim_tick_qvel", "sim_xfrc_applied"):
        assert np.array_equal(full[k], lean[k]), k


def test_the_contact_consistent_reference_stands_on_the_floor_when_asked(cmu_dir):
    """The sampler's reference: with the option its stance soles touch z = 0 (lowest sole
    point within 2 mm in stance), lifted 1 cm without it; the same window either way."""
    from sim.simulate.model import CONTROL_HZ
    from sim.simulate.reference import STANCE_GAP, lowest_foot_point

    lows, starts = {}, {}
    for contact in (False, True):
        p, model, ref = _reference(
            _task(cmu_dir, contact_reference=contact), int(SHORT * CONTROL_HZ)
        )
        assert p["reference"] == ("contact-consistent" if contact else "lifted")
        low = lowest_foot_point(model, ref)
        lows[contact], starts[contact] = low[low <= STANCE_GAP + 0.01], p["start_tick"]
    assert starts[True] == starts[False] and lows[True].size and lows[False].size
    assert abs(np.median(lows[True])) < 0.002
    assert np.median(lows[False]) > 0.005


def test_a_run_with_options_resumes_as_itself_only(optioned_run, cmu_dir, tmp_path):
    import shutil

    from sim.simulate.dataset import synthesize

    out, written = optioned_run
    run = tmp_path / "run"
    shutil.copytree(out, run)
    kw = dict(kinds=("track", "fall"), seconds=SHORT, seed=3, samples=4, workers=1,
              progress=False)  # fmt: skip
    with pytest.raises(ValueError, match="other parameters"):
        synthesize(cmu_dir, run, 2, resume=True, **kw)  # without the options: another run
    assert synthesize(cmu_dir, run, 2, resume=True, **kw, **ALL_ON).written == written


def test_the_cli_flags_reach_synthesize(cmu_dir, tmp_path, monkeypatch):
    from types import SimpleNamespace

    import sidql.commands.synth as synth_cmd
    from sidql.commands import main as cli

    seen = {}

    def fake(*args, **kw):
        seen.update(kw)
        return SimpleNamespace(written=[], skipped=[], seconds=0.0, rejected={})

    monkeypatch.setattr(synth_cmd, "synthesize", fake)
    argv = ["synth", "--data", str(cmu_dir), "--n", "1", "--out", str(tmp_path / "o")]
    assert cli.main([*argv, "--drift", "--no-lean"]) in (0, None)
    assert (seen["drift"], seen["contact_reference"], seen["lean"]) == (True, None, False)
    assert cli.main([*argv, "--contact-reference", "--foot-lock"]) in (0, None)
    assert (seen["contact_reference"], seen["foot_lock"]) == (True, True)


def test_a_foot_locked_episode_is_recorded_tracks_the_locked_reference_and_replays(cmu_dir):
    """``SynthTask.foot_lock``: the sampler tracks ``foot_locked`` of the contact-consistent
    reference (the same window: the reference built here by the module's own functions), the
    generation says so, and the episode replays bit for bit under MuJoCo alone."""
    from sim.simulate.footlock import foot_locked
    from sim.simulate.generate import generate
    from sim.simulate.model import CONTROL_HZ

    task = replace(_task(cmu_dir, contact_reference=True, foot_lock=True), seconds=1.0)
    n = int(task.seconds * CONTROL_HZ)
    refs = {}
    for lock in (False, True):
        _, model, refs[lock] = _reference(replace(task, foot_lock=lock), n)
    np.testing.assert_array_equal(refs[True], foot_locked(model, refs[False], CONTROL_HZ))
    assert not np.array_equal(refs[True], refs[False])  # the lock moved some leg
    clip, rec = generate(task)
    g = rec["generation"]
    assert g["reference"] == "contact-consistent, foot-locked"
    labels = rec["labels"]
    assert json.loads(array_text(labels["sim_generation"])) == g
    limits = np.array([human_torque_limit(nm, 75.0 * g["scale"] ** 3) for nm in clip.joint_names])
    q, v, worst, _ = oracle_replay(labels, limits)
    assert np.array_equal(q, labels["sim_tick_qpos"]) and np.array_equal(v, labels["sim_tick_qvel"])
    assert worst <= 1 + 1e-12


def test_a_foot_lock_needs_the_contact_consistent_reference(cmu_dir, tmp_path):
    from sim.errors import UsageError
    from sim.simulate.dataset import synthesize
    from sim.simulate.generate import generate

    with pytest.raises(UsageError, match="contact-consistent"):
        generate(_task(cmu_dir, foot_lock=True))
    with pytest.raises(UsageError, match="contact-consistent"):
        synthesize(cmu_dir, tmp_path / "o", 1, seconds=SHORT, samples=4, workers=1,
                   progress=False, foot_lock=True)  # fmt: skip
