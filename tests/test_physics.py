"""sim.physics: ground, contacts, inverse kinematics, inverse dynamics and the analysis, checked
against hand-made cases, brute force, finite differences and MuJoCo's own forward simulation."""

from __future__ import annotations

import copy

import mujoco
import numpy as np
import pytest

from sim.analysis.job import PhysicsJob
from sim.model import quaternion as quat
from sim.model.angles import wrap_angle
from sim.model.humanoid import humanoid_model, subject_model
from sim.model.rotations import Y_UP_TO_Z_UP
from sim.physics.dynamics import InverseDynamics, derivatives, pyramid, residual_wrench
from sim.physics.ground import Ground, estimate_ground
from sim.physics.ik import HumanoidIK, anatomical_ranges, hinge_names, limit_excess
from sim.replay.checks import FrameChecks, self_penetration_excess

PROTOCOL = (
    "root", "lhipjoint", "lfemur", "ltibia", "lfoot", "rhipjoint", "rfemur", "rtibia", "rfoot",
    "lowerback", "upperback", "thorax", "lowerneck", "upperneck", "head", "lclavicle", "lhumerus",
    "lradius", "lwrist", "rclavicle", "rhumerus", "rradius", "rwrist",
)  # fmt: skip


# (ground and contacts: tests/test_contacts.py)


# ---------------------------------------------------------------- inverse kinematics


@pytest.fixture(scope="module")
def walk(cmu_dir):
    from sim.motion.ingest import load_clips

    asf = cmu_dir / "02" / "02.asf"
    clip = load_clips(asf, cmu_dir / "02" / "02_01.amc")[0]
    return clip, subject_model(asf)[1], asf


def test_ik_recovers_the_originals_points_and_observed_angles(walk):
    clip, model, _ = walk
    idx = [clip.names.index(n) for n in PROTOCOL]
    pts = clip.positions[:20, idx]
    ik = HumanoidIK(model, PROTOCOL, limit_weight=0.0)  # exact: the original breaks CMU's limits
    warm = ik.fit(pts, q_init=clip.qpos[0])
    cold = ik.fit(pts)  # from a rigid (Kabsch) placement of the zero pose
    assert warm.error.max() < 1e-5 and cold.error.max() < 1e-4
    soft = HumanoidIK(model, PROTOCOL).fit(pts, q_init=clip.qpos[0])
    assert soft.error.max() < 5e-4  # the limit penalty trades little point error
    guessed = HumanoidIK(model, PROTOCOL).fit(pts, guesses=clip.qpos[:20])
    assert guessed.error.max() < 1e-9 and np.abs(guessed.qpos - clip.qpos[:20]).max() < 1e-9
    names = hinge_names(model)
    limbs = [k for k, n in enumerate(names) if n.split("_")[0][1:] in ("femur", "tibia", "humerus")]
    d = np.abs(wrap_angle(warm.qpos[:, 7:] - clip.qpos[:20, 7:]))[:, limbs]
    assert np.degrees(d.max()) < 0.1
    assert np.abs(warm.qpos[:, :3] - clip.qpos[:20, :3]).max() < 1e-6


def test_ik_limit_penalty_keeps_a_straightening_knee_on_its_branch(cmu_dir):
    """Regression: optimal W=10 on 07_01 straightens the left knee around frame 30; without the
    penalty the fit turned the thigh ~180 deg and bent the knee backwards (60 deg beyond limits)."""
    from sidql.evaluation.cases import make_case
    from sidql.keyframes.methods import select
    from sidql.keyframes.reconstructions import reconstruct_series
    from sim.motion.ingest import load_clips

    asf = cmu_dir / "07" / "07.asf"
    case = make_case(load_clips(asf, cmu_dir / "07" / "07_01.amc")[0])
    rec = reconstruct_series(case.series, select("optimal", case.clip, 10), "hermite")
    model = subject_model(asf)[1]
    fit = HumanoidIK(model, PROTOCOL).fit(rec.positions[20:45], q_init=case.clip.qpos[20])
    free = HumanoidIK(model, PROTOCOL, limit_weight=0.0).fit(
        rec.positions[20:45], q_init=case.clip.qpos[20]
    )
    assert fit.error.max() < 3e-3
    leg = ("lfemur_rz", "lfemur_ry", "lfemur_rx", "ltibia_rx")
    assert limit_excess(fit.qpos, model, leg).max() < 12.0
    assert limit_excess(free.qpos, model, leg).max() > 40.0


