"""``synth --gain-choice``: the sampler chooses its feedback gains per window between the body's
and the stiff set, and the episodes still replay bit for bit, because each tick's gains are
stored with its action (a variable-impedance action) and the torque limits never move."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest
from synth_replay import PER_KIND, REAL, SECONDS, check_replays, oracle_replay

from sim.motion.clip import load_extra
from sim.simulate.episode import array_text

SHARE = 0.5


@pytest.fixture(scope="module")
def gain_run(cmu_dir, tmp_path_factory):
    """``PER_KIND`` clips of each real-motion kind, the sampler (4 rollouts per window, half on
    the stiff gains: short to run) choosing its gains per window."""
    from sim.simulate.dataset import synthesize

    out = tmp_path_factory.mktemp("gains")
    s = synthesize(cmu_dir, out, (PER_KIND + 1) * len(REAL), kinds=REAL, seconds=SECONDS,
                   seed=0, samples=4, workers=2, progress=False, gain_choice=SHARE)  # fmt: skip
    assert not s.skipped
    return out, s.written


@pytest.mark.slow
def test_gain_chosen_episodes_of_every_real_kind_replay_bit_for_bit(gain_run):
    out, written = gain_run
    count = check_replays(out, written, REAL)  # the oracle sets each tick's stored gains
    assert count["pushed"] >= 10 and count["weakened"] >= 5 and count["assisted"] == 0
    assert count["switched"] >= len(written) // 2  # the gains changed within most clips (49 of 63)
    for r in written:
        assert r["task"]["gain_choice"] == SHARE
        assert r["generation"]["sampling"]["gain_choice"]["share"] == SHARE


@pytest.mark.slow
def test_without_the_stored_gains_a_replay_strays(gain_run):
    """The stored gains are needed: replayed with the MJCF's gains alone, the states differ."""
    out, written = gain_run
    labels = load_extra(out / written[0]["file"], "sim_")
    assert len(np.unique(labels["sim_actuator_gains"][:, 0, 0])) == 2
    fixed = {k: v for k, v in labels.items() if k != "sim_actuator_gains"}
    q, _, _, _ = oracle_replay(fixed, np.full(labels["sim_actions"].shape[1], np.inf))
    assert not np.array_equal(q, labels["sim_tick_qpos"])


def test_the_gain_sets_are_one_body_with_the_human_limits():
    from sim.model.humanoid import canonical_skeleton
    from sim.simulate.episode_body import episode_bodies
    from sim.simulate.model import Gains, sim_model
    from sim.simulate.validate import STIFF_GAINS

    (body, stiff), mjcf, _ = episode_bodies(canonical_skeleton(), 1.0, 1.3, "position", False,
                                            (STIFF_GAINS,))  # fmt: skip
    own = sim_model(canonical_skeleton(), gains=STIFF_GAINS.scaled(1.3))  # the stiff set alone
    assert np.allclose(stiff.actuator_gainprm[:, 0], own.actuator_gainprm[:, 0], rtol=1e-5)
    assert np.allclose(stiff.actuator_biasprm[:, 2], own.actuator_biasprm[:, 2], rtol=1e-5)
    assert np.all(stiff.actuator_gainprm[:, 0] > 2 * body.actuator_gainprm[:, 0])
    default = sim_model(canonical_skeleton(), gains=Gains().scaled(1.3))
    assert np.allclose(body.actuator_gainprm[:, 0], default.actuator_gainprm[:, 0], rtol=1e-5)
    rebuilt = mujoco.MjModel.from_xml_string(mjcf)
    for name in ("actuator_forcerange", "actuator_ctrlrange", "dof_armature", "body_mass",
                 "dof_invweight0", "actuator_gainprm", "actuator_biasprm"):  # fmt: skip
        assert np.array_equal(getattr(rebuilt, name), getattr(body, name)), name
    for name in ("actuator_forcerange", "actuator_ctrlrange", "dof_armature", "body_mass",
                 "dof_invweight0"):  # fmt: skip
        assert np.array_equal(getattr(stiff, name), getattr(body, name)), name
    # the armature is the larger of the two sets' (the stiff one's where it is raised), to
    # the MJCF's 6 digits
    larger = np.maximum(default.dof_armature, own.dof_armature)
    assert np.allclose(body.dof_armature, larger, rtol=1e-5, atol=0)
    assert np.any(own.dof_armature > default.dof_armature * 1.01)  # where it was raised
    # the stiff set's own control range lies within the MJCF's
    assert np.all(own.actuator_ctrlrange[:, 0] >= body.actuator_ctrlrange[:, 0] - 1e-5)
    assert np.all(own.actuator_ctrlrange[:, 1] <= body.actuator_ctrlrange[:, 1] + 1e-5)


