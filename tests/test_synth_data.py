"""Synthetic data as learners use it: every episode replays bit for bit from its stored first
state, actions and applied wrenches on the MJCF it carries; its torques stay within the human
limits; Minari loads the export unedited, with terminations only at falls."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest
from synth_replay import PER_KIND, REAL, SECONDS, check_replays

from sim.motion.clip import load_extra
from sim.simulate.episode import array_text
from sim.simulate.model import human_torque_limit

KINDS = ("track", "fall", "follow", "procedural")


@pytest.fixture(scope="module")
def synth(cmu_dir, tmp_path_factory):
    """A synth folder of ``PER_KIND`` short clips of every kind (plain tracker), and its
    index entries."""
    from sim.simulate.dataset import synthesize

    out = tmp_path_factory.mktemp("synth")
    # a few spare tasks: a simulation MuJoCo flags as diverging is dropped and listed (the
    # plain tracker diverges on a few references at their first ticks)
    s = synthesize(cmu_dir, out, (PER_KIND + 2) * len(KINDS), kinds=KINDS, seconds=SECONDS,
                   seed=0, workers=1, progress=False, controller="plain")  # fmt: skip
    assert all("UnstableSimulation" in r["error"] for r in s.skipped) and len(s.skipped) <= 4
    return out, s.written


@pytest.fixture(scope="module")
def synth_wholebody(cmu_dir, tmp_path_factory):
    """``PER_KIND`` short clips of every real-motion kind tracked by the whole-body QP, whose
    weakening (the ``fall`` kind) bounds its torques at a share of the limits for a while."""
    from sim.simulate.dataset import synthesize

    out = tmp_path_factory.mktemp("synth_wb")
    s = synthesize(cmu_dir, out, (PER_KIND + 1) * 3, kinds=REAL, seconds=SECONDS, seed=0,
                   workers=1, progress=False, controller="wholebody")  # fmt: skip
    assert all("UnstableSimulation" in r["error"] for r in s.skipped) and len(s.skipped) <= 3
    return out, s.written


def test_stored_actions_replay_every_state_bit_for_bit_within_human_torque_limits(synth):
    count = check_replays(*synth, KINDS)
    assert count["pushed"] >= 10 and count["assisted"] >= 20 and count["strong"] >= 3
    assert count["stepped"] >= 1  # an episode in the scene inferred from its trial (01_02, 03_0x)
    assert count["weakened"] >= 5  # the wrenches, assistance, gains and weakenings were there
    assert all(r["generation"]["controller"] == "plain" for r in synth[1])


def test_the_wholebody_controller_replays_bit_for_bit_through_its_weakenings(synth_wholebody):
    """The QP weakens by bounding its torques; the episode records the torque that acts, so
    the MJCF's own model replays it (``Recorder``)."""
    count = check_replays(*synth_wholebody, REAL)
    assert count["pushed"] >= 10 and count["weakened"] >= 5 and count["assisted"] == 0
    assert all(r["generation"]["controller"] == "wholebody" for r in synth_wholebody[1])


def test_an_edited_position_actuator_is_refused_by_the_recorder():
    from sim.errors import UsageError
    from sim.model.humanoid import canonical_skeleton
    from sim.simulate.episode import Recorder
    from sim.simulate.model import sim_model

    model = sim_model(canonical_skeleton())
    data = mujoco.MjData(model)
    rec = Recorder(model, "", 2)
    rec(0, data)
    model.actuator_gainprm[:, 0] *= 0.5  # a weakening by editing the model's PD servos
    with pytest.raises(UsageError):
        rec(1, data)


def test_assistance_only_on_request_and_labelled(cmu_dir):
    from dataclasses import replace

    from sim.simulate.generate import SynthTask, generate

    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    task = SynthTask("follow", 0, 0, str(asf), str(amc), seconds=0.5, controller="plain")
    _, plain = generate(task)
    _, helped = generate(replace(task, assist=0.5))
    assert plain["generation"]["assist_limit"] == 0 and plain["mean_assistance"] == 0
    assert not plain["labels"]["sim_qfrc_applied"].any() and plain["physical"]
    assert helped["generation"]["assist_limit"] == 0.5 and helped["mean_assistance"] > 0
    assert helped["labels"]["sim_qfrc_applied"].any()
    assert np.abs(helped["labels"]["sim_assist_wrench"]).max() > 0


def test_the_sampling_tracker_replays_bit_for_bit(cmu_dir):
    from sim.simulate.episode import replay
    from sim.simulate.generate import SynthTask, generate

    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    for index in (0, 1):
        task = SynthTask("track", 0, index, str(asf), str(amc), seconds=0.5, samples=4)
        _, rec = generate(task)
        lab = rec["labels"]
        assert not np.any(lab["sim_qfrc_applied"])  # no assistance at all
        q, v = replay(array_text(lab["sim_mjcf"]), lab["sim_initial_state"], lab["sim_actions"],
                      lab["sim_xfrc_applied"], lab["sim_qfrc_applied"], 4)  # fmt: skip
        assert np.array_equal(q, lab["sim_tick_qpos"]) and np.array_equal(v, lab["sim_tick_qvel"])


