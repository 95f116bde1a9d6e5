"""Inverse dynamics at the analysis rate (30 fps) against an ``mj_step`` ground truth, through the
pipeline the evaluation runs.

The humanoid is simulated at 1200 Hz with its limbs driven (PD towards 0.45-0.5 rad sinusoids at
1.5-3 Hz), known pushes on the thorax and a hand, in flight and standing, a kick on a foot in
flight and a landing. Its 120 Hz states become a clip exactly as CMU's source frames do
(:func:`sim.motion.ingest.clip_from_qpos`: 30 fps frames, the points' velocities and
accelerations from the 120 Hz samples around each frame), and :class:`PhysicsJob` analyses that
clip on the 23 protocol points as it analyses an original: inverse kinematics, the points'
derivatives through the fitted humanoid's Jacobians, contacts labelled from the soles, the
residual. A second path gives the job the exact point velocities and accelerations (MuJoCo's
``J qvel`` and ``J qacc + Jdot qvel``), as a reconstruction's curve gives its own. Truth: the push
MuJoCo applied and the floor force it computed.
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np
import pytest

from sidql.keyframes.spherical import POINTS, protocol_parent_indices
from sim.analysis.job import PhysicsJob
from sim.model import quaternion as quat
from sim.model.humanoid import humanoid_model
from sim.model.kinematics import point_names, point_parents
from sim.model.rotations import Y_UP_TO_Z_UP
from sim.motion.ingest import clip_from_qpos
from sim.physics.ground import Ground

SIM_HZ, DENSE_HZ, FPS = 1200, 120, 30
DRIVEN = {  # hinge: (amplitude [rad], frequency [Hz])
    "lfemur_rx": (0.45, 1.5), "rfemur_rx": (0.45, 2.0), "ltibia_rx": (0.5, 3.0),
    "lhumerus_rx": (0.45, 2.5), "rhumerus_rx": (0.45, 1.5), "rradius_rx": (0.5, 3.0),
}  # fmt: skip
ARMS = {k: v for k, v in DRIVEN.items() if "humerus" in k or "radius" in k}


@pytest.fixture(scope="module")
def humanoid():
    return humanoid_model()


def _pose(model, z):
    q = np.zeros(model.nq)
    q[3:7] = quat.from_matrix(Y_UP_TO_Z_UP)
    q[2] = z
    return q


def _simulate(
    model, *, seconds, z0, v0=(0, 0, 0), pushes=(), floor=False, kp=200.0, kd=5.0, driven=DRIVEN
):
    """mj_step at :data:`SIM_HZ`; ``pushes``: (body name, force (3,) [N], start [s], stop [s],
    shape "box" or "sine" (half sine)); ``z0`` None: standing on the floor. Returns per
    :data:`DENSE_HZ` sample: qpos (N, nq), qvel, qacc (N, nv), the applied push (N, 3) [N] and
    the floor's total force on the body (N, 3) [N], its mean over the sample's interval (the
    stiff floor's force varies step to step)."""
    m = copy.deepcopy(model)
    m.opt.timestep = 1.0 / SIM_HZ
    if not floor:
        m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    d = mujoco.MjData(m)
    q0 = _pose(m, z0 if z0 is not None else 1.0)
    if z0 is None:  # standing: the lowest capsule 1 mm into the floor
        d.qpos[:] = q0
        mujoco.mj_kinematics(m, d)
        axis = d.geom_xmat.reshape(-1, 3, 3)[:, 2, 2]
        low = d.geom_xpos[:, 2] - np.abs(axis) * m.geom_size[:, 1] - m.geom_size[:, 0]
        q0 = _pose(m, 1.0 - low[1:].min() - 0.001)
    d.qpos[:] = q0
    d.qvel[:3] = v0
    adr = {n: m.jnt_qposadr[m.joint(n).id] for n in driven}
    bodies = [(m.body(b).id, np.asarray(f, float), a, z, s) for b, f, a, z, s in pushes]
    every = SIM_HZ // DENSE_HZ
    out = {k: [] for k in ("qpos", "qvel", "qacc", "push", "floor")}
    f6 = np.zeros(6)
    steps = []
    for k in range(int(seconds * SIM_HZ) + 1):
        t = k / SIM_HZ
        target = q0[7:].copy()
        for n, (amp, f) in driven.items():
            target[adr[n] - 7] += amp * np.sin(2 * np.pi * f * t)
        d.qfrc_applied[6:] = kp * (target - d.qpos[7:]) - kd * d.qvel[6:]
        d.xfrc_applied[:] = 0.0
        total = np.zeros(3)
        for b, f, a, z, shape in bodies:
            if a <= t < z:
                g = f * (np.sin(np.pi * (t - a) / (z - a)) if shape == "sine" else 1.0)
                d.xfrc_applied[b, :3] += g
                total += g
        mujoco.mj_forward(m, d)
        ground = np.zeros(3)
        for c in range(d.ncon):
            con = d.contact[c]
            if 0 in con.geom:  # the floor (geom 0) pushes the body
                mujoco.mj_contactForce(m, d, c, f6)
                sign = 1.0 if con.geom[0] == 0 else -1.0
                ground += sign * (con.frame.reshape(3, 3).T @ f6[:3])
        steps.append(ground)
        if k % every == 0:
            for key, v in (("qpos", d.qpos), ("qvel", d.qvel), ("qacc", d.qacc),
                           ("push", total)):  # fmt: skip
                out[key].append(np.array(v, dtype=np.float64))
        mujoco.mj_step(m, d)
    steps = np.array(steps)
    for i in range(len(out["qpos"])):  # the floor force over each sample's interval
        k = i * every
        out["floor"].append(steps[max(k - every // 2, 0) : k + every // 2].mean(axis=0))
    return {k: np.array(v) for k, v in out.items()}


def _analyse(humanoid, sim, *, exact=False, ground=None):
    """The 30 fps analysis of a simulated run as an original (``exact``: with the exact point
    derivatives instead of the source frames'). Returns the job's MotionPhysics and the dense
    sample of each frame."""
    job, clip, idx = _job_and_clip(humanoid, sim)
    model, names = humanoid[1], clip.names
    ground = ground or Ground(-5.0)  # flight: a floor far below
    centre = np.arange(0, len(sim["qpos"]), DENSE_HZ // FPS)
    if not exact:
        return job.original(clip, ground), centre
    vel, acc = _exact_point_derivatives(model, sim, centre, idx, names)
    mp = job.motion_physics(
        clip.positions[:, idx], None, ground, clip.qpos, velocities=vel, accelerations=acc,
    )  # fmt: skip
    return mp, centre


def _job_and_clip(humanoid, sim):
    """The job on the protocol points, the simulated run as a 30 fps clip of its 120 Hz states,
    and the protocol points' indices in the clip."""
    skeleton, model = humanoid
    names, parents = point_names(skeleton), point_parents(skeleton)
    clip = clip_from_qpos(model, names, parents, sim["qpos"], source_fps=DENSE_HZ, fps=FPS)
    return (
        PhysicsJob(model, POINTS, protocol_parent_indices(), FPS),
        clip,
        [names.index(n) for n in POINTS],
    )


def _exact_point_derivatives(model, sim, centre, idx, names):
    """The points' exact velocities ``J qvel`` and accelerations ``J qacc + Jdot qvel``."""
    d = mujoco.MjData(model)
    T = len(centre)
    vel, acc = np.zeros((T, len(idx), 3)), np.zeros((T, len(idx), 3))
    jac, jdot = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    for t, c in enumerate(centre):
        d.qpos[:], d.qvel[:] = sim["qpos"][c], sim["qvel"][c]
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        mujoco.mj_comVel(model, d)
        for k, i in enumerate(idx):
            if names[i] == "root":
                body = model.body("root").id
                point = d.xpos[body]
                mujoco.mj_jacBody(model, d, jac, None, body)
            else:
                s = model.site(f"{names[i]}_end").id
                body, point = int(model.site_bodyid[s]), d.site_xpos[s]
                mujoco.mj_jacSite(model, d, jac, None, s)
            mujoco.mj_jacDot(model, d, jdot, None, point, body)
            vel[t, k] = jac @ sim["qvel"][c]
            acc[t, k] = jac @ sim["qacc"][c] + jdot @ sim["qvel"][c]
    return vel, acc


def _limbs_move(model, qpos, driven=DRIVEN):
    """Each driven hinge swings by at least 0.3 rad (half its peak to peak) (the motion is real)."""
    for n in driven:
        a = qpos[:, model.jnt_qposadr[model.joint(n).id]]
        assert (a.max() - a.min()) / 2 >= 0.3, n


@pytest.mark.parametrize("exact", [False, True], ids=["source frames", "exact derivatives"])
@pytest.mark.parametrize("body", ["thorax", "lhand"])
def test_a_push_in_flight_is_recovered_at_30_fps_with_limbs_moving(humanoid, body, exact):
    """A 262 N half-sine push for 200 ms on the thorax or a hand, during flight: its impulse
    within 5 %, its peak within 15 %; unpushed flight frames <= 3 % body weight on average."""
    push = np.array([200.0, -120.0, 120.0])
    sim = _simulate(
        humanoid[1], seconds=1.0, z0=3.0, v0=(0.5, 0, 2.0), pushes=[(body, push, 0.4, 0.6, "sine")]
    )
    _limbs_move(humanoid[1], sim["qpos"])
    mp, centre = _analyse(humanoid, sim, exact=exact)
    dyn = mp.dynamics
    assert not mp.contacts.contact.any()  # in the air
    rf = dyn.residual_force
    applied = sim["push"]
    on = np.linalg.norm(applied[centre], axis=1) > 0
    got = rf[on].sum(0) / FPS  # the frames' residual times the frame interval ...
    true = applied.sum(0) / DENSE_HZ  # ... against the applied impulse
    spread = np.flatnonzero(on)  # the filter spreads the push over +-2 frames
    near = np.zeros(len(on), bool)
    near[max(spread[0] - 2, 0) : spread[-1] + 3] = True
    got = rf[near].sum(0) / FPS
    assert np.linalg.norm(got - true) < 0.05 * np.linalg.norm(true)
    peak, true_peak = np.linalg.norm(rf[on], axis=1).max(), np.linalg.norm(push)
    assert abs(peak - true_peak) < 0.15 * true_peak
    quiet = ~near
    assert quiet.sum() > 10
    assert np.linalg.norm(rf[quiet], axis=1).mean() / dyn.weight < 0.03
    if not exact:  # the 9-frame filter on the 30 fps frames alone misses this by far
        job, clip, idx = _job_and_clip(humanoid, sim)
        sg = job.motion_physics(clip.positions[:, idx], None, Ground(-5.0), clip.qpos).dynamics
        assert np.linalg.norm(sg.residual_force[quiet], axis=1).mean() / sg.weight > 0.1


@pytest.mark.parametrize("exact", [False, True], ids=["source frames", "exact derivatives"])
def test_an_impact_does_not_leak_into_frames_two_away(humanoid, exact):
    """A 10 ms, 4 kN kick on a foot in flight (an impact): frames more than two frames from it
    show < 10 % body weight; the frames around it see it."""
    kick = np.array([0.0, 1500.0, 3700.0])
    sim = _simulate(humanoid[1], seconds=0.8, z0=3.0, pushes=[("rfoot", kick, 0.395, 0.405, "box")])
    mp, centre = _analyse(humanoid, sim, exact=exact)
    rf = np.linalg.norm(mp.dynamics.residual_force, axis=1) / mp.dynamics.weight
    hit = int(round(0.4 * FPS))
    far = np.abs(np.arange(len(centre)) - hit) > 2
    assert rf[far].max() < 0.10
    assert rf[~far].sum() / FPS > 0.5 * np.linalg.norm(kick) * 0.01 / mp.dynamics.weight


def test_a_push_while_standing_is_the_required_force_less_the_floor_force(humanoid):
    """Standing with the arms moving, a 262 N half-sine push on the thorax for 200 ms: the force
    the motion requires (``m (a_com - g)``) less the floor force MuJoCo computed is the push:
    impulse within 5 %, peak within 15 %, and <= 3 % body weight where nothing pushes."""
    push = np.array([150.0, -150.0, 150.0])
    sim = _simulate(
        humanoid[1], seconds=1.0, z0=None, floor=True, kp=600.0, kd=20.0, driven=ARMS,
        pushes=[("thorax", push, 0.4, 0.6, "sine")],
    )  # fmt: skip
    _limbs_move(humanoid[1], sim["qpos"], ARMS)
    mp, centre = _analyse(humanoid, sim, ground=Ground(0.0))
    dyn = mp.dynamics
    # what neither gravity nor the floor explains (the floor's force over each frame's interval)
    floor = np.array([sim["floor"][max(c - 2, 0) : c + 2].mean(axis=0) for c in centre])
    extra = dyn.force - floor
    on = np.linalg.norm(sim["push"][centre], axis=1) > 0
    near = np.zeros(len(on), bool)
    idx = np.flatnonzero(on)
    near[max(idx[0] - 2, 0) : idx[-1] + 3] = True
    true = sim["push"].sum(0) / DENSE_HZ
    got = extra[near].sum(0) / FPS
    assert np.linalg.norm(got - true) < 0.05 * np.linalg.norm(true)
    peak = np.linalg.norm(extra[on], axis=1).max()
    assert abs(peak - np.linalg.norm(push)) < 0.15 * np.linalg.norm(push)
    quiet = ~near
    quiet[:3] = quiet[-3:] = False  # the settling start and the take's one-sided ends
    assert np.linalg.norm(extra[quiet], axis=1).mean() / dyn.weight < 0.03
    # and the feet stay labelled in contact: the floor explains it, no residual needed
    assert mp.contacts.contact[quiet].all()
    assert np.median(np.linalg.norm(dyn.residual_force[quiet], axis=1)) / dyn.weight < 0.03


def test_a_landing_does_not_leak_into_the_fall_and_stance_needs_no_residual(humanoid):
    """Dropped onto the floor with limbs moving: free-fall frames more than two frames before the
    first contact show < 10 % body weight (< 3 % on average); standing afterwards, on the contacts
    the job labels from the soles, little residual."""
    sim = _simulate(humanoid[1], seconds=0.9, z0=1.05, floor=True, kp=300.0, kd=10.0)
    mp, centre = _analyse(humanoid, sim, ground=Ground(0.0))
    rf = np.linalg.norm(mp.dynamics.residual_force, axis=1) / mp.dynamics.weight
    touch = np.linalg.norm(sim["floor"][centre], axis=1) > 0
    first = int(np.argmax(touch))
    assert first > 3  # some free fall first
    assert rf[: first - 2].max() < 0.10
    assert rf[: first - 2].mean() < 0.03
    stance = touch.copy()
    stance[: first + 3] = False  # the landing itself
    assert stance.sum() > 5
    assert np.median(rf[stance]) < 0.05


def test_a_sustained_pull_is_held_by_something_else_an_impact_and_a_landing_are_not(humanoid):
    """Pulled sideways by 0.4 body weights for 0.4 s in flight (limbs moving, source frames at
    120 Hz): the frames of the pull are held by something else (:func:`held_frames`), the free
    flight more than 2 frames from it is not; a 10 ms kick of 4 kN on a foot (spread by the filter) is not, and
    neither is a landing on the floor."""
    from sim.physics.support import held_frames

    W = 75.0 * 9.81
    pull = np.array([0.4 * W, 0.0, 0.0])
    sim = _simulate(humanoid[1], seconds=1.2, z0=3.0, pushes=[("thorax", pull, 0.4, 0.8, "box")])
    mp, centre = _analyse(humanoid, sim)
    held = held_frames(mp.dynamics.residual_force, mp.dynamics.weight, FPS, mp.measured)
    on = np.linalg.norm(sim["push"][centre], axis=1) > 0
    inner = on & np.roll(on, 2) & np.roll(on, -2)  # two frames inside the pull's ends
    assert held[inner].all()
    near = on | np.roll(on, 2) | np.roll(on, -2) | np.roll(on, 1) | np.roll(on, -1)
    assert not held[~near].any()  # the filter spreads the pull's steps by +-2 frames, no further
    kick = np.array([4000.0, 0.0, 0.0])
    sim = _simulate(humanoid[1], seconds=0.8, z0=3.0, pushes=[("rfoot", kick, 0.395, 0.405, "box")])
    mp, _ = _analyse(humanoid, sim)
    assert not held_frames(mp.dynamics.residual_force, mp.dynamics.weight, FPS, mp.measured).any()
    sim = _simulate(humanoid[1], seconds=0.9, z0=1.05, floor=True, kp=300.0, kd=10.0)
    mp, _ = _analyse(humanoid, sim, ground=Ground(0.0))
    assert not held_frames(mp.dynamics.residual_force, mp.dynamics.weight, FPS, mp.measured).any()


def test_a_bounce_held_up_by_nothing_is_unsupported_and_standing_is_not(humanoid):
    """:func:`capture_unsupported` on the analysis of an original, as ``bench_simulate_falls``
    and the report read it. A body bouncing at 1.5 Hz with its feet 15+ cm above the floor
    (limbs moving), held up by a push of 0.4-1.6 body weights that no floor gives (the Russian
    dances' squats: a bounce's bottom with nothing under the body): unsupported in most frames.
    Standing on the floor with the arms moving: supported."""
    from sim.physics.support import capture_unsupported

    model = humanoid[1]
    W = float(mujoco.mj_getTotalmass(model)) * 9.81
    held = [("thorax", np.array([0.0, 0.0, W]), 0.0, 9.0, "box")]
    for k in range(3):  # the bounce: +-0.6 W in half sines at 1.5 Hz
        a = k / 1.5
        held += [("thorax", np.array([0.0, 0.0, 0.6 * W]), a, a + 1 / 3, "sine"),
                 ("thorax", np.array([0.0, 0.0, -0.6 * W]), a + 1 / 3, a + 2 / 3, "sine")]  # fmt: skip
    v0 = (0.0, 0.0, -0.6 * 9.81 / (2 * np.pi * 1.5))  # no drift: z = z0 - 6.6 cm sin(wt)
    sim = _simulate(model, seconds=2.0, z0=1.3, v0=v0, pushes=held)
    job, clip, _ = _job_and_clip(humanoid, sim)
    bounce = job.analyse(clip, None, Ground(0.0))
    assert 150 < bounce["per_frame"]["foot_height_mm"].min()  # nothing near the floor
    assert bounce["unsupported_share"] == 1.0
    assert bounce["residual_force_bw_p95"] > 1.4  # the bottoms ask for more than the weight
    assert bounce["support_missing_share"] > 0.8
    assert capture_unsupported(bounce["support_missing_share"])
    sim = _simulate(model, seconds=2.0, z0=None, floor=True, kp=600.0, kd=20.0, driven=ARMS)
    _limbs_move(model, sim["qpos"], ARMS)
    job, clip, _ = _job_and_clip(humanoid, sim)
    standing = job.analyse(clip, None, Ground(0.0))
    assert standing["support_missing_share"] == 0.0
    assert not capture_unsupported(standing["support_missing_share"])
    assert not capture_unsupported(None)  # not measured