def test_limit_excess_wraps_angles_and_skips_non_anatomical_hinges():
    _, model = humanoid_model()
    ranges = anatomical_ranges(model)
    names = hinge_names(model)
    assert not any(n.startswith(("lthumb", "rfingers", "ltoes")) for n in ranges)
    q = np.zeros((3, model.nq))
    k = names.index("ltibia_rx")
    lo, hi = ranges["ltibia_rx"]
    q[0, 7 + k] = hi + np.radians(10)
    q[1, 7 + k] = hi + np.radians(10) + 4 * np.pi  # the same angle, unwrapped
    q[2, 7 + names.index("lthumb_rx")] = 12.0  # junk channel: ignored
    ex = limit_excess(q, model)
    assert ex[0] == pytest.approx(10.0) and ex[1] == pytest.approx(10.0) and ex[2] == 0.0
    assert limit_excess(q, model, hinges=("lfemur_rx",))[0] == 0.0


# ---------------------------------------------------------------- dynamics


def _standing_pose(model, z=1.0):
    q = np.zeros(model.nq)
    q[3:7] = quat.from_matrix(Y_UP_TO_Z_UP)
    q[2] = z
    return q


def test_derivatives_are_exact_for_cubic_hinges_and_constant_root_spin():
    _, model = humanoid_model()
    fps, T = 30.0, 40
    t = np.arange(T) / fps
    q = np.tile(_standing_pose(model), (T, 1))
    coef = np.random.default_rng(0).normal(0, 0.5, (4, model.nq - 7))
    q[:, 7:] = coef[0] + np.outer(t, coef[1]) + np.outer(t**2, coef[2]) + np.outer(t**3, coef[3])
    w = np.array([0.3, -0.5, 0.8])  # body-frame angular velocity [rad/s]
    for i in range(T):
        q[i, 3:7] = quat.mul(q[0, 3:7], quat.exp(w * t[i]))
    q[:, :3] += np.outer(t**2, [0.5, 0.0, -0.2])
    vel, acc = derivatives(model, q, fps)
    assert np.allclose(vel[:, 6:], coef[1] + 2 * np.outer(t, coef[2]) + 3 * np.outer(t**2, coef[3]))
    assert np.allclose(acc[:, 6:], 2 * coef[2] + 6 * np.outer(t, coef[3]))
    assert np.allclose(vel[:, 3:6], w) and np.allclose(acc[:, 3:6], 0, atol=1e-9)
    assert np.allclose(acc[:, :3], [1.0, 0.0, -0.4])
    jumped = q.copy()
    jumped[::3, 7:] += 2 * np.pi  # the same poses, some hinges a turn further on
    v2, a2 = derivatives(model, jumped, fps)
    assert np.allclose(v2, vel) and np.allclose(a2, acc)


