"""Reference motions for the tracking controller: time warps, floor placement, body scaling.

A reference is a ``qpos`` stream (T, nq) at the control rate (``sim.simulate.model.CONTROL_HZ``).
CMU's floor height varies per trial (the lowest foot point sits anywhere from -20 to +16 cm), and even drifts within
one, so a real reference is shifted vertically, frame by frame, by a running low percentile of its
lowest foot point (:func:`floor_track`). (The physics room's ground estimate can replace it.)
"""

from __future__ import annotations

import os

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d

from sim.errors import MotionDataError, UsageError
from sim.model.humanoid import humanoid_model
from sim.model.kinematics import SOLE_POINTS
from sim.motion.ingest import check_memory
from sim.motion.resample import resample_qpos, resampled_frames
from sim.motion.retarget import leg_length, motion_to_qpos, retarget_rotations
from sim.motion.trial import CMU_FPS, read_trial, trial_files
from sim.simulate.model import FLOOR_BITS, SOLE_GEOMS, TOE_GEOMS, G
from sim.simulate.terrain import running_floor, surface_height, terrain_geoms


def trial_qpos(asf: str | os.PathLike, amc: str | os.PathLike) -> np.ndarray:
    """(T, nq) ``qpos`` of a CMU trial (or a BVH as both ``asf`` and ``amc``) on the shared
    humanoid at 120 Hz (a BVH of another rate interpolated onto it): angles copied, root
    translation scaled by the leg-length ratio (as ``load_motion`` with ``skeleton="humanoid"``
    does, without computing the clip's kinematics).

    Raises:
        MotionDataError: malformed or unreadable files.
    """
    try:
        subject, motion, fps = read_trial(asf, amc)
    except FileNotFoundError as e:
        raise MotionDataError(str(asf), None, f"cannot read file: {e.strerror}") from e
    target, model = humanoid_model()
    source = subject
    bvh = trial_files(asf, amc)
    if bvh is not None:  # a BVH: rotations re-expressed in the ASF bones' frames, 120 Hz
        check_memory(bvh, resampled_frames(motion.n_frames, fps, CMU_FPS), len(target.bones) + 1)
        subject, motion = retarget_rotations(subject, motion, target)
        source = target
    qpos = motion_to_qpos(
        source, motion, model, root_scale=leg_length(target) / leg_length(subject)
    )
    return qpos if fps == CMU_FPS else resample_qpos(qpos, fps, CMU_FPS)


def lowest_foot_point(model, qpos: np.ndarray) -> np.ndarray:
    """(T,) height [m] of the lowest surface point of the feet's geoms that touch the floor in
    each frame: the sole boxes where the model has them (``sim.simulate.model.add_soles``; the
    foot and toe capsules then touch the body only), else the foot and toe capsules. On a
    model with terrain (``sim.simulate.terrain.add_terrain``) each geom's height is taken above
    the support under its centre (``surface_height``): a sole on a step is at 0."""
    data = mujoco.MjData(model)
    terrain = terrain_geoms(model)
    names = SOLE_POINTS + SOLE_GEOMS + TOE_GEOMS
    ids = [
        model.geom(n).id
        for n in names
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) >= 0
        and int(model.geom(n).conaffinity[0]) & FLOOR_BITS[0]
    ]
    low = np.empty(len(qpos))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        if terrain is None:
            z = min((_geom_low(model, data, g) for g in ids), default=np.inf)
        else:  # the same lowest point, above the support under each geom
            z = min(_geom_low(model, data, g) - surface_height(terrain, data.geom_xpos[g, :2])
                    for g in ids)  # fmt: skip
        low[t] = z
    return low


def _geom_low(model, data, g: int) -> float:
    """[m] the lowest surface point of geom ``g`` (capsule, box or sphere) of ``data``."""
    c, r = data.geom_xpos[g, 2], model.geom_size[g, 0]
    if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return c - model.geom_size[g, 1] * abs(data.geom_xmat[g, 8]) - r
    if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
        return c - np.abs(data.geom_xmat[g, 6:9]) @ model.geom_size[g]
    return c - r


