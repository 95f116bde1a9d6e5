"""The replay oracle of synthetic episodes (shared by the synth tests): MuJoCo alone steps the
stored actions and wrenches on the stored MJCF's model from the stored first state."""

from __future__ import annotations

import json

import mujoco
import numpy as np

from sim.model.mass import DEFAULT_BODY_MASS_KG
from sim.motion.clip import load_extra, load_npz
from sim.simulate.episode import array_text
from sim.simulate.model import human_torque_limit

REAL = ("track", "fall", "follow")
PER_KIND = 20
SECONDS = 1.0  # long enough for the pushes of track (from 0.3 s) and many of fall (0.5-1.5 s)


def oracle_replay(labels: dict, limits: np.ndarray):
    """Step the stored actions and wrenches one physics step at a time on the stored MJCF's
    model (MuJoCo alone, nothing of ours), each tick's stored PD gains (``sim_actuator_gains``:
    kp, kv) written into its position actuators first; return the states before each action
    and after the last, and the largest |hinge actuator torque| over its limit seen at any
    step."""
    model = mujoco.MjModel.from_xml_string(array_text(labels["sim_mjcf"]))
    data = mujoco.MjData(model)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    mujoco.mj_setState(model, data, labels["sim_initial_state"], spec)
    actions = labels["sim_actions"]
    gains = labels.get("sim_actuator_gains")
    limit_range = model.actuator_forcerange.copy()
    qpos, qvel, worst = [], [], 0.0
    for k in range(len(actions)):
        qpos.append(data.qpos.copy())
        qvel.append(data.qvel.copy())
        if gains is not None:  # MuJoCo's position servo: gain kp, bias (0, -kp, -kv)
            model.actuator_gainprm[:, 0] = gains[k, 0]
            model.actuator_biasprm[:, 1] = -gains[k, 0]
            model.actuator_biasprm[:, 2] = -gains[k, 1]
        data.ctrl[:] = actions[k]
        data.xfrc_applied[:] = labels["sim_xfrc_applied"][k]
        data.qfrc_applied[:] = labels["sim_qfrc_applied"][k]
        for _ in range(int(labels["sim_frame_skip"])):
            mujoco.mj_step(model, data)
            worst = max(worst, float(np.max(np.abs(data.actuator_force) / limits)))
    qpos.append(data.qpos.copy())
    qvel.append(data.qvel.copy())
    assert np.array_equal(model.actuator_forcerange, limit_range)  # no gain moves a limit
    return np.array(qpos), np.array(qvel), worst, model


def _scene_in_mjcf(generation: dict, model) -> bool:
    """Whether the episode's scene has steps; its MJCF's static boxes ``terrain<k>`` are the
    ones its parameters record (``scene``), on a body whose mass they do not add to."""
    boxes = generation["scene"]["boxes"]
    names = [model.geom(g).name for g in range(model.ngeom)]
    ids = [g for g, name in enumerate(names) if name.startswith("terrain")]
    assert len(ids) == len(boxes)
    assert not boxes or generation["scene"]["inferred"]
    for g, b in zip(ids, boxes, strict=True):
        assert model.geom_bodyid[g] == model.nbody - 1 and model.body_mass[-1] == 0.0
        assert np.allclose(model.geom_pos[g], b["centre"], atol=1e-5)
        assert np.allclose(model.geom_size[g], b["half"], atol=1e-5)
        assert np.isclose(2 * np.arctan2(model.geom_quat[g, 3], model.geom_quat[g, 0]), b["yaw"],
                          atol=1e-5)  # fmt: skip
    return bool(boxes)


def check_replays(out, written, kinds) -> dict:
    """Every clip of ``written`` replays bit for bit within the human limits (the assertions
    below); returns counts of what the clips held."""
    count = {k: 0 for k in kinds} | {"pushed": 0, "assisted": 0, "strong": 0, "weakened": 0,
                                     "switched": 0, "stepped": 0}  # fmt: skip
    for r in written:
        path = out / r["file"]
        labels, clip = load_extra(path, "sim_"), load_npz(path)
        generation = json.loads(array_text(labels["sim_generation"]))
        assert generation == r["generation"]  # the episode carries its own parameters
        mass = DEFAULT_BODY_MASS_KG * generation["scale"] ** 3
        names = clip.joint_names
        limits = np.array([human_torque_limit(n, mass) for n in names])
        q, v, worst, model = oracle_replay(labels, limits)
        assert np.array_equal(q, labels["sim_tick_qpos"]), r["file"]
        assert np.array_equal(v, labels["sim_tick_qvel"]), r["file"]
        T = len(labels["sim_actions"])
        assert T == round(SECONDS * 120) and int(labels["sim_frame_skip"]) == 4
        assert np.array_equal(q[: 4 * clip.n_frames : 4], clip.qpos)  # the clip's frames
        # human strength: the body's limits are the table's (never times a gain), and no
        # physics step of the replay applied more
        assert [model.actuator(i).name for i in range(model.nu)] == list(names)
        body = model.actuator_forcerange[:, 1]  # (the MJCF's 6 digits, rounded down)
        assert np.all(body <= limits) and np.all(body >= limits * (1 - 1e-5))
        assert np.array_equal(labels["sim_torque_limit"], model.actuator_forcerange[:, 1])
        assert worst <= 1 + 1e-12
        lo, hi = model.actuator_ctrlrange.T  # actions in the documented, bounded space
        assert np.all((labels["sim_actions"] >= lo) & (labels["sim_actions"] <= hi))
        gains = labels.get("sim_actuator_gains")
        if model.actuator_biasprm[:, 1].any():  # position actuators: gains at every tick
            assert gains.shape == (T, 2, model.nu) and np.all(gains > 0)
            sets = np.unique(gains.reshape(T, -1), axis=0)
            choice = generation.get("sampling", {}).get("gain_choice")
            assert len(sets) <= (2 if choice else 1)  # the body's gains, or the two sets
            if len(sets) == 1:  # the MJCF's own (its model as compiled, before any replay)
                body = mujoco.MjModel.from_xml_string(array_text(labels["sim_mjcf"]))
                assert np.array_equal(sets[0][: model.nu], body.actuator_gainprm[:, 0])
                assert np.array_equal(sets[0][model.nu :], -body.actuator_biasprm[:, 2])
            count["switched"] += len(sets) > 1
        else:
            assert gains is None
        # no help unless asked for: only the procedural kind asks (and is labelled so)
        helped = bool(np.any(labels["sim_qfrc_applied"]))
        assert (generation["assist_limit"] > 0) == (r["subject"] == "procedural")
        assert not helped or generation["assist_limit"] > 0
        count[r["subject"]] += 1
        count["pushed"] += bool(np.any(labels["sim_xfrc_applied"]))
        count["assisted"] += helped
        count["strong"] += generation["gain"] > 1.2
        count["weakened"] += any(w["start"] < SECONDS - 0.1 for w in generation["weakenings"])
        count["stepped"] += _scene_in_mjcf(generation, model)
    assert all(count[k] >= PER_KIND for k in kinds), count
    seeds = [r["generation"]["seed"] for r in written]
    assert len(set(seeds)) == len(seeds)  # a seed per episode, not the run's
    return count
