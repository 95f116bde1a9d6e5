"""Simulated synthetic clips: the controller, the dataset format, determinism, Ray = process pool,
and the velocity pipeline checked against the simulator's own qvel and analytic velocities."""

from __future__ import annotations

import json
import shutil

import mujoco
import numpy as np
import pytest

from sim.model.humanoid import canonical_skeleton, humanoid_model
from sim.motion.clip import load_npz
from sim.motion.synthetic import synthetic_qpos
from sim.motion.velocities import qvel_from_qpos
from sim.simulate.controller import track
from sim.simulate.dataset import synthesize
from sim.simulate.episode import array_text
from sim.simulate.generate import (
    LABELS,
    PHYSICAL_BUDGET,
    SynthTask,
    episode_seed,
    generate,
    simulated_clip,
)
from sim.simulate.model import CONTROL_HZ, SUBSTEPS, sim_model
from sim.simulate.reference import on_floor, time_warp


def _arrays(path):
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def test_procedural_clip_is_simulated_state_in_dataset_format():
    clip, rec = generate(SynthTask("procedural", seed=3, index=0, seconds=1.0))
    assert clip.n_frames == 30 and clip.fps == 30.0
    # bone lengths are exact: positions come from the chain of the simulated qpos
    L = np.linalg.norm(clip.bone_vectors(), axis=-1)
    assert np.ptp(L, axis=0).max() < 1e-9
    # point velocities (chain, from the simulator's qvel) are the derivative of the points along
    # qvel: central differences of positions at qpos moved by +-eps qvel (mj_integratePos)
    model = mujoco.MjModel.from_xml_string(array_text(rec["labels"]["sim_mjcf"]))
    eps, moved = 1e-6, []
    for sign in (1, -1):
        q = clip.qpos.copy()
        for t in range(len(q)):
            mujoco.mj_integratePos(model, q[t], clip.qvel[t], sign * eps)
        zero = np.zeros_like(clip.qvel)
        moved.append(simulated_clip(model, canonical_skeleton(), q, zero, 30.0, "").positions)
    fd = (moved[0] - moved[1]) / (2 * eps)
    assert np.abs(fd - clip.velocities).max() < 1e-5 * (1 + np.abs(clip.velocities).max())
    assert np.linalg.norm(clip.velocities, axis=-1).max() > 1.0  # it moves
    assert rec["labels"]["sim_assist_wrench"].shape == (clip.n_frames, 6)
    assert rec["generation"]["run_seed"] == 3
    assert rec["generation"]["seed"] == episode_seed(SynthTask("procedural", seed=3, index=0))


def test_same_seed_same_clip_bit_for_bit(tmp_path):
    a = synthesize(None, tmp_path / "a", 2, seed=5, kinds=("procedural",), seconds=1.0,
                   workers=1, progress=False)  # fmt: skip
    b = synthesize(None, tmp_path / "b", 2, seed=5, kinds=("procedural",), seconds=1.0,
                   workers=1, progress=False)  # fmt: skip
    c = synthesize(None, tmp_path / "c", 2, seed=6, kinds=("procedural",), seconds=1.0,
                   workers=1, progress=False)  # fmt: skip
    assert len(a.written) == 2 and not a.skipped
    for ra, rb, rc in zip(a.written, b.written, c.written, strict=True):
        xa, xb = _arrays(tmp_path / "a" / ra["file"]), _arrays(tmp_path / "b" / rb["file"])
        assert xa.keys() == xb.keys()
        for k in xa:
            assert np.array_equal(xa[k], xb[k]), k
        xc = _arrays(tmp_path / "c" / rc["file"])
        assert not np.array_equal(xa["qpos"], xc["qpos"])
    index = json.loads((tmp_path / "a" / "index.json").read_text())
    assert index["trials"][0]["generation"]["kind"] == "procedural"