def floor_track(
    model, qpos: np.ndarray, rate: float, *, window: float = 1.5, percentile: float = 10.0
) -> np.ndarray:
    """(T,) floor height [m] under each frame: the ``percentile`` of the lowest foot point over a
    ``window``-second window centred on the frame, then averaged over the same window.

    CMU floors drift within a trial (02_01's stance foot rises 5 cm over 3 s), so one offset per
    trial leaves feet hovering or sunk; a running low percentile follows the stance foot.
    """
    return running_floor(lowest_foot_point(model, qpos), rate, window, percentile)


FLOOR_LIFT = 0.01  # [m]


def on_floor(model, qpos: np.ndarray, rate: float = 120.0, lift: float = FLOOR_LIFT) -> np.ndarray:
    """A copy of ``qpos`` shifted vertically, frame by frame, so the floor under it
    (:func:`floor_track`) is at z = -``lift``.

    The lift (1 cm) keeps a reference whose floor estimate is off by marker noise from driving
    the stiff legs into the floor or catching a toe: on 7 CMU trials it turned 2 falls into none.
    """
    out = qpos.copy()
    out[:, 2] -= floor_track(model, qpos, rate) - lift
    return out


def wrap_hinges(model, qpos: np.ndarray) -> np.ndarray:
    """(T, nq) ``qpos`` with every limited hinge's angles [rad] unwrapped along time (a jump of
    more than half a turn between frames is taken as a whole turn) and then moved by the whole
    turns that bring their median within half a turn of the range's middle: the same poses
    (the points do not move) and no new jump, but targets the tracker can reach. IK fits and
    CMU's own angles hold some hinges whole turns outside their range (a foot at 6.3 rad, a
    thigh's twist at 7.5) or jump a turn between frames, which linear interpolation would
    sweep round."""
    out = np.array(qpos, dtype=float)
    hinge = (model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE) & (model.jnt_limited != 0)
    hinge &= np.diff(model.jnt_range, axis=1)[:, 0] < 2 * np.pi  # else in range may move
    adr = model.jnt_qposadr[hinge]
    mid = model.jnt_range[hinge].mean(axis=1)
    if len(out) == 0:
        return out
    angles = np.unwrap(out[:, adr], axis=0)
    two_pi = 2 * np.pi
    out[:, adr] = angles - two_pi * np.round((np.median(angles, axis=0) - mid) / two_pi)
    return out


def time_warp(model, qpos: np.ndarray, rate: float, speed: float, out_rate: float) -> np.ndarray:
    """``qpos`` sampled at ``rate`` replayed ``speed`` times faster, resampled at ``out_rate``.

    Hinge angles are first moved by whole turns towards their ranges (:func:`wrap_hinges`);
    positions and hinges are interpolated linearly; the root quaternion by slerp on the
    shortest arc. Returns (T', nq) covering the same motion.
    """
    if speed <= 0:
        raise UsageError(f"speed must be positive; got {speed}")
    qpos = wrap_hinges(model, qpos)
    T = len(qpos)
    duration = (T - 1) / rate / speed
    n = int(np.floor(duration * out_rate + 1e-9)) + 1
    s = np.arange(n) / out_rate * speed * rate  # source frame index (float)
    i0 = np.minimum(np.floor(s).astype(int), T - 1)
    i1 = np.minimum(i0 + 1, T - 1)
    a = (s - i0)[:, None]
    out = (1 - a) * qpos[i0] + a * qpos[i1]
    q0, q1 = qpos[i0, 3:7], qpos[i1, 3:7]
    sign = np.where((q0 * q1).sum(-1, keepdims=True) < 0, -1.0, 1.0)
    dot = np.clip(np.abs((q0 * q1).sum(-1, keepdims=True)), -1, 1)
    theta = np.arccos(dot)
    small = theta < 1e-6
    st = np.where(small, 1.0, np.sin(theta))
    w0 = np.where(small, 1 - a, np.sin((1 - a) * theta) / st)
    w1 = np.where(small, a, np.sin(a * theta) / st)
    q = w0 * q0 + w1 * sign * q1
    out[:, 3:7] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return out


#: [m] a sole whose lowest corner is this high or lower is laid flat on the floor in full; from
#: there to FLAT_TO it is turned less and less, and above it not at all
FLAT_FROM, FLAT_TO = 0.02, 0.05
FLAT_ITERATIONS = 5
FLAT_MAX_STEP = 0.2  # [rad] per Gauss-Newton iteration