def test_whole_body_wrench_is_newton_euler_by_finite_differences():
    """F = m (a_com - g) and tau = dL/dt about the CoM, with a_com and dL/dt by central
    differences of MuJoCo's CoM and angular momentum along a smooth motion."""
    _, model = humanoid_model()
    inv = InverseDynamics(model)
    m, d = inv.model, inv.data
    rng = np.random.default_rng(2)
    a0, a1 = rng.normal(0, 0.3, m.nq - 7), rng.normal(0, 0.6, m.nq - 7)
    w = np.array([0.4, 0.2, -0.3])

    def state(t):
        q = _standing_pose(m)
        q[7:] = a0 + np.sin(a1 * t + 1.0) * 0.5
        q[3:7] = quat.mul(q[3:7], quat.exp(w * t + 0.2 * np.sin(3 * t)))
        q[:3] += [0.3 * t, 0.1 * t**2, 0.05 * np.sin(2 * t)]
        return q

    def com_and_momentum(t, h=1e-5):
        qa, qb = state(t - h), state(t + h)
        v = np.empty(m.nv)
        mujoco.mj_differentiatePos(m, v, 2 * h, qa, qb)
        d.qpos[:], d.qvel[:] = state(t), v
        mujoco.mj_forward(m, d)
        mujoco.mj_subtreeVel(m, d)
        return d.subtree_com[inv.root].copy(), d.subtree_angmom[inv.root].copy()

    t, h = 0.7, 1e-3
    qs = [state(t + k * h) for k in (-2, -1, 0, 1, 2)]
    vel, acc = derivatives(m, np.array(qs), 1 / h, window=5, polyorder=4)
    F, tau, com, _ = inv.wrench(qs[2], vel[2], acc[2])
    c = [com_and_momentum(t + k * h)[0] for k in (-1, 0, 1)]
    a_com = (c[2] - 2 * c[1] + c[0]) / h**2
    assert np.allclose(F, inv.mass * (a_com - m.opt.gravity), rtol=1e-3, atol=0.05)
    L = [com_and_momentum(t + k * h)[1] for k in (-1, 1)]
    assert np.allclose(tau, (L[1] - L[0]) / (2 * h), rtol=1e-3, atol=0.05)


def test_residual_is_zero_inside_the_cones_and_the_unsuppliable_part_outside():
    com = np.array([0.0, 0.0, 1.0])
    pts = np.array([[0.1, 0.1, 0.0], [-0.1, 0.1, 0.0], [0.0, -0.15, 0.0]])
    rng = np.random.default_rng(3)
    D = pyramid(0.8)
    f = np.einsum("ke,ed->kd", rng.random((3, 4)) * 200, D)  # forces inside the cones
    F = f.sum(0)
    tau = np.cross(pts - com, f).sum(0)
    rF, rt, fit = residual_wrench(F, tau, com, pts)
    assert np.linalg.norm(rF) < 1e-6 and np.linalg.norm(rt) < 1e-6
    assert np.allclose(fit.sum(0), F)
    down = np.array([0.0, 0.0, -100.0])  # the ground cannot pull
    rF, rt, _ = residual_wrench(down, np.zeros(3), com, pts)
    assert np.allclose(rF, down, atol=1e-6)
    rF, rt, _ = residual_wrench(F, tau, com, np.zeros((0, 3)))  # flight: all of it
    assert np.allclose(rF, F) and np.allclose(rt, tau)


