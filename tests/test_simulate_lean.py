"""``sim_model(lean=True)``: MuJoCo skips stages the body has nothing for, and the body moves as
the default one bit for bit (contacts, self-collision, joint limits, the sampler's search)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sim.model.humanoid import canonical_skeleton
from sim.simulate.controller import track
from sim.simulate.model import LEAN_DISABLED, sim_model
from sim.simulate.sampling import search_offsets


@pytest.fixture(scope="module")
def bodies():
    skeleton = canonical_skeleton()
    return sim_model(skeleton), sim_model(skeleton, lean=True)


@pytest.fixture(scope="module")
def walk(trial_on_floor, bodies):
    return trial_on_floor(bodies[0], "02_01")[:96]


def test_lean_skips_only_what_the_body_has_none_of(bodies):
    """The lean flags are set and nothing else: contacts, limits, damping, actuation and
    gravity stay on; the body has no equality constraint, friction loss, joint spring or
    sensor for the skipped stages to compute, and one kinematic tree (one island)."""
    default, lean = bodies
    assert default.opt.disableflags == 0
    assert lean.opt.disableflags == LEAN_DISABLED
    D = mujoco.mjtDisableBit
    for kept in (D.mjDSBL_CONTACT, D.mjDSBL_LIMIT, D.mjDSBL_DAMPER, D.mjDSBL_ACTUATION,
                 D.mjDSBL_GRAVITY, D.mjDSBL_CONSTRAINT, D.mjDSBL_FILTERPARENT):  # fmt: skip
        assert not lean.opt.disableflags & int(kept)
    assert lean.neq == 0 and lean.nsensor == 0
    assert not lean.dof_frictionloss.any() and not lean.jnt_stiffness.any()
    assert lean.dof_damping.any()  # damping is used, and kept
    assert lean.ntree == 1
    assert lean.nexclude == default.nexclude and lean.ngeom == default.ngeom


def test_lean_body_tracks_bit_for_bit_as_the_default(bodies, walk):
    """The plain tracker on a walk (floor contacts, a fall) gives the same states, torques and
    fall on both bodies, to the bit."""
    a, b = (track(m, walk, assist_limit=0.0, record_every=1) for m in bodies)
    assert np.array_equal(a.qpos, b.qpos) and np.array_equal(a.joint_torque, b.joint_torque)
    assert a.fell == b.fell and a.fall_frame == b.fall_frame


def test_lean_body_self_collides_bit_for_bit_as_the_default(bodies):
    """Legs driven across each other in the air: the same contacts and states every step."""
    runs = []
    for model in bodies:
        data = mujoco.MjData(model)
        data.qpos[3:7] = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]
        data.qpos[2] = 2.0
        target = data.qpos[7:].copy()
        for side, sign in (("l", 1.0), ("r", -1.0)):
            j = model.joint(f"{side}femur_rz").id
            target[model.jnt_qposadr[j] - 7] = np.clip(-0.8 * sign, *model.jnt_range[j])
        states, ncon = [], 0
        for _ in range(120):
            data.ctrl[:] = target
            mujoco.mj_step(model, data)
            states.append(data.qpos.copy())
            ncon += data.ncon
        runs.append((np.array(states), ncon))
    assert runs[0][1] > 0  # the legs met
    assert np.array_equal(runs[0][0], runs[1][0]) and runs[0][1] == runs[1][1]


def test_sampler_search_is_the_same_on_the_lean_body_and_repeats(bodies, walk):
    """The sampler's offsets on the lean body equal the default body's for the same seed, and
    a second run on the lean body repeats them."""
    kw = {"samples": 6, "keep": 3, "lookahead": 12, "seed": 3}
    ref = walk[:48]
    base, _ = search_offsets(bodies[0], ref, **kw)
    lean, _ = search_offsets(bodies[1], ref, **kw)
    again, _ = search_offsets(bodies[1], ref, **kw)
    assert np.abs(base).max() > 0  # the search moved the targets
    assert np.array_equal(base, lean) and np.array_equal(lean, again)
