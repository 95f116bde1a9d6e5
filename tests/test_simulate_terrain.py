"""The scene inferred from the motion (``sim.simulate.terrain``): a box under a foot that stands
on a known step, none under a foot held still in the air nor on flat walks; the ground not pulled
up by the step; terrain is floor for the fall rule; a clip without terrain runs bit for bit as
without the option."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sim.model.humanoid import canonical_skeleton
from sim.simulate import tracking
from sim.simulate.falls import fall_cause, fall_reference, geom_bottoms
from sim.simulate.model import CONTROL_HZ, sim_model, sim_spec, total_mass
from sim.simulate.reference import floor_track, lowest_foot_point
from sim.simulate.terrain import (
    CLEAR,
    DROP,
    Box,
    carve,
    find_terrain,
    foot_tracks,
    merge_boxes,
    scene_model,
    surface_height,
    terrain_geoms,
)

STEP = 0.30  # [m] the synthetic step's height


@pytest.fixture(scope="module")
def spec():
    return sim_spec(canonical_skeleton())


@pytest.fixture(scope="module")
def model(spec):
    return spec.compile()


def _standing(model) -> np.ndarray:
    """(nq,) the rest pose stood upright, legs together (the ASF's rest pose spreads them 20
    deg), its lowest geom at z = 0."""
    data = mujoco.MjData(model)
    q = model.qpos0.copy()
    q[3:7] = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]  # the skeleton's y up to z up
    for joint, angle in (("lfemur_rz", -0.35), ("rfemur_rz", 0.35)):
        q[model.jnt_qposadr[model.joint(joint).id]] += angle
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    q[2] -= geom_bottoms(model, data)[1:].min()
    return q


def _step_up(model, rate=CONTROL_HZ) -> np.ndarray:
    """(T, nq) 1.5 s standing on the floor, then 1.5 s standing on a step :data:`STEP` high."""
    q = _standing(model)
    n = int(1.5 * rate)
    out = np.repeat(q[None], 2 * n, axis=0)
    out[n:, 2] += STEP
    return out


def test_a_step_stood_on_gets_a_box_at_its_height_and_the_ground_stays_down(model):
    motion = _step_up(model)
    boxes, ground = find_terrain(model, motion, CONTROL_HZ)
    assert boxes, "the step was not found"
    for b in boxes:
        assert b.top == pytest.approx(STEP, abs=0.01)
    _, corners, _, _, _ = foot_tracks(model, motion[-1:])
    for f in range(2):  # each sole stands inside a box (its footprint's centre)
        assert surface_height(_as_terrain(boxes), corners[0, f].mean(axis=0)) == pytest.approx(
            STEP, abs=0.01
        )
    assert np.abs(ground).max() < 0.01  # the floor where the feet stood, not the step
    assert floor_track(model, motion, CONTROL_HZ)[-1] > 0.1  # the plain track is pulled up


def test_a_foot_held_still_in_the_air_gets_no_pedestal(model):
    q = _standing(model)
    n = int(0.6 * CONTROL_HZ)
    motion = np.repeat(q[None], 3 * n, axis=0)
    hip = model.jnt_qposadr[model.joint("lfemur_rx").id]
    knee = model.jnt_qposadr[model.joint("ltibia_rx").id]
    motion[n:, hip] -= 1.2  # the left thigh raised forward and held (a held kick)
    motion[n:, knee] += 0.3
    low, _, _, _, _ = foot_tracks(model, motion)
    assert low[-1, 0] > 0.2 and low[-1, 1] < 0.01  # the left foot high and still, the right down
    assert find_terrain(model, motion, CONTROL_HZ) == ([], None)


def test_a_motion_without_soles_or_stance_finds_nothing(model):
    plain = sim_model(canonical_skeleton(), soles=False)
    assert find_terrain(plain, _step_up(plain), CONTROL_HZ) == ([], None)
    still = np.repeat(_standing(model)[None], 120, axis=0)  # one level only: the ground
    assert find_terrain(model, still, CONTROL_HZ) == ([], None)


def _as_terrain(boxes):
    tops = np.array([b.top for b in boxes])
    centres = np.array([b.centre[:2] for b in boxes])
    halves = np.array([b.half[:2] for b in boxes])
    return None, tops, centres, halves, np.array([b.yaw for b in boxes])


def test_surface_height_of_a_turned_box():
    box = Box(np.array([1.0, 2.0, 0.1]), np.array([0.4, 0.1, 0.2]), np.pi / 2)  # long along y
    terrain = _as_terrain([box])
    xy = np.array([[1.0, 2.35], [1.35, 2.0], [1.0, 2.0], [0.0, 0.0]])
    np.testing.assert_allclose(surface_height(terrain, xy), [0.3, 0.0, 0.3, 0.0])
    assert surface_height(None, xy).tolist() == [0.0] * 4


def test_boxes_of_one_height_that_overlap_merge_and_others_do_not():
    a = Box(np.array([0.0, 0.0, 0.1]), np.array([0.2, 0.1, 0.2]), 0.0)
    b = Box(np.array([0.3, 0.0, 0.11]), np.array([0.2, 0.1, 0.21]), 0.0)  # overlaps a, 2 cm up
    c = Box(np.array([0.3, 0.0, 0.3]), np.array([0.2, 0.1, 0.4]), 0.0)  # overlaps, 0.4 m up
    d = Box(np.array([2.0, 0.0, 0.1]), np.array([0.2, 0.1, 0.2]), 0.0)  # far away
    merged = merge_boxes([a, b, c, d])
    assert len(merged) == 3
    one = merged[0]
    assert one.top == pytest.approx(0.31, abs=1e-9)
    np.testing.assert_allclose(one.centre[:2], [0.15, 0.0], atol=1e-9)
    np.testing.assert_allclose(one.half[:2], [0.35, 0.1], atol=1e-9)


def test_a_box_leaves_free_where_the_feet_were_below_its_top():
    box = Box(np.array([0.0, 0.0, 0.1]), np.array([0.3, 0.2, 0.2]), 0.0)  # top 0.3, x -0.3..0.3
    core = [np.array([[-0.1, -0.05], [0.1, 0.05]])]  # the stance on it
    # a foot on the floor beside it at x = 0.2 (outside the stance): that side is cut back
    cut = carve(box, core, np.array([[0.2, 0.0]]), np.array([0.0]))
    assert cut.centre[0] + cut.half[0] == pytest.approx(0.2 - CLEAR)
    assert cut.centre[0] - cut.half[0] == pytest.approx(-0.3)
    assert cut.centre[2] - cut.half[2] == pytest.approx(box.centre[2] - box.half[2])  # solid
    # a foot under the stance (a lower rung, 0.1 m up): the box becomes a rung above it
    rung = carve(box, core, np.array([[0.0, 0.0]]), np.array([0.1]))
    assert rung.top == pytest.approx(0.3) and rung.half[:2] == pytest.approx(box.half[:2])
    assert rung.centre[2] - rung.half[2] == pytest.approx(0.1 + CLEAR)
    thin = carve(box, core, np.array([[0.0, 0.0]]), np.array([0.3 - DROP - 0.01]))
    assert 2 * thin.half[2] == pytest.approx(DROP + 0.01 - CLEAR)
    # a foot on it (less than DROP below its top) changes nothing
    same = carve(box, core, np.array([[0.2, 0.0]]), np.array([0.3 - DROP + 0.01]))
    np.testing.assert_allclose([*same.centre, *same.half], [*box.centre, *box.half])


def test_the_scene_adds_boxes_without_changing_the_body(spec, model):
    box = Box(np.array([0.5, 0.0, 0.1]), np.array([0.2, 0.15, 0.2]), 0.3)
    scene = scene_model(spec, [box])
    assert scene.ngeom == model.ngeom + 1 and terrain_geoms(model) is None
    ids, tops, centres, halves, yaws = terrain_geoms(scene)
    assert tops == pytest.approx([0.3]) and yaws == pytest.approx([0.3])
    np.testing.assert_allclose(centres, [[0.5, 0.0]])
    for field in ("body_mass", "geom_size", "actuator_gainprm", "dof_armature", "jnt_range"):
        np.testing.assert_array_equal(getattr(scene, field)[: getattr(model, field).shape[0]],
                                      getattr(model, field))  # fmt: skip
    assert np.array_equal(scene.geom_size[: model.ngeom], model.geom_size)
    # the box is the world's: the body's mass and centre of mass, which the balance feedback's
    # gains scale with, are the body's (a 0.12 m^3 box of density 1000 would weigh 120 kg)
    assert scene.body_mass[-1] == 0.0 and total_mass(scene) == total_mass(model)
    data, body = mujoco.MjData(scene), mujoco.MjData(model)
    for m, d in ((scene, data), (model, body)):
        mujoco.mj_forward(m, d)
    assert np.array_equal(data.subtree_com[0], body.subtree_com[0])
    assert np.array_equal(tracking.floor_ids(scene), [scene.geom("floor").id, *ids])


def test_a_sole_on_a_step_is_at_zero_above_it(spec, model):
    q = _standing(model)
    q[2] += STEP
    _, corners, _, _, _ = foot_tracks(model, q[None])
    centre = corners[0].reshape(-1, 2).mean(axis=0)
    box = Box(np.array([*centre, 0.5 * (STEP - 0.1)]), np.array([0.4, 0.4, 0.5 * (STEP + 0.1)]), 0)
    scene = scene_model(spec, [box])
    assert lowest_foot_point(model, q[None])[0] == pytest.approx(STEP, abs=0.01)
    assert lowest_foot_point(scene, q[None])[0] == pytest.approx(0.0, abs=0.01)
    # skating counts the soles on the step as in contact (still: 0 mm/s), not as in the air
    from sim.simulate.validate import ForwardValidation

    fv = ForwardValidation(model, ("root",), controller="plain")
    still = np.repeat(q[None], 10, axis=0)
    assert fv.skating(still, 30.0) is None
    assert fv.skating(still, 30.0, terrain_geoms(scene)) == pytest.approx(0.0, abs=1e-9)


def test_a_hand_on_a_step_is_a_fall_unless_the_reference_has_it_there(spec, model):
    stand = _standing(model)
    data = mujoco.MjData(model)
    data.qpos[:] = stand
    mujoco.mj_kinematics(model, data)
    hand = model.geom("lhand").id
    top = geom_bottoms(model, data)[hand] + 0.005  # the hand 5 mm into the step's top
    xy = data.geom_xpos[hand, :2]
    box = Box(np.array([*xy, 0.5 * (top - 0.1)]), np.array([0.03, 0.03, 0.5 * (top + 0.1)]), 0)
    scene = scene_model(spec, [box])
    state = mujoco.MjData(scene)
    state.qpos[:] = stand
    mujoco.mj_forward(scene, state)
    pairs = [tuple(scene.geom(g).name for g in p) for p in state.contact.geom[: state.ncon]]
    on_step = {a if b == "terrain0" else b for a, b in pairs if "terrain0" in (a, b)}
    assert "lhand" in on_step  # the step touches the hand
    # the reference has the hand there, resting on the step: support, no fall
    assert fall_cause(scene, state, fall_reference(scene, stand[None]), 0) is None
    # the reference 20 cm higher (its hand above the step): the hand on the step is a fall
    higher = stand.copy()
    higher[2] += 0.2
    assert fall_cause(scene, state, fall_reference(scene, higher[None]), 0) in {
        f"contact:{g}" for g in on_step
    }
    # on the plain floor the standing body has not fallen against either reference
    plain = mujoco.MjData(model)
    plain.qpos[:] = stand
    mujoco.mj_forward(model, plain)
    assert fall_cause(model, plain, fall_reference(model, higher[None]), 0) is None


def test_a_clip_without_terrain_runs_bit_for_bit_as_without_the_option(spec, model):
    from sim.simulate.validate import ForwardValidation

    still = np.repeat(_standing(model)[None], 72, axis=0)  # 0.6 s standing: no terrain
    rows = []
    for terrain in (False, True):
        fv = ForwardValidation(model, ("root",), controller="plain", terrain=terrain,
                               specs=(spec,))  # fmt: skip
        rows.append(fv.run(still, CONTROL_HZ))
        assert fv.last_boxes == []
    assert rows[0] == rows[1] and rows[0]["sim_steps"] == 0


def test_a_clip_on_a_step_is_tracked_in_its_scene(spec, model):
    from sim.simulate.validate import ForwardValidation

    motion = _step_up(model)[::2]  # 3 s at 60 Hz
    ngeom = model.ngeom
    fv = ForwardValidation(model, ("root",), controller="plain", terrain=True, specs=(spec,))
    row = fv.run(motion, CONTROL_HZ / 2)
    assert fv.last_boxes and all(b.top == pytest.approx(STEP, abs=0.01) for b in fv.last_boxes)
    assert row["sim_steps"] == len(fv.last_boxes)  # the row says the scene was not empty
    assert model.ngeom == ngeom  # the body's model is not changed
    # the report draws the boxes it was simulated in, lifted to the original's frame
    from sidql.evaluation.validation import clip_scene

    drawn, ground = clip_scene(model, motion, CONTROL_HZ / 2)
    assert len(drawn) == len(fv.last_boxes) and abs(ground) < 0.01
    for d, b in zip(drawn, fv.last_boxes, strict=True):
        np.testing.assert_allclose(d.centre - [0, 0, ground], b.centre, atol=1e-12)
        np.testing.assert_array_equal(d.half, b.half)
        assert d.yaw == b.yaw
    # the tracked reference stands on the step: its root as high above the floor as before
    tracked = fv.last_tracked
    assert tracked[-1, 2] - tracked[0, 2] == pytest.approx(STEP, abs=0.02)
    with pytest.raises(Exception, match="specs"):
        ForwardValidation(model, ("root",), controller="plain", terrain=True)


def test_the_drawn_scene_lies_where_the_motion_stood_in_its_own_frame(model):
    """A motion standing on a 0.5 m platform, then stepping onto a 0.3 m step on it: the
    scene's ground is the platform and the box's top the step, in the motion's own frame
    (its sole heights, :func:`foot_tracks`), not the simulation's (platform at z = 0)."""
    from sidql.evaluation.validation import clip_scene

    motion = _step_up(model)
    motion[:, 2] += 0.5
    boxes, ground = clip_scene(model, motion, CONTROL_HZ)
    low = foot_tracks(model, motion)[0].min(axis=1)  # (T,) the lowest sole corner [m]
    assert ground == pytest.approx(low[0], abs=0.01) and ground == pytest.approx(0.5, abs=0.01)
    assert boxes and all(b.top == pytest.approx(low[-1], abs=0.01) for b in boxes)
    assert low[-1] == pytest.approx(0.5 + STEP, abs=0.01)
    assert clip_scene(None, motion, CONTROL_HZ) == ((), None)  # no body: no scene
    flat = np.repeat(motion[:1], len(motion), axis=0)  # standing still on the platform
    assert clip_scene(model, flat, CONTROL_HZ) == ((), None)