def test_the_minari_export_carries_each_step_s_gains_in_its_action(gain_run, tmp_path,
                                                                   monkeypatch):  # fmt: skip
    minari = pytest.importorskip("minari")
    from sim.simulate.episode import replay, split_actions
    from sim.simulate.export import export_minari

    out, written = gain_run
    assert export_minari(out, tmp_path / "root", "sidql/gains-test-v0") == len(written)
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "root"))
    ds = minari.load_dataset("sidql/gains-test-v0")
    meta = json.loads((tmp_path / "root/sidql/gains-test-v0/data/metadata.json").read_text())
    nu = len(meta["joint_names"])
    assert meta["action_layout"] == {"target": [0, nu], "kp": [nu, 2 * nu], "kv": [2 * nu, 3 * nu]}
    assert ds.action_space.shape == (3 * nu,)
    episodes = ds.iterate_episodes()
    metadata = ds.storage.get_episode_metadata(range(ds.total_episodes))
    for ep, m, r in list(zip(episodes, metadata, written, strict=True))[:12]:
        labels = load_extra(out / r["file"], "sim_")
        N = len(ep.actions)
        targets, gains = split_actions(ep.actions)
        assert np.array_equal(targets, labels["sim_actions"][:N])
        assert np.array_equal(gains, labels["sim_actuator_gains"][:N])
        assert all(ds.action_space.contains(a) for a in ep.actions)
        q, v = replay(m["mjcf"], m["initial_state"], targets, ep.infos["xfrc_applied"][1:],
                      ep.infos["qfrc_applied"][1:], int(m["frame_skip"]), gains)  # fmt: skip
        assert np.array_equal(q, ep.observations["qpos"])
        assert np.array_equal(v, ep.observations["qvel"])
        body = mujoco.MjModel.from_xml_string(m["mjcf"])
        assert np.array_equal(m["torque_limit"], body.actuator_forcerange[:, 1])


def test_a_gain_choice_run_resumes_as_itself_only(cmu_dir, tmp_path):
    from sim.simulate.dataset import synthesize

    kw = dict(kinds=("track",), seconds=0.25, seed=5, samples=2, workers=1, progress=False)
    first = synthesize(cmu_dir, tmp_path, 1, gain_choice=SHARE, **kw)
    index = json.loads((tmp_path / "index.json").read_text())["synthetic"]
    assert index["gain_choice"] == SHARE
    with pytest.raises(ValueError, match="other parameters"):
        synthesize(cmu_dir, tmp_path, 1, resume=True, gain_choice=0.0, **kw)
    again = synthesize(cmu_dir, tmp_path, 1, resume=True, gain_choice=SHARE, **kw)
    assert again.written == first.written
    generation = json.loads(array_text(load_extra(tmp_path / first.written[0]["file"],
                                                  "sim_")["sim_generation"]))  # fmt: skip
    assert generation["sampling"]["gain_choice"]["share"] == SHARE


def test_a_gain_choice_is_the_sampler_s_alone(cmu_dir, tmp_path, capsys):
    from sidql.commands.main import main
    from sim.errors import UsageError
    from sim.simulate.dataset import synthesize

    for kw in ({"controller": "plain", "gain_choice": 0.5}, {"gain_choice": 1.5}):
        with pytest.raises(UsageError):
            synthesize(cmu_dir, tmp_path / "o", 1, kinds=("track",), progress=False, **kw)
    args = ["synth", "--data", str(cmu_dir), "--n", "1", "--out", str(tmp_path / "c")]
    assert main([*args, "--controller", "plain", "--gain-choice", "0.5"]) == 2
    assert "--gain-choice" in capsys.readouterr().err
    assert not (tmp_path / "o").exists() and not (tmp_path / "c").exists()