def flat_soles(model, qpos: np.ndarray) -> np.ndarray:
    """A copy of ``qpos`` (T, nq, floor at z = 0 or a lift below) in which each sole box
    (``sim.simulate.model.add_soles``) near the floor is turned flat on it by its ankle hinges
    (``foot_rx``, ``foot_rz``, within their ranges): in full where its lowest corner is at most
    :data:`FLAT_FROM` high, in part up to :data:`FLAT_TO`, not above. The rest of the body
    stays as it is.

    A captured foot's bone points wherever the subject's markers put it: in 60_01's still
    double-stance frame 108 the sole boxes (whose normal is the mean captured stance direction)
    sit 15 and 11 deg toe-up, so the body tracking that pose rests on its heels and topples
    forward. Models without soles come back unchanged."""
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, SOLE_GEOMS[0]) < 0:
        return qpos.copy()
    out = qpos.copy()
    data = mujoco.MjData(model)
    corners = np.array([[i, j, -1.0] for i in (-1, 1) for j in (-1, 1)])

    def sole(g):
        R = data.geom_xmat[g].reshape(3, 3)
        low = (data.geom_xpos[g] + (corners * model.geom_size[g]) @ R.T)[:, 2].min()
        return R[:2, 2].copy(), low  # the normal's horizontal part, the lowest corner

    for side in "lr":
        g = model.geom(f"{side}sole").id
        adr = [model.jnt_qposadr[model.joint(f"{side}foot_{a}").id] for a in ("rx", "rz")]
        lo = np.array([model.jnt_range[model.joint(f"{side}foot_{a}").id, 0] for a in ("rx", "rz")])
        hi = np.array([model.jnt_range[model.joint(f"{side}foot_{a}").id, 1] for a in ("rx", "rz")])
        for t in range(len(out)):
            data.qpos[:] = out[t]
            mujoco.mj_kinematics(model, data)
            _, low = sole(g)
            w = float(np.clip((FLAT_TO - low) / (FLAT_TO - FLAT_FROM), 0.0, 1.0))
            if w == 0.0:
                continue
            q0 = out[t, adr].copy()
            q = q0.copy()
            f0 = f = sole(g)[0]
            for _ in range(FLAT_ITERATIONS):  # damped Gauss-Newton on the normal's tilt
                data.qpos[adr] = q
                mujoco.mj_kinematics(model, data)
                f, _ = sole(g)
                J = np.empty((2, 2))
                for k in range(2):
                    data.qpos[adr[k]] = q[k] + 1e-4
                    mujoco.mj_kinematics(model, data)
                    J[:, k] = (sole(g)[0] - f) / 1e-4
                    data.qpos[adr[k]] = q[k]
                step = np.linalg.lstsq(J, f, rcond=1e-3)[0]
                step *= min(1.0, FLAT_MAX_STEP / max(np.linalg.norm(step), 1e-12))
                q = np.clip(q - step, lo, hi)
            data.qpos[adr] = q
            mujoco.mj_kinematics(model, data)
            if np.linalg.norm(sole(g)[0]) >= np.linalg.norm(f0):
                continue  # no flatter within the ankle's range: the captured foot stays
            out[t, adr] = q0 + w * (q - q0)
    return out


#: [m] a sole whose lowest corner is at most this high (after the floor shift) is in stance
STANCE_GAP = 0.03
#: [s] the vertical correction of :func:`contact_consistent` is smoothed over this scale
CONSISTENT_SMOOTH_S = 0.05
#: smoothing passes of :func:`contact_shift` with ``floor_bound``, each followed by the bound
#: (a sole never below z = 0): the bound's kinks are smoothed by the next pass, the last holds
FLOOR_PASSES = 3
#: [s] a flight (no sole within :data:`STANCE_GAP`) at least this long is judged by its root
#: height (:func:`supported`); shorter ones (a run's) are kept as they are
MIN_FLIGHT_S = 0.15
#: a flight is ballistic where the root's height, fitted by a parabola over it, falls with at
#: least this share of gravity; one that floats is not a flight
BALLISTIC_SHARE = 0.5