def test_dataset_keys_match_ingest(tmp_path, walk_clip):
    from sim.motion.clip import save_npz

    save_npz(walk_clip, tmp_path / "real.npz")
    synthesize(None, tmp_path / "s", 1, kinds=("procedural",), seconds=1.0, workers=1,
               progress=False)  # fmt: skip
    path = tmp_path / "s" / "procedural" / "procedural_00000.npz"
    synth = _arrays(path)
    # (a real trial's points also carry derivatives from its 120 fps source frames)
    real = set(_arrays(tmp_path / "real.npz")) - {
        "source_velocities",
        "accelerations",
        "derivative_noise",
    }
    assert set(synth) == real | set(LABELS)
    clip = load_npz(path)
    # the learning labels: per frame, shapes as documented, consistent with the index
    from sim.motion.clip import load_extra

    labels = load_extra(path, "sim_")
    F, U = clip.n_frames, len(clip.joint_names)
    assert labels["sim_joint_torque"].shape == (F, U)
    T = int(round(1.0 * 120))  # control ticks: actions at the control rate, frame i = tick 4 i
    assert labels["sim_actions"].shape == (T, U)
    assert labels["sim_tick_qpos"].shape == (T + 1, clip.qpos.shape[1])
    assert np.array_equal(labels["sim_tick_qpos"][: 4 * F : 4], clip.qpos)
    assert int(labels["sim_frame_skip"]) == 4
    assert labels["sim_assist_wrench"].shape == (F, 6)
    assert labels["sim_foot_force"].shape == (F, 2, 3)
    assert labels["sim_foot_contact"].dtype == bool
    assert np.array_equal(
        labels["sim_foot_contact"], np.linalg.norm(labels["sim_foot_force"], axis=-1) > 0
    )
    rec = json.loads((tmp_path / "s" / "index.json").read_text())["trials"][0]
    assert "labels" not in rec and "assistance" not in rec  # per-frame arrays: the clip only
    weight = 9.81 * 75.0
    force = np.linalg.norm(labels["sim_assist_wrench"][:, :3], axis=1) / weight
    torque = np.linalg.norm(labels["sim_assist_wrench"][:, 3:], axis=1) / weight
    assert rec["mean_assistance"] == pytest.approx(force.mean(), rel=1e-3)
    assert rec["mean_assist_torque"] == pytest.approx(torque.mean(), rel=1e-3)
    assert rec["physical"] == (max(force.mean(), torque.mean()) <= PHYSICAL_BUDGET)
    assert labels["sim_fallen"].shape == (F,) and labels["sim_fallen"].dtype == bool
    assert labels["sim_fallen"].any() == rec["fell"]


def test_bad_input_is_skipped_and_listed(tmp_path, cmu_dir):
    src = tmp_path / "cmu" / "02"
    src.mkdir(parents=True)
    (src / "02.asf").write_bytes((cmu_dir / "02" / "02.asf").read_bytes())
    (src / "02_01.amc").write_bytes((cmu_dir / "02" / "02_01.amc").read_bytes())
    (src / "02_99.amc").write_text(":FULLY-SPECIFIED\n:DEGREES\n1\nroot 0 0 zero\n")
    s = synthesize(tmp_path / "cmu", tmp_path / "out", 2, kinds=("track",), seconds=1.0,
                   workers=1, progress=False)  # fmt: skip
    assert any("02_99" in r["amc"] for r in s.skipped)
    assert len(s.written) == 2
    assert all(r["amc"].endswith("02_01.amc") for r in s.written)


def test_tracking_follows_a_walk_with_enough_assistance(cmu_dir):
    from sim.motion.ingest import load_motion

    clip = load_motion(cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc",
                       skeleton="humanoid", fps=CONTROL_HZ)  # fmt: skip
    model = sim_model(canonical_skeleton())
    ref = on_floor(model, clip.qpos[:240])
    r = track(model, ref, assist_limit=2.0)
    assert not r.fell
    assert np.abs(r.qpos[:, :3] - ref[::4, :3]).max() < 0.15  # the root stays within 15 cm
    r0 = track(model, ref, assist_limit=0.0)  # no help: the same controller cannot walk
    assert r0.assistance.max() == 0.0
    assert np.abs(r0.qpos[:, :3] - ref[::4, :3]).max() > np.abs(r.qpos[:, :3] - ref[::4, :3]).max()