def _simulate(model, *, z0, v0, push, window, steps, every=2, kp=200.0, kd=5.0):
    """mj_step the humanoid (gravity, floor, PD on every hinge towards its zero pose) with a known
    force on the pelvis during ``window`` [s]; returns qpos at every ``every`` steps, the push
    flag, the number of floor contacts and MuJoCo's contact points per sample."""
    m = copy.deepcopy(model)
    d = mujoco.MjData(m)
    q0 = _standing_pose(m, z0)
    if z0 is None:  # stand on the floor: the lowest capsule 1 mm into it
        d.qpos[:] = _standing_pose(m, 1.0)
        mujoco.mj_kinematics(m, d)
        axis = d.geom_xmat.reshape(-1, 3, 3)[:, 2, 2]
        low = d.geom_xpos[:, 2] - np.abs(axis) * m.geom_size[:, 1] - m.geom_size[:, 0]
        q0 = _standing_pose(m, 1.0 - low[1:].min() - 0.001)  # geom 0 is the floor
    d.qpos[:] = q0
    d.qvel[:3] = v0
    out = {"q": [], "push": [], "ncon": [], "contacts": [], "ground_force": []}
    for k in range(steps):
        d.qfrc_applied[6:] = kp * (q0[7:] - d.qpos[7:]) - kd * d.qvel[6:]
        on = window[0] <= k * m.opt.timestep < window[1]
        d.xfrc_applied[1, :3] = push if on else 0.0
        if k % every == 0:
            mujoco.mj_forward(m, d)
            out["q"].append(d.qpos.copy())
            out["push"].append(on)
            floor = [c for c in (d.contact[: d.ncon] if d.ncon else []) if 0 in c.geom]
            out["ncon"].append(len(floor))
            out["contacts"].append(
                [(int(m.geom_bodyid[c.geom.max()]), c.pos.copy()) for c in floor]
            )
            total = np.zeros(3)
            for i in range(d.ncon):
                if 0 in d.contact[i].geom:
                    f6 = np.zeros(6)
                    mujoco.mj_contactForce(m, d, i, f6)  # contact frame; normal along row 0
                    sign = 1.0 if d.contact[i].geom[0] == 0 else -1.0  # force on the body
                    total += sign * d.contact[i].frame.reshape(3, 3).T @ f6[:3]
            out["ground_force"].append(total)
        mujoco.mj_step(m, d)
    return {k: np.array(v) if k != "contacts" else v for k, v in out.items()}


def _away_from_edges(flags, edge):
    """Samples whose whole +-edge neighbourhood has ``flags`` set (filter support inside)."""
    n = len(flags)
    return np.array(
        [flags[max(0, i - edge) : i + edge + 1].all() and edge <= i < n - edge for i in range(n)]
    )


def test_ground_truth_push_in_flight_is_recovered_and_nothing_else(walk):
    """A pelvis push during flight is all residual (no ground to supply it); the analysis recovers
    it within 2 %, through IK of the simulated points too; unpushed flight leaves ~0."""
    _, model = humanoid_model()
    push = np.array([120.0, -40.0, 60.0])
    sim = _simulate(model, z0=1.8, v0=[0.5, 0.0, 1.0], push=push, window=(0.15, 0.4), steps=300)
    fps = 1 / (2 * model.opt.timestep)
    flight = sim["ncon"] == 0
    inv = InverseDynamics(model)
    dyn = inv.run(sim["q"], fps, [[]] * len(sim["q"]))
    pushed = _away_from_edges(sim["push"] & flight, 5)
    quiet = _away_from_edges(~sim["push"] & flight, 5)
    assert pushed.sum() > 20 and quiet.sum() > 20
    assert np.allclose(
        dyn.residual_force[pushed], push, rtol=0.02, atol=0.02 * np.linalg.norm(push)
    )
    assert np.linalg.norm(dyn.residual_force[quiet], axis=1).max() < 0.01 * dyn.weight
    # the whole pipeline: the simulated sites as points, IK, dynamics (ground far below: flight)
    names = PROTOCOL
    ik = HumanoidIK(model, names)
    pts = np.array([ik.points(q) for q in sim["q"]])
    parent_body = {
        model.body(b).name: model.body(model.body_parentid[b]).name for b in range(2, model.nbody)
    }
    parents = [-1] + [names.index(parent_body[n]) for n in names[1:]]
    job = PhysicsJob(model, names, parents, fps)
    far = Ground(-5.0)
    mp = job.motion_physics(pts, None, far, sim["q"][0])
    assert mp.fit.error.max() < 1e-4  # the PD pose (all zeros) sits at some limits
    assert np.allclose(
        mp.dynamics.residual_force[pushed], push, rtol=0.02, atol=0.02 * np.linalg.norm(push)
    )