def _trial_boxes(cmu_dir, trial: str) -> list[tuple[int, float]]:
    """(clip start, absolute top [m]) of every box found in each 2 s clip of a CMU trial on the
    shared humanoid."""
    from sim.simulate.reference import time_warp, trial_qpos

    model = sim_model(canonical_skeleton())
    subject = trial.split("_")[0]
    q = trial_qpos(cmu_dir / subject / f"{subject}.asf", cmu_dir / subject / f"{trial}.amc")
    out = []
    for s in range(0, len(q) - 239, 240):
        clip = time_warp(model, q[s : s + 240], 120.0, 1.0, CONTROL_HZ)
        boxes, ground = find_terrain(model, clip, CONTROL_HZ)
        out += [(s, b.top + float(ground.mean())) for b in boxes]
    return out


@pytest.mark.parametrize("trial", ["02_01", "07_01", "35_01", "05_10", "05_20", "17_10", "90_31"])
def test_flat_walks_and_held_feet_get_no_terrain(cmu_dir, trial):
    assert _trial_boxes(cmu_dir, trial) == []


def test_the_playground_climb_gets_its_three_platforms(cmu_dir):
    tops = np.array([top for _, top in _trial_boxes(cmu_dir, "01_02")])
    levels = np.array([0.28, 0.55, 0.8])  # where its lowest foot point stands still [m]
    assert np.abs(tops[:, None] - levels).min(axis=1).max() < 0.1
    assert set(np.abs(tops[:, None] - levels).argmin(axis=1)) == {0, 1, 2}


