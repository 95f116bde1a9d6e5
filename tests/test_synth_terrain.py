"""``synth`` in the scene inferred from the trial (``sim.simulate.episode_scene``): a trial
without steps gives the episode it gave on the empty floor bit for bit; the playground climb
01_02 gets its boxes in the episode's MJCF and parameters, its reference's feet stand on them
at any time warp, and ``--flat-floor`` keeps the empty floor (recorded, and a run of the other
scene is not resumed)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from synth_replay import oracle_replay

from sim.model.humanoid import canonical_skeleton
from sim.simulate.model import CONTROL_HZ, scaled_skeleton, total_mass

SHORT = 0.5  # [s]


def _task(cmu_dir, trial: str, terrain: bool, kind: str = "track", index: int = 0):
    from sim.simulate.generate import SynthTask

    subject = trial.split("_")[0]
    asf, amc = cmu_dir / subject / f"{subject}.asf", cmu_dir / subject / f"{trial}.amc"
    return SynthTask(kind, 0, index, str(asf), str(amc), seconds=SHORT, samples=4,
                     terrain=terrain)  # fmt: skip


def test_a_trial_without_steps_gives_the_flat_floor_episode_bit_for_bit(cmu_dir):
    from sim.simulate.generate import generate

    for kind, index in (("track", 0), ("fall", 1)):
        _, inferred = generate(_task(cmu_dir, "02_01", True, kind, index))
        _, flat = generate(_task(cmu_dir, "02_01", False, kind, index))
        a, b = inferred.pop("labels"), flat.pop("labels")
        assert set(a) == set(b)
        for k in a:
            if k != "sim_generation":  # it records the scene asked for
                assert np.array_equal(a[k], b[k]), k
        assert inferred["generation"].pop("scene") == {"inferred": True, "boxes": []}
        assert flat["generation"].pop("scene") == {"inferred": False, "boxes": []}
        assert inferred == flat


def test_the_playground_climb_is_tracked_among_its_boxes_and_replays(cmu_dir):
    from sim.simulate.episode import array_text
    from sim.simulate.generate import generate
    from sim.simulate.model import human_torque_limit

    _, inferred = generate(_task(cmu_dir, "01_02", True))
    _, flat = generate(_task(cmu_dir, "01_02", False))
    scene = inferred["generation"]["scene"]
    assert scene["inferred"] and len(scene["boxes"]) >= 3  # its three platforms at least
    assert flat["generation"]["scene"] == {"inferred": False, "boxes": []}
    labels = inferred["labels"]
    mjcf = array_text(labels["sim_mjcf"])
    assert mjcf.count('name="terrain') == len(scene["boxes"]) + 1  # the body and its boxes
    assert 'name="terrain' not in array_text(flat["labels"]["sim_mjcf"])
    mass = 75.0 * inferred["generation"]["scale"] ** 3
    names = _joint_names(mjcf)
    limits = np.array([human_torque_limit(n, mass) for n in names])
    q, v, worst, model = oracle_replay(labels, limits)  # MuJoCo alone, on the stored MJCF
    assert np.array_equal(q, labels["sim_tick_qpos"]) and np.array_equal(v, labels["sim_tick_qvel"])
    assert worst <= 1 + 1e-12
    assert labels["sim_xfrc_applied"].shape[1] == model.nbody  # the scene's body included
    assert total_mass(model) == pytest.approx(mass, rel=1e-5)  # the boxes weigh nothing


def _joint_names(mjcf: str) -> list[str]:
    import mujoco

    model = mujoco.MjModel.from_xml_string(mjcf)
    return [model.actuator(i).name for i in range(model.nu)]


class _Start:
    """A stand-in for the episode's random stream that draws the window start ``start``."""

    def __init__(self, start: int):
        self.start = start

    def integers(self, low, high, size):
        assert low <= self.start < high
        return np.full(size, self.start)