def test_ground_truth_stance_needs_no_residual_with_the_true_contacts():
    """Standing on the floor (PD-held pose, before it topples), the ground forces at MuJoCo's
    contact points inside friction cones (mu = the floor's 1.0) explain the motion: residual < 3 %
    of body weight; the required force is the floor's force MuJoCo applied."""
    _, model = humanoid_model()
    sim = _simulate(model, z0=None, v0=[0, 0, 0], push=np.zeros(3), window=(0, 0), steps=250,
                    kp=300.0, kd=10.0)  # fmt: skip
    fps = 1 / (2 * model.opt.timestep)
    inv = InverseDynamics(model, mu=1.0)
    dyn = inv.run(sim["q"], fps, sim["contacts"])
    ok = _away_from_edges(sim["ncon"] > 0, 5)
    ok[:10] = False  # the first 1 mm of penetration is pushed out with a jolt
    assert ok.sum() > 50
    assert (np.linalg.norm(dyn.residual_force[ok], axis=1) / dyn.weight).max() < 0.03
    # Newton-Euler's required force is the force MuJoCo's floor exerted (but where the filter
    # blurs an impact as a capsule touches down: hence percentiles, not the max)
    err = np.linalg.norm(dyn.force[ok] - sim["ground_force"][ok], axis=1) / dyn.weight
    assert np.median(err) < 0.01 and np.percentile(err, 90) < 0.03


# ---------------------------------------------------------------- self-penetration and analysis


def _checks(pairs):
    z = np.zeros(len(pairs))
    return FrameChecks(z, z, z, z, z, (), z[:, None], z[:, None], z, z, z, z, z, tuple(pairs))


def test_self_penetration_excess_is_per_pair_and_counts_lost_contacts():
    orig = _checks(
        [{("head", "thorax"): 0.006}, {("head", "thorax"): 0.006, ("lwrist", "rwrist"): 0.01}]
    )
    rec = _checks(
        [{("head", "thorax"): 0.006, ("lfemur", "rfemur"): 0.004}, {("head", "thorax"): 0.002}]
    )
    ex = self_penetration_excess(rec, orig)
    assert ex["self_pen_excess_mm"] == pytest.approx(2.0)  # frame 0: 4 mm new; frame 1: none
    assert ex["self_pen_excess_pairs"] == 1
    assert ex["lost_contacts"] == 2  # head-thorax 4 mm shallower, wrists apart
    same = self_penetration_excess(orig, orig)
    assert same["self_pen_excess_mm"] == 0 and same["lost_contacts"] == 0


def test_analysis_baseline_row_and_a_sunken_copy(walk):
    clip, model, _ = walk
    clip = clip.slice(0, 30)
    idx = [clip.names.index(n) for n in PROTOCOL]
    parents = [-1 if p < 0 else PROTOCOL.index(clip.names[p]) for p in clip.parents[idx]]
    job = PhysicsJob(model, PROTOCOL, parents, clip.fps)
    ground = estimate_ground(clip.positions, clip.names, clip.fps)
    base = job.analyse(clip, None, ground)
    for k in ("ground_z_m", "penetration_mm", "float_mm", "skate_mm_s", "contact_precision",
              "contact_recall", "self_pen_excess_mm", "lost_contacts", "limit_excess_deg",
              "residual_force_bw", "residual_force_bw_p95", "residual_torque_nm_kg",
              "joint_torque_rms_nm_kg", "physdiff_penetrate_mm", "physdiff_float_mm",
              "physdiff_skate", "floor_fits"):  # fmt: skip
        assert k in base
    assert base["derivatives"] == "source frames"
    assert base["contact_recall_n"] > 0 and base["contact_recall"] == 1.0
    assert base["self_pen_excess_mm"] == 0 and base["residual_force_bw_excess"] == 0
    sunk = clip.positions[:, idx] - [0.0, 0.0, 0.04]
    r = job.analyse(clip, sunk, ground)
    assert r["penetration_max_mm"] > 38 and r["penetration_mm"] > base["penetration_mm"] + 10
    assert r["physdiff_penetrate_mm"] > base["physdiff_penetrate_mm"] + 35
    assert r["float_mm"] < 0.5 * base["float_mm"] + 1e-9
    assert r["ik_error_mm"] < 0.01 and r["limit_excess_deg_excess"] == pytest.approx(0, abs=1e-3)
    up = job.analyse(clip, clip.positions[:, idx] + [0.0, 0.0, 0.10], ground)
    assert up["contact_precision_n"] == 0 and up["contact_recall"] == 0.0
    assert up["float_mm"] > 90 and up["physdiff_float_mm"] > 90
    assert up["residual_force_bw"] > base["residual_force_bw"] + 0.5  # nothing holds it up