def supported(root_z: np.ndarray, stance: np.ndarray, rate: float) -> np.ndarray:
    """(T,) bool: ``stance`` (T,) with every flight that cannot be one set to stance. A body
    off the floor falls freely: its root height over a flight is a parabola of curvature -g
    (-g/2 t^2). Where the root's height ``root_z`` (T,) [m] over a run of non-stance ticks
    of at least :data:`MIN_FLIGHT_S` (at ``rate`` [Hz]) fitted by a parabola curves down by
    less than :data:`BALLISTIC_SHARE` of that, the reference floats: its feet hover over a
    floor estimate that is too low, over equipment the scene lacks, or the IK fit's legs do not
    reach the floor (the deep squats of the Russian dances 90_30 and 90_31 hover 5-30 cm for
    half a second at a time with the root 0.4-0.6 m high), and the only support the scene has
    is the floor under its lowest sole point: those ticks are stance."""
    out = stance.copy()
    edges = np.flatnonzero(np.diff(np.concatenate([[1], stance.astype(int), [1]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):  # runs [a, b) of flight
        if (b - a) / rate < MIN_FLIGHT_S:
            continue
        t = np.arange(b - a) / rate
        curvature = 2.0 * np.polyfit(t, root_z[a:b], 2)[0]  # d^2 z / dt^2 [m/s^2]
        if curvature > -BALLISTIC_SHARE * G:
            out[a:b] = True
    return out


def contact_shift(
    model, qpos: np.ndarray, rate: float = 120.0, *, floor_bound: bool = False,
    floating: bool = False,
) -> np.ndarray:  # fmt: skip
    """(T,) [m] the vertical shift :func:`contact_consistent` takes off ``qpos`` (T, nq, its
    floor near z = 0): in stance (the lowest sole point within :data:`STANCE_GAP`) that point's
    height, interpolated between stance frames (flight), smoothed by a Gaussian of
    :data:`CONSISTENT_SMOOTH_S`; zeros for a motion that never stands. Another motion shifted
    by it stands on the same floor as ``qpos`` (a reconstruction on its original's).

    Options (tried, not kept as defaults: docs/synthetic.md): ``floor_bound``, the shift is
    also bounded by the lowest sole point in every frame, so that ``qpos`` shifted by it has no
    sole below z = 0 (:data:`FLOOR_PASSES` rounds of smoothing and bound; smoothing alone
    leaves the IK fits' stamps, a foot dipping 15 cm in 0.1 s, 5-8 cm through the floor in
    90_30 and 90_31); ``floating``, a flight that floats instead of falling is stance
    (:func:`supported`)."""
    low = lowest_foot_point(model, qpos)
    stance = low <= STANCE_GAP
    if floating:
        stance = supported(qpos[:, 2], stance, rate)
    if not stance.any():
        return np.zeros(len(qpos))
    t = np.arange(len(qpos))
    shift = np.interp(t, t[stance], low[stance])
    if len(qpos) > 1:
        for _ in range(FLOOR_PASSES if floor_bound else 1):  # smooth[, then never below]
            shift = gaussian_filter1d(shift, CONSISTENT_SMOOTH_S * rate, mode="nearest")
            if floor_bound:
                shift = np.minimum(shift, low)
    return shift


def contact_consistent(
    model, qpos: np.ndarray, rate: float = 120.0, *, floating: bool = False
) -> np.ndarray:
    """A copy of ``qpos`` (T, nq, its floor near z = 0, e.g. from :func:`on_floor` with no lift)
    shifted vertically frame by frame so that in stance the lower sole (its lowest surface
    point, :func:`lowest_foot_point`) touches the floor at z = 0: feet meet the floor where
    the reference stands on it, instead of hovering or sinking by the floor estimate's error.
    A frame is in stance when its lowest sole point is within :data:`STANCE_GAP`; between
    stance frames (flight) the shift is interpolated; the shift is then smoothed by a Gaussian
    of :data:`CONSISTENT_SMOOTH_S` (no jumps): :func:`contact_shift` (``floating``: its
    option). A motion that never stands comes back as is."""
    out = qpos.copy()
    out[:, 2] -= contact_shift(model, qpos, rate, floating=floating)
    return out
