"""Simulated clips as a Minari dataset (Farama's offline-RL format), written with ``h5py`` alone.

``export_minari(synth_dir, root, dataset_id)`` writes what ``minari.load_dataset(dataset_id)``
loads with ``MINARI_DATASETS_PATH=root`` (Minari 0.5's HDF5 storage, as its own
``DataCollector`` writes it):

``root/<dataset_id>/data/main_data.hdf5``, one group ``episode_<k>`` per clip (k = 0, 1, ... in
the ``synth`` index's order), an episode of N steps being the control ticks up to the fall (or
the whole clip):

* ``observations/qpos`` (N + 1, nq), ``observations/qvel`` (N + 1, nv): the simulator's state
  before each step and after the last (root position [m], quaternion wxyz, hinge angles [rad];
  velocities [m/s, rad/s], z up);
* ``actions``: the action of each step. With position actuators (plain and sampling trackers)
  (N, 3 U) variable-impedance actions (``sim.simulate.episode.impedance_actions``): the hinges'
  PD targets [rad] (feed-forward folded in, inside each actuator's control range,
  ``sim.simulate.model.sim_spec``), then each actuator's ``kp`` [N m/rad] and ``kv`` [N m s/rad]
  of the step (the gain set the controller chose: ``sim_actuator_gains``); with torque
  actuators (the whole-body QP) (N, U) their torques [N m] (the torque that acts,
  ``sim.simulate.episode.Recorder``); one kind per dataset (metadata ``actions``);
* ``rewards`` (N,): zeros (imitation data); ``terminations`` (N,): True only at the last step
  of an episode that ends in a fall (the state it reaches is the first fallen one);
  ``truncations`` (N,): True only at the last step of one that does not (the clip's length);
* ``infos/xfrc_applied`` (N + 1, B, 6) and ``infos/qfrc_applied`` (N + 1, nv): entry ``t + 1``
  is the wrench applied during step ``t`` (pushes on bodies, world frame [N, N m]; root
  assistance [N, N m]), entry 0 zeros (Minari's infos: one at reset, one per step);
* attributes: ``id``, ``seed`` (the episode's own), ``total_steps`` and, read back by
  ``episode.metadata`` (``dataset.storage.get_episode_metadata``): ``kind``, ``file``,
  ``mjcf`` (its body), ``frame_skip``, ``initial_state`` (``mj_getState`` with
  ``mjSTATE_INTEGRATION``), ``torque_limit`` (U,) [N m], ``generation`` (JSON of its
  parameters: scale, gain, pushes, ...), ``fell``, ``fall_tick``, ``physical``,
  ``mean_assistance``.

``root/<dataset_id>/data/metadata.json`` (written last): Minari's keys (``dataset_id``,
``minari_version``, ``data_format``, ``total_episodes``, ``total_steps``, the serialised
``observation_space`` (a Dict of two Boxes) and ``action_space`` (a Box spanning every episode's
control range and, for variable-impedance actions, every gain seen)) plus ``frame_skip``,
``joint_names``, ``actions`` (what an action is), ``action_layout`` (its columns), the
unscaled body's ``mjcf`` on the empty floor and its ``torque_limit`` (U,) [N m] (an episode of
another body size, or in a scene with inferred steps, carries its own ``mjcf``: replay each
episode on its own), and ``scenes``: what ``mjcf`` is, and how many episodes carry steps
(their MJCF's static boxes ``terrain<k>``, their ``xfrc_applied`` one body wider;
``sim.simulate.episode_scene``).

Replaying an episode: ``targets, gains = sim.simulate.episode.split_actions(actions)`` (torque
actions: ``actions``, ``None``), then ``replay(mjcf, initial_state, targets,
infos["xfrc_applied"][1:], infos["qfrc_applied"][1:], frame_skip, gains)`` gives back its
observations bit for bit.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import h5py
import mujoco
import numpy as np

from sim.errors import MotionDataError
from sim.files import write_atomic
from sim.model.humanoid import canonical_skeleton
from sim.motion.clip import load_extra
from sim.motion.dataset import entry_file, read_index
from sim.simulate.episode import array_text, impedance_actions, is_position, pd_gains, torque_limits
from sim.simulate.episode_body import episode_model
from sim.simulate.generate import EPISODE_LABELS
from sim.simulate.terrain import terrain_geoms

#: the episode labels only a body of position actuators has
POSITION_LABELS = ("sim_actuator_gains",)
#: what an action is, per kind of actuators (metadata ``actions``), and its columns, U each
ACTIONS = {
    "motor": "torque [N m] per actuator",
    "position": "variable impedance: PD target [rad], kp [N m/rad], kv [N m s/rad] per actuator",
}
LAYOUT = {"motor": ("torque",), "position": ("target", "kp", "kv")}

MINARI_VERSION = "0.5.4"  # the dataset format written (Minari's supported_dataset_versions)
DEFAULT_ID = "sidql/synth-v0"
# Minari's dataset id: (namespace/)name-v(version); no dots, so no path leaves the root
DATASET_ID = re.compile(r"^(?:[-_\w][-_\w/]*[-_\w]+/)?[-_\w]+?-v\d+$")


def episode_steps(labels: dict) -> int:
    """N, the steps of a clip's episode: its control ticks up to the first fallen state, or
    all of them."""
    T = len(labels["sim_actions"])
    fall = int(labels["sim_fall_tick"])
    return fall if 0 < fall < T else T


def _box(low, high) -> dict:
    low, high = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    return {"type": "Box", "dtype": "float64", "shape": list(low.shape),
            "low": low.tolist(), "high": high.tolist()}  # fmt: skip


def episode_actions(labels: dict, model) -> np.ndarray:
    """(T, 3 U) the variable-impedance actions of a clip's episode (its ``sim_`` ``labels``) on
    a body of position actuators ``model`` (its MJCF's; the MJCF's gains at every tick where
    the clip has no ``sim_actuator_gains``), or (T, U) the torques of torque actuators."""
    actions = labels["sim_actions"]
    if not is_position(model):
        return actions
    gains = labels.get("sim_actuator_gains")
    if gains is None:
        gains = np.broadcast_to(pd_gains(model), (len(actions), 2, model.nu))
    return impedance_actions(actions, gains)


def _write_episode(h, k: int, r: dict, labels: dict) -> tuple[int, np.ndarray, str, bool]:
    """Write clip ``r`` (its index entry, its ``sim_`` labels) as ``episode_<k>``; returns its
    step count, its action box (2, A) (lowest and highest: the control range, and the gains
    of its steps), its actuators (:func:`_actuators`; from its MJCF's model) and whether its
    scene has steps (``terrain`` geoms in its MJCF)."""
    missing = set(EPISODE_LABELS) - set(POSITION_LABELS) - set(labels)
    if missing:
        raise MotionDataError(r["file"], None, f"no {min(missing)}: not a synth episode")
    model = mujoco.MjModel.from_xml_string(array_text(labels["sim_mjcf"]))
    N = episode_steps(labels)
    fell = 0 < int(labels["sim_fall_tick"]) <= N
    g = h.create_group(f"episode_{k}")
    obs = g.create_group("observations")
    obs.create_dataset("qpos", data=labels["sim_tick_qpos"][: N + 1])
    obs.create_dataset("qvel", data=labels["sim_tick_qvel"][: N + 1])
    actions = episode_actions(labels, model)[:N]
    g.create_dataset("actions", data=actions)
    g.create_dataset("rewards", data=np.zeros(N))
    end = np.zeros(N, dtype=bool)
    end[-1] = True
    g.create_dataset("terminations", data=end & fell)
    g.create_dataset("truncations", data=end & (not fell))
    infos = g.create_group("infos")
    for name in ("xfrc_applied", "qfrc_applied"):
        x = labels[f"sim_{name}"][:N]
        infos.create_dataset(
            name, data=np.concatenate([np.zeros_like(x[:1]), x]), compression="gzip"
        )
    generation = json.loads(array_text(labels["sim_generation"]))
    g.attrs.update(
        id=k, seed=int(generation["seed"]), total_steps=N, kind=r["subject"], file=r["file"],
        mjcf=array_text(labels["sim_mjcf"]), frame_skip=int(labels["sim_frame_skip"]),
        initial_state=labels["sim_initial_state"], torque_limit=labels["sim_torque_limit"],
        generation=array_text(labels["sim_generation"]), fell=fell,
        fall_tick=int(labels["sim_fall_tick"]), physical=bool(r.get("physical", False)),
        mean_assistance=float(r.get("mean_assistance", 0.0)),
    )  # fmt: skip
    lo, hi = model.actuator_ctrlrange.T
    if actions.shape[1] > model.nu:  # the gains' columns: the lowest and highest seen
        lo, hi = np.r_[lo, actions[:, model.nu :].min(0)], np.r_[hi, actions[:, model.nu :].max(0)]
    return N, np.stack([lo, hi]), _actuators(model), terrain_geoms(model) is not None


def _actuators(model) -> str:
    """``"motor"`` (torque actuators: the action is a torque [N m]) or ``"position"`` (PD
    servos: the action is a target angle [rad]), as ``sim.simulate.model.sim_spec`` names them."""
    return "position" if is_position(model) else "motor"


def _metadata(dataset_id: str, labels: dict, steps: list, ranges: np.ndarray, actuators: str,
              stepped: int):  # fmt: skip
    """``metadata.json``'s content (module docstring): ``labels`` of the first episode,
    ``steps`` per episode, ``ranges`` (E, 2, A) their action boxes, ``actuators`` their kind,
    ``stepped`` how many of them are in a scene with steps."""
    model, mjcf, _ = episode_model(canonical_skeleton(), 1.0, 1.0, actuators)
    nq, nv = labels["sim_tick_qpos"].shape[1], labels["sim_tick_qvel"].shape[1]
    inf = np.full(nq, np.inf)
    return {
        "dataset_id": dataset_id,
        "minari_version": MINARI_VERSION,
        "data_format": "hdf5",
        "jpeg_encoding": False,
        "total_episodes": len(steps),
        "total_steps": int(sum(steps)),
        "observation_space": json.dumps(
            {
                "type": "Dict",
                "subspaces": {"qpos": _box(-inf, inf), "qvel": _box(-inf[:nv], inf[:nv])},
            }
        ),  # fmt: skip
        "action_space": json.dumps(_box(ranges[:, 0].min(0), ranges[:, 1].max(0))),
        "description": "sidql synth: simulated humanoid clips (docs/synthetic.md)",
        "frame_skip": int(labels["sim_frame_skip"]),
        "joint_names": [model.actuator(a).name for a in range(model.nu)],
        "mjcf": mjcf,
        "torque_limit": torque_limits(model).tolist(),
        "scenes": f"mjcf: the unscaled body on the empty floor; {stepped} of {len(steps)} "
        "episodes carry steps inferred from their trial (static boxes terrain<k>) in their own "
        "mjcf, every episode its own body",
        "actions": ACTIONS[actuators],
        "action_layout": {
            name: [i * model.nu, (i + 1) * model.nu] for i, name in enumerate(LAYOUT[actuators])
        },  # fmt: skip
    }


def export_minari(
    dataset_dir: str | os.PathLike,
    root: str | os.PathLike,
    dataset_id: str = DEFAULT_ID,
    *,
    physical_only: bool = False,
) -> int:
    """Write the clips of the ``synth`` folder ``dataset_dir`` (its ``index.json`` and clip
    files with their ``sim_`` labels) as the Minari dataset ``dataset_id`` under ``root``
    (layout: module docstring); each file atomically through ``sim.files.write_atomic`` (no
    link below ``root`` followed), ``metadata.json`` last.

    Args:
        physical_only: only the clips whose index entry says ``physical``.

    Returns:
        the number of episodes written.

    Raises:
        MotionDataError: the index or a clip file is unreadable, a clip has no episode labels,
            or ``dataset_id`` is not a Minari id (``name-v0``, ``namespace/name-v0``).
        OutputError: a link below ``root``, or a target that is not a regular file.
    """
    if not DATASET_ID.match(dataset_id):
        raise MotionDataError(
            None, None, f"dataset id {dataset_id!r}: expected (namespace/)name-v<version>"
        )
    src = Path(dataset_dir)
    index = read_index(src / "index.json")  # bounded, regular file; MotionDataError otherwise
    chosen = [i for i, r in enumerate(index["trials"]) if r.get("physical") or not physical_only]
    if not chosen:
        raise MotionDataError(str(src), None, "no clip to export")
    files = [(index["trials"][i], entry_file(src, index, i)) for i in chosen]  # inside src
    root = Path(root)
    out = root / dataset_id / "data"  # made by the writer below root, through no link
    steps, ranges, kinds, stepped = [], [], set(), []

    def write(f) -> None:
        with h5py.File(f, "w", track_order=True) as h:
            for k, (r, file) in enumerate(files):
                n, rng, actuators, scene = _write_episode(h, k, r, load_extra(file, "sim_"))
                steps.append(n)
                stepped.append(scene)
                ranges.append(rng)
                kinds.add(actuators)
                if len(kinds) > 1:  # one action space per dataset
                    raise MotionDataError(str(file), None, "torque and PD-target actions in one "
                                          "folder: export the controllers' clips apart")  # fmt: skip

    write_atomic(out / "main_data.hdf5", write, root=root)
    (actuators,) = kinds
    metadata = _metadata(dataset_id, load_extra(files[0][1], "sim_"), steps, np.stack(ranges),
                         actuators, sum(stepped))  # fmt: skip
    text = json.dumps(metadata, indent=1).encode()
    write_atomic(out / "metadata.json", lambda f: f.write(text), root=root)
    return len(files)