def test_time_warp_keeps_the_path_and_changes_the_duration():
    _, model = humanoid_model()
    q, _ = synthetic_qpos(model, 1.0, seed=1)
    fast = time_warp(model, q, 120.0, 2.0, 120.0)
    assert len(fast) == len(q[::2])
    np.testing.assert_allclose(fast[::1, 7:], q[::2, 7:], atol=1e-12)
    np.testing.assert_allclose(fast[:, 3:7], q[::2, 3:7], atol=1e-9)


# --- item 6: sim/motion/velocities.py against two independent ground truths -------------------


def test_qvel_from_qpos_recovers_analytic_velocities_to_second_order():
    """Procedural hinge velocities are known in closed form; central differences are O(h^2)."""
    _, model = humanoid_model()
    errs = []
    for rate in (120.0, 240.0):
        q, dq = synthetic_qpos(model, 1.0, seed=2, rate=rate)
        v = qvel_from_qpos(model, q, rate)
        errs.append(np.abs(v[1:-1, 6:] - dq[1:-1]).max())
    assert errs[0] < 0.02
    assert 3.0 < errs[0] / errs[1] < 5.0  # halving h quarters the error: second order


def test_qvel_from_qpos_recovers_the_simulators_qvel():
    """MuJoCo integrates q[t+1] = q[t] (+) h v[t+1], so the central difference of the simulated
    qpos equals (v[t] + v[t+1]) / 2 up to rounding (and, for the root's rotation, to O(h^2))."""
    _, model = humanoid_model()
    model = sim_model(canonical_skeleton())
    ref, _ = synthetic_qpos(model, 0.5, seed=4, rate=CONTROL_HZ)
    data = mujoco.MjData(model)
    data.qpos[:] = ref[0]
    qs, vs = [], []
    for k in range(len(ref)):
        data.ctrl[:] = ref[k, 7:]
        for _ in range(SUBSTEPS):
            qs.append(data.qpos.copy())
            vs.append(data.qvel.copy())
            mujoco.mj_step(model, data)
    qs, vs = np.array(qs), np.array(vs)
    h = model.opt.timestep
    v = qvel_from_qpos(model, qs, 1.0 / h)
    mid = (vs[1:-1] + vs[2:]) / 2
    np.testing.assert_allclose(v[1:-1, 6:], mid[:, 6:], atol=1e-8)
    np.testing.assert_allclose(v[1:-1, :6], mid[:, :6], atol=1e-3 * (1 + np.abs(vs).max()))


@pytest.mark.slow
def test_ray_results_equal_the_process_pool(tmp_path):
    pytest.importorskip("ray")
    kw = dict(kinds=("procedural",), seconds=0.5, seed=1, progress=False)
    synthesize(None, tmp_path / "pool", 3, workers=2, **kw)
    synthesize(None, tmp_path / "ray", 3, workers=2, ray="local", **kw)
    a = json.loads((tmp_path / "pool" / "index.json").read_text())["trials"]
    b = json.loads((tmp_path / "ray" / "index.json").read_text())["trials"]
    assert len(a) == len(b) == 3
    for ra, rb in zip(a, b, strict=True):
        assert ra == rb
        xa, xb = _arrays(tmp_path / "pool" / ra["file"]), _arrays(tmp_path / "ray" / rb["file"])
        for k in xa:
            assert np.array_equal(xa[k], xb[k]), k


