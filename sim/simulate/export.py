"""Simulated clips as an offline-RL / imitation-learning dataset: one HDF5 file (``h5py``).

The layout follows Minari's (Farama) episode layout, so loaders written for it need only the
path changes; every array of a clip keeps its frame axis first:

``/`` attributes: ``format`` = ``"sidql-sim-episodes"``, ``version`` = 1, ``fps`` [Hz],
``joint_names`` (U,) the hinges in action order, ``point_names`` (P,), ``total_episodes``.

``/episode_<k>/`` (k = 0, 1, ... in the dataset index's order), attributes ``id`` (k), ``file``
(the clip file in the dataset folder), ``kind``, ``seed``, ``mean_assistance`` [body weight],
``physical``, ``fell``, ``fall_frame`` (-1: none), ``total_steps`` (F - 1), and

* ``observations/qpos`` (F, nq), ``observations/qvel`` (F, nv): the simulator's state (root
  position [m], quaternion wxyz, hinge angles [rad]; velocities [m/s, rad/s]);
  ``observations/positions`` (F, P, 3) and ``observations/velocities`` (F, P, 3): points [m],
  their velocities [m/s] (world frame, z up);
* ``actions`` (F - 1, U): actuator controls (target angles [rad], feed-forward included) set at
  frame ``t`` and held until ``t + 1``: the transition ``observations[t] -> observations[t + 1]``;
* ``rewards`` (F - 1,): zeros (imitation data carries no reward); ``terminations`` (F - 1,): true
  from the transition reaching the fall frame on (the figure is down), ``truncations`` (F - 1,):
  true at the last transition of a clip that did not fall (the clip ends, the motion does not);
* ``infos/joint_torque`` (F, U) [N m], ``infos/assist_wrench`` (F, 6) (force [N] world frame,
  torque [N m] root frame), ``infos/foot_contact`` (F, 2) bool (left, right),
  ``infos/foot_force`` (F, 2, 3) [N, world frame]: per frame, like Minari's ``infos``.
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from sim.errors import MotionDataError
from sim.files import write_atomic
from sim.motion.clip import load_extra, load_npz
from sim.motion.dataset import entry_file, read_index

FORMAT = "sidql-sim-episodes"
_INFOS = ("joint_torque", "assist_wrench", "foot_contact", "foot_force")


def export_hdf5(
    dataset_dir: str | os.PathLike, out: str | os.PathLike, *, physical_only: bool = False
) -> int:
    """Write the clips of the ``synth`` folder ``dataset_dir`` (its ``index.json`` and clip files
    with their ``sim_*`` labels) to the HDF5 file ``out`` atomically (layout: module docstring).

    Args:
        physical_only: only the clips whose index entry says ``physical``.

    Returns:
        the number of episodes written.

    Raises:
        MotionDataError: the index or a clip file is unreadable or a clip has no labels.
    """
    root = Path(dataset_dir)
    index = read_index(root / "index.json")  # bounded, regular file; MotionDataError otherwise
    chosen = [i for i, r in enumerate(index["trials"]) if r.get("physical") or not physical_only]
    trials = [index["trials"][i] for i in chosen]
    episodes = []
    for i, r in zip(chosen, trials, strict=True):
        file = entry_file(root, index, i)  # relative, inside the folder
        clip = load_npz(file)
        labels = load_extra(file, "sim_")
        if "sim_actions" not in labels:
            raise MotionDataError(str(file), None, "no sim_ labels: not a synth clip")
        episodes.append((r, clip, labels))
    if not episodes and trials:
        raise MotionDataError(str(root), None, "no clip to export")

    def write(f) -> None:
        with h5py.File(f, "w") as h:
            h.attrs["format"] = FORMAT
            h.attrs["version"] = 1
            h.attrs["fps"] = float(index.get("fps", 30.0))
            h.attrs["total_episodes"] = len(episodes)
            if episodes:
                h.attrs["joint_names"] = list(episodes[0][1].joint_names)
                h.attrs["point_names"] = list(episodes[0][1].names)
            for k, (r, clip, labels) in enumerate(episodes):
                g = h.create_group(f"episode_{k}")
                F = clip.n_frames
                fall = int(r.get("fall_frame", -1))
                g.attrs.update(
                    id=k, file=r["file"], kind=r["subject"], seed=int(r["task"]["seed"]),
                    mean_assistance=float(r["mean_assistance"]), physical=bool(r["physical"]),
                    fell=bool(r["fell"]), fall_frame=fall, total_steps=F - 1,
                )  # fmt: skip
                obs = g.create_group("observations")
                for name in ("qpos", "qvel", "positions", "velocities"):
                    obs.create_dataset(name, data=getattr(clip, name), compression="gzip")
                g.create_dataset("actions", data=labels["sim_actions"][: F - 1])
                g.create_dataset("rewards", data=np.zeros(F - 1))
                term = np.zeros(F - 1, dtype=bool)
                if fall >= 1:
                    term[fall - 1 :] = True
                trunc = np.zeros(F - 1, dtype=bool)
                if fall < 0 and F > 1:
                    trunc[-1] = True
                g.create_dataset("terminations", data=term)
                g.create_dataset("truncations", data=trunc)
                infos = g.create_group("infos")
                for name in _INFOS:
                    infos.create_dataset(name, data=labels[f"sim_{name}"], compression="gzip")

    write_atomic(Path(out), write)
    return len(episodes)


def load_hdf5(path: str | os.PathLike) -> list[dict]:
    """The episodes of a file written by :func:`export_hdf5`: per episode a dict of its
    attributes plus ``observations`` (dict), ``actions``, ``rewards``, ``terminations``,
    ``truncations`` and ``infos`` (dict), as numpy arrays."""
    out = []
    try:
        with h5py.File(path, "r") as h:
            if h.attrs.get("format") != FORMAT:
                raise MotionDataError(str(path), None, f"not a {FORMAT} file")
            for k in range(int(h.attrs["total_episodes"])):
                g = h[f"episode_{k}"]
                ep = {a: g.attrs[a] for a in g.attrs}
                ep["observations"] = {n: g["observations"][n][()] for n in g["observations"]}
                ep["infos"] = {n: g["infos"][n][()] for n in g["infos"]}
                for n in ("actions", "rewards", "terminations", "truncations"):
                    ep[n] = g[n][()]
                out.append(ep)
    except OSError as e:
        raise MotionDataError(str(path), None, f"not an HDF5 file: {e}") from e
    return out