@pytest.mark.parametrize("speed", [1.0, 1.5])
def test_the_reference_stands_on_the_boxes_at_any_time_warp(cmu_dir, speed):
    """A window of 01_02 around a stance on its highest platform, warped: where the sole that
    stood there is over the box its lowest point is at the box's top (the 1 cm lift, the
    sole's fit), not in it nor floating, so the ground track and the boxes follow the warped
    motion. (The other foot, a step lower, may stand within the box's footprint: the boxes are
    not carved, as in eval: ``terrain.CARVE``.)"""
    from sim.simulate.episode_body import episode_bodies
    from sim.simulate.episode_scene import placed_reference, source_window
    from sim.simulate.reference import trial_qpos
    from sim.simulate.terrain import find_terrain, foot_tracks, surface_height

    task = _task(cmu_dir, "01_02", True, "follow")
    skeleton = scaled_skeleton(canonical_skeleton(), 1.0)
    body = episode_bodies(skeleton, 1.0, 1.0)[0][0]
    trial = trial_qpos(task.asf, task.amc)
    boxes, ground = find_terrain(body, trial, CONTROL_HZ)
    high = max(boxes, key=lambda b: b.top)
    low, corners, *_ = foot_tracks(body, trial)
    over = surface_height(_geoms(boxes), corners.mean(axis=2)) == high.top  # (T, 2)
    on = over & (np.abs(low - ground[:, None] - high.top) < 0.05)
    frame, side = (int(x[0]) for x in np.nonzero(on))  # a sole on the highest platform
    n = int(SHORT * CONTROL_HZ)
    p = {"scale": 1.0, "speed": speed, "gain": 1.0, "controller": "plain"}
    start = max(0, int(frame / speed) - n // 2)
    window, track, found = source_window(task, p, body, n, _Start(start))
    assert len(found) == len(boxes) and track.shape == (n,)
    scene = episode_bodies(skeleton, 1.0, 1.0, terrain=found)[0][0]
    ref = placed_reference(task, p, body, scene, window, track)
    low, corners, *_ = foot_tracks(body, ref)  # that sole's lowest corner, and over what
    top = max(b.top for b in found)
    over = surface_height(_geoms(found), corners[:, side].mean(axis=1)) == top
    height = low[over, side] - top  # [m] above the box
    assert over.sum() >= 10
    assert np.all(height > -0.02) and np.percentile(height, 10) < 0.02  # on it, not in it


def _geoms(boxes) -> tuple:
    """``terrain_geoms``' tuple of ``boxes``."""
    return (np.arange(len(boxes)), np.array([b.top for b in boxes]),
            np.array([b.centre[:2] for b in boxes]), np.array([b.half[:2] for b in boxes]),
            np.array([b.yaw for b in boxes]))  # fmt: skip


def test_cli_flat_floor_is_recorded_and_a_run_of_the_other_scene_is_not_resumed(
    cmu_dir, tmp_path, capsys
):
    from sidql.commands.main import main

    data = tmp_path / "data" / "03"
    data.mkdir(parents=True)
    for name in ("03.asf", "03_01.amc"):  # a trial with steps
        shutil.copy(cmu_dir / "03" / name, data / name)
    args = ["synth", "--data", str(tmp_path / "data"), "--n", "1", "--kinds", "follow",
            "--controller", "plain", "--seconds", "0.25", "--workers", "1", "--quiet"]  # fmt: skip
    runs = {}
    for flag in ([], ["--flat-floor"]):
        out = tmp_path / f"out{len(flag)}"
        assert main([*args, *flag, "--out", str(out)]) == 0
        index = json.loads((out / "index.json").read_text())
        (entry,) = index["trials"]
        runs[bool(flag)] = index["synthetic"].get("terrain"), entry["generation"]["scene"]
        assert entry["task"].get("terrain", False) is not bool(flag)
    assert runs[False][0] is True and runs[False][1]["inferred"] and runs[False][1]["boxes"]
    assert runs[True] == (False, {"inferred": False, "boxes": []})
    capsys.readouterr()
    assert main([*args, "--out", str(tmp_path / "out1"), "--resume"]) == 2  # flat, resumed inferred
    assert "other parameters" in capsys.readouterr().err