@pytest.mark.slow
def test_dataset_on_ray_equals_the_process_pool(tmp_path, cmu_dir):
    pytest.importorskip("ray")
    from sim.motion.dataset import ingest_directory

    src = tmp_path / "cmu" / "02"
    src.mkdir(parents=True)
    for name in ("02.asf", "02_01.amc", "02_02.amc"):
        (src / name).write_bytes((cmu_dir / "02" / name).read_bytes())
    (src / "02_99.amc").write_text("not an amc\n")
    a = ingest_directory(tmp_path / "cmu", tmp_path / "pool", workers=2, progress=False)
    b = ingest_directory(tmp_path / "cmu", tmp_path / "ray", workers=2, ray="local", progress=False)
    assert [r["file"] for r in a.written] == [r["file"] for r in b.written] == [
        "02/02_01.npz", "02/02_02.npz"
    ]  # fmt: skip
    assert [r["amc"] for r in a.skipped] == [r["amc"] for r in b.skipped]
    for r in a.written:
        xa, xb = _arrays(tmp_path / "pool" / r["file"]), _arrays(tmp_path / "ray" / r["file"])
        for k in xa:
            assert np.array_equal(xa[k], xb[k]), k


def test_floor_contact_parameters_are_the_floors_and_feet_stay_within_softness(trial_on_floor):
    from sim.simulate.model import FLOOR_SOLIMP, FLOOR_TIMECONST

    model = sim_model(canonical_skeleton())
    r = track(model, trial_on_floor(model, "02_01")[:240], assist_limit=0.5)
    # the floor's solref is used as is, not averaged with the body geoms' (MuJoCo's mixing)
    data = mujoco.MjData(model)
    data.qpos[:] = r.qpos[int(np.argmax(r.contact_penetration))]  # the deepest contact
    mujoco.mj_forward(model, data)
    floor = (data.contact.geom[: data.ncon] == model.geom("floor").id).any(axis=1)
    assert floor.any()
    assert np.allclose(data.contact.solref[: data.ncon][floor], [FLOOR_TIMECONST, 1.0])
    assert np.allclose(data.contact.solimp[: data.ncon][floor], FLOOR_SOLIMP)
    # a walking stance foot settles within a millimetre or two; landings stay under 1.5 cm (a
    # sole box landing on a corner: measured 12.7 mm on this walk, the capsule feet 8-10)
    touching = r.contact_penetration > 0
    assert touching.mean() > 0.8
    assert np.median(r.contact_penetration[touching]) < 2e-3
    assert r.penetration < 0.015


def test_residual_appears_only_where_assistance_was_recorded_and_recovers_it(trial_on_floor):
    """The physics room (``sim.physics``) audits simulated motion: with no help recorded its
    residual force is small; with the body walking in the air, held up by the recorded root
    assistance, its residual is that assistance frame by frame."""
    from sim.simulate.audit import assistance_audit, floor_ground
    from sim.simulate.generate import simulated_clip

    skeleton = canonical_skeleton()
    # 4x human strength, set here on purpose (no model parameter scales the human limits): at
    # human strength the legs hanging in the air saturate their torque limits and swing at
    # frequencies that 30 fps second differences do not resolve (measured 0.10 BW mean
    # residual-help gap, 0.015 at 4x): this test is about the audit, not the body
    model = sim_model(skeleton, soles=False)
    model.actuator_forcerange[:] *= 4.0
    ref = trial_on_floor(model, "02_01")[:180]  # 1.5 s: the unassisted walk has not fallen yet
    plain = {"generation": {"scale": 1.0, "pushes": []}}

    r0 = track(model, ref, assist_limit=0.0)
    assert not r0.fell and r0.assistance.max() == 0.0
    walk = simulated_clip(model, skeleton, r0.qpos, r0.qvel, 30.0, "walk")
    a0 = assistance_audit(walk, {**plain, "assistance": r0.assistance.tolist()})
    assert a0["quiet_n"] >= 30 and a0["assisted_n"] == 0
    # measured 0.02 BW mean without self-collision, 0.05 with it (a foot brushes the other shin
    # once and the unassisted gait differs); a walk the feet cannot carry leaves ~0.2-1 BW
    assert a0["residual_quiet_bw"] < 0.08
    assert np.percentile(a0["residual"][a0["quiet"]], 90) < 0.12

    # the same walk 20 cm above the floor, held by up to 3 body weights of assistance (a hand
    # that acts in flight too: the synthesis never allows it, the audit must still see it)
    lifted = ref.copy()
    lifted[:, 2] += 0.2
    r1 = track(model, lifted, assist_limit=3.0, assist_in_flight=True)
    air = simulated_clip(model, skeleton, r1.qpos, r1.qvel, 30.0, "air")
    assert air.positions[:, :, 2].min() > 0.05  # nothing touches the floor
    a1 = assistance_audit(
        air, {**plain, "assistance": r1.assistance.tolist()}, ground=floor_ground(walk)
    )
    inner = slice(4, -4)  # half a filter window from the ends
    res, help_ = a1["residual"][inner], a1["help"][inner]
    assert help_.min() > 0.5 and np.ptp(help_) > 0.05  # the help varies with the legs' swing
    # tolerance: both sides are smoothed by the same 9-frame filter, but the residual comes from
    # second differences of 30 fps positions and the help from 120 Hz samples: a few % of BW
    assert np.abs(res - help_).mean() < 0.03
    assert np.abs(res - help_).max() < 0.1