def test_cached_original_is_keyed_by_the_points_and_the_whole_ground(walk):
    # Synthetic clips of one trial share source, start frame and length; a cache keyed on those
    # (and the ground's z alone) gave the second clip the first one's original physics.
    import dataclasses

    clip, model, _ = walk
    a = clip.slice(0, 30)
    b = dataclasses.replace(a, positions=a.positions + [0.0, 0.0, 0.05], source_velocities=None,
                            accelerations=None)  # fmt: skip
    idx = [a.names.index(n) for n in PROTOCOL]
    parents = [-1 if p < 0 else PROTOCOL.index(a.names[p]) for p in a.parents[idx]]
    ground = estimate_ground(a.positions, a.names, a.fps)
    job = PhysicsJob(model, PROTOCOL, parents, a.fps)

    def height(job, clip, g):  # mean lowest sole point above the floor [mm]
        return float(np.mean(job.analyse(clip, None, g)["per_frame"]["foot_height_mm"]))

    ha = height(job, a, ground)
    assert height(job, b, ground) == pytest.approx(ha + 50, abs=1e-6)
    other = dataclasses.replace(ground, z=ground.z + 0.03)
    assert height(job, a, other) == pytest.approx(ha - 30, abs=1e-6)


def test_held_frames_need_a_sustained_horizontal_force_no_contact_supplies():
    """A sideways residual over 0.15 BW for 0.2 s or longer is held by something else; an impact
    the source filter spreads over 5 frames, a vertical residual, a weaker force and a run an
    unmeasured frame breaks are not."""
    from sim.physics.support import HELD_BW, held_frames

    W, fps = 700.0, 30.0
    r = np.zeros((90, 3))
    r[5:14] = [0.3 * W, 0.25 * W, 0.0]  # 9 frames (0.3 s), 0.39 BW sideways: held
    r[20:25, 0] = 2.0 * W  # an impact spread over 5 frames (0.17 s): not
    r[30:45, 2] = -1.0 * W  # pulled down for 0.5 s, nothing sideways: not
    r[50:65, 1] = 0.9 * HELD_BW * W  # too weak
    r[70:85, 0] = 0.5 * W  # sustained, but frame 77 unmeasured: two runs of 7 (0.23 s)
    measured = np.ones(90, dtype=bool)
    measured[77] = False
    held = held_frames(r, W, fps, measured)
    assert held[5:14].all() and held[70:77].all() and held[78:85].all()
    assert held.sum() == 9 + 14
    measured[74] = False  # now runs of 4, 2 and 7 frames
    assert held_frames(r, W, fps, measured)[70:85].sum() == 7
    assert held_frames(r, W, 60.0).sum() == 15  # at 60 fps 9 frames are 0.15 s: only the 15 hold