def test_flat_floor_reaches_eval_and_report_bodies_and_needs_simulate(tmp_path, capsys, cmu_dir):
    import pickle

    from sidql.commands import main as cli
    from sidql.evaluation.cases import load_cases
    from sidql.evaluation.trial_physics import simulate_setup

    out = str(tmp_path / "r.json")
    assert cli.main(["eval", "--data", str(tmp_path), "--flat-floor", "--out", out]) == 2
    assert capsys.readouterr().err.strip() == "sidql eval: error: --flat-floor needs --simulate"
    asf, amc = f"{cmu_dir}/07/07.asf", f"{cmu_dir}/07/07_01.amc"
    assert cli.main(["report", asf, amc, "--flat-floor", "--out", str(tmp_path / "r")]) == 2
    assert capsys.readouterr().err.strip() == "sidql report: error: --flat-floor needs --simulate"
    assert not (tmp_path / "r").exists()  # refused before anything was written
    cases = load_cases(cmu_dir, progress=False, subjects=["07"])[0][:1]
    (inferred,) = simulate_setup(cases).values()  # eval's default: the inferred scene
    (flat,) = simulate_setup(cases, terrain=False).values()
    assert inferred.terrain and not flat.terrain
    assert pickle.loads(pickle.dumps(inferred)).terrain  # to workers with its specs