def test_tasks_name_their_trials_by_absolute_paths(cmu_dir, tmp_path, monkeypatch):
    """Tasks travel to Ray workers, which run in other folders (or machines): a --from given
    relative to the driver's folder named files no worker could find."""
    import os

    from sim.simulate.dataset import plan_tasks

    src = tmp_path / "cmu" / "02"
    src.mkdir(parents=True)
    for name in ("02.asf", "02_01.amc"):
        shutil.copy(cmu_dir / "02" / name, src / name)
    monkeypatch.chdir(tmp_path)
    tasks, skipped = plan_tasks("cmu", 2, kinds=("track",))
    assert not skipped and len(tasks) == 2
    for t in tasks:
        assert os.path.isabs(t.asf) and os.path.isabs(t.amc) and os.path.isfile(t.amc)


def test_clips_are_stored_as_they_arrive_and_a_stopped_run_resumes(tmp_path, monkeypatch):
    """Every clip is on disk (and in the journal) as soon as its task finishes: a run stopped
    at the third task keeps the first two; resumed, it simulates only the rest, and the folder
    equals an uninterrupted run's bit for bit."""
    import sim.simulate.dataset as dataset

    kw = dict(kinds=("procedural",), seconds=0.5, seed=4, workers=1, progress=False)
    whole = synthesize(None, tmp_path / "whole", 4, **kw)
    calls = []

    def stopped_at_the_third(task):
        calls.append(task.index)
        if task.index == 2:
            raise KeyboardInterrupt  # the driver stops (not a task error: nothing catches it)
        return generate(task)

    monkeypatch.setattr(dataset, "generate", stopped_at_the_third)
    with pytest.raises(KeyboardInterrupt):
        synthesize(None, tmp_path / "run", 4, **kw)
    out = tmp_path / "run"
    assert sorted(p.name for p in out.glob("procedural/*.npz")) == [
        "procedural_00000.npz", "procedural_00001.npz"
    ]  # fmt: skip
    assert not (out / "index.json").exists()
    journal = (out / dataset.JOURNAL).read_text().splitlines()
    assert [json.loads(line).get("index") for line in journal[1:]] == [0, 1]
    calls.clear()
    monkeypatch.setattr(
        dataset, "generate", lambda task: calls.append(task.index) or generate(task)
    )
    with pytest.raises(ValueError, match="other parameters"):
        synthesize(None, out, 4, resume=True, **{**kw, "seed": 5})
    resumed = synthesize(None, out, 4, resume=True, **kw)
    assert calls == [2, 3]
    assert resumed.written == whole.written
    for r in whole.written:
        a, b = _arrays(tmp_path / "whole" / r["file"]), _arrays(out / r["file"])
        assert all(np.array_equal(a[k], b[k]) for k in a)