def test_residual_causes_and_the_support_verdict_for_held_trials():
    from sim.physics.support import RESIDUAL_CAUSES, residual_causes, support_verdict

    F = np.array([[0.0, 0.0, 700.0], [900.0, 0.0, 700.0], [0.0, 100.0, -50.0], [10.0, 0, 0.0],
                  [400.0, 400.0, 700.0], [500.0, 0.0, 700.0]])  # fmt: skip
    causes = residual_causes(F, np.array([True, True, True, False, True, True]), mu=0.8)
    assert [RESIDUAL_CAUSES[c] if c >= 0 else None for c in causes] == [
        None, "outside the friction cone", "pulling", "no contact", "outside the friction cone",
        None,
    ]  # fmt: skip
    # the cause is exactly where the dynamics' pyramid leaves a residual
    from sim.physics.dynamics import residual_wrench

    for f, c in zip(F, causes, strict=True):
        if c == 0:
            continue  # nothing on the floor: no pyramid to ask
        left = residual_wrench(f, np.zeros(3), np.zeros(3), np.array([[0.0, 0.0, -1.0]]))[0]
        assert (np.linalg.norm(left) > 1e-6) == (c >= 0), (f, c)
    flag, why = support_verdict(0.0, 0.0, True, None, held=0.04)
    assert flag and "held by something else (a partner, a prop)" in why and "4 %" in why
    assert support_verdict(0.0, 0.0, False, None, held=0.04)[1].endswith("the floor does not fit")
    assert support_verdict(0.01, 0.0, True, None, held=0.015) == (False, "")  # a clean trial
    # support missing on the floor keeps its own reason
    assert "stands still" in support_verdict(0.3, 0.2, True, 500.0, held=0.1)[1]


def test_dynamics_figures_are_over_the_measured_frames_and_say_how_many_are_not():
    from sim.physics.dynamics import Dynamics, summarise_dynamics

    T = 6
    rf = np.zeros((T, 3))
    rf[0, 0] = 2.0 * 700.0  # a take's first frame: 2 BW from the one-sided window
    rf[3, 2] = 0.1 * 700.0
    z = np.zeros((T, 3))
    dyn = Dynamics(np.zeros((T, 8)), np.zeros((T, 8)), z, z, z, rf, z, z, np.ones((T, 2)),
                   70.0, 700.0)  # fmt: skip
    measured = np.array([False, True, True, True, True, True])
    s = summarise_dynamics(dyn, np.array([True, True]), measured)["summary"]
    assert s["residual_force_bw"] == pytest.approx(0.1 / 5)
    assert s["dynamics_n"] == 5 and s["dynamics_unmeasured_n"] == 1
    assert s["residual_force_bw_unmeasured"] == pytest.approx(2.0)
    every = summarise_dynamics(dyn, np.array([True, True]))["summary"]
    assert every["residual_force_bw"] == pytest.approx(2.1 / 6)
    assert every["dynamics_unmeasured_n"] == 0 and every["residual_force_bw_unmeasured"] is None


def test_a_takes_first_frame_is_unmeasured_for_the_original_and_its_reconstructions(walk):
    """The first frame of a take reads its source window at its first sample (5.3x the noise):
    its dynamics is not measured, for the original and, on the same frames, for any motion
    scored against it; every other frame of a walk is."""
    from sidql.keyframes.spherical import POINTS, protocol_parent_indices

    whole, model, _ = walk
    clip = whole.slice(0, 30)
    assert clip.derivative_noise[0].max() > 5 and clip.derivative_noise[4:].max() <= 1.0 + 1e-9
    job = PhysicsJob(model, POINTS, protocol_parent_indices(), clip.fps)
    orig = job.analyse(clip)
    assert orig["dynamics_unmeasured_n"] == 1 and orig["dynamics_n"] == 29
    pf = orig["per_frame"]
    assert pf["dynamics_measured"][0] == 0 and pf["dynamics_measured"][1:].all()
    assert orig["residual_force_bw"] == pytest.approx(pf["residual_force_bw"][1:].mean())
    idx = [clip.names.index(n) for n in POINTS]
    rec = job.analyse(clip, np.asarray(clip.positions)[:, idx] + 1e-4)
    assert rec["dynamics_unmeasured_n"] == 1 and rec["dynamics_n"] == 29
    assert orig["support_held_share"] == 0.0
    # a later stretch of the take is measured throughout
    assert job.analyse(whole.slice(30, 60))["dynamics_unmeasured_n"] == 0