def test_minari_loads_the_export_with_terminations_only_at_falls(synth, tmp_path, monkeypatch):
    minari = pytest.importorskip("minari")  # the test extra installs it
    from sim.simulate.episode import replay, split_actions
    from sim.simulate.export import export_minari

    out, written = synth
    assert export_minari(out, tmp_path / "root", "sidql/synth-test-v0") == len(written)
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "root"))
    ds = minari.load_dataset("sidql/synth-test-v0")
    assert ds.total_episodes == len(written)
    meta = ds.storage.metadata
    assert meta["frame_skip"] == 4 and "<mujoco" in meta["mjcf"]
    canonical = mujoco.MjModel.from_xml_string(meta["mjcf"])
    assert np.allclose(meta["torque_limit"],
                       [human_torque_limit(canonical.actuator(i).name) for i in range(canonical.nu)])  # fmt: skip
    episodes = list(ds.iterate_episodes())
    metadata = list(ds.storage.get_episode_metadata(range(len(written))))
    steps = falls = 0
    for ep, m, r in zip(episodes, metadata, written, strict=True):
        labels = load_extra(out / r["file"], "sim_")
        T, fall = len(labels["sim_actions"]), int(labels["sim_fall_tick"])
        N = fall if fall > 0 else T
        assert len(ep.actions) == len(ep.rewards) == N and m["total_steps"] == N
        assert np.array_equal(ep.observations["qpos"], labels["sim_tick_qpos"][: N + 1])
        assert np.array_equal(ep.observations["qvel"], labels["sim_tick_qvel"][: N + 1])
        targets, gains = split_actions(ep.actions)  # PD targets, then kp and kv per actuator
        assert np.array_equal(targets, labels["sim_actions"][:N])
        assert np.array_equal(gains, labels["sim_actuator_gains"][:N])
        assert ds.action_space.contains(ep.actions[0])
        last = np.arange(N) == N - 1
        assert np.array_equal(ep.terminations, last & (fall > 0))
        assert np.array_equal(ep.truncations, last & (fall <= 0))
        assert m["seed"] == r["generation"]["seed"] and m["kind"] == r["subject"]
        assert json.loads(m["generation"]) == r["generation"]
        q, v = replay(m["mjcf"], m["initial_state"], targets, ep.infos["xfrc_applied"][1:],
                      ep.infos["qfrc_applied"][1:], int(m["frame_skip"]), gains)  # fmt: skip
        assert np.array_equal(q, ep.observations["qpos"]) and np.array_equal(
            v, ep.observations["qvel"]
        )
        steps += N
        falls += fall > 0
    assert ds.total_steps == steps
    assert falls >= 1  # a fall ended some episode (and its terminations were checked)
    # episodes in a scene with steps replayed on their own MJCF (above); the dataset's is the
    # empty floor's, and says how many carry steps
    stepped = sum('name="terrain0"' in m["mjcf"] for m in metadata)
    assert stepped >= 1 and 'name="terrain' not in meta["mjcf"]
    assert f"{stepped} of {len(written)} episodes carry steps" in meta["scenes"]


def test_cli_synth_exports_minari_and_refuses_a_bad_id(tmp_path, monkeypatch, capsys):
    minari = pytest.importorskip("minari")
    from sidql.commands.main import main

    root = tmp_path / "root"
    args = ["synth", "--n", "2", "--kinds", "procedural", "--seconds", "0.25", "--workers", "1",
            "--out", str(tmp_path / "s"), "--export-minari", str(root), "--quiet"]  # fmt: skip
    assert main(args) == 0
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    assert minari.load_dataset("sidql/synth-v0").total_episodes == 2
    assert main([*args, "--minari-id", "../escape"]) == 2
    assert "../escape" in capsys.readouterr().err
    assert not (tmp_path / "escape").exists()


def test_minari_export_of_torque_actions_carries_the_torque_body(synth_wholebody, tmp_path):
    from sim.simulate.export import export_minari

    out, written = synth_wholebody
    assert export_minari(out, tmp_path / "root", "sidql/wb-test-v0") == len(written)
    meta = json.loads(
        (tmp_path / "root" / "sidql/wb-test-v0" / "data" / "metadata.json").read_text()
    )
    assert meta["actions"].startswith("torque [N m]")
    body = mujoco.MjModel.from_xml_string(meta["mjcf"])
    assert not body.actuator_biasprm[:, 1].any()  # torque actuators, not PD servos
    space = json.loads(meta["action_space"])
    high, limit = np.array(space["high"]), np.array(meta["torque_limit"])
    assert np.all(high >= 0.6 * limit) and np.all(high <= 1.6 * limit)  # limits x body sizes
