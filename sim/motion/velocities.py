"""True velocities: ``qvel`` from ``qpos`` and point velocities from the kinematic chain.

``qvel`` comes from central differences of ``qpos`` through ``mujoco.mj_differentiatePos`` (so the
free joint's quaternion is differentiated on the rotation group), one-sided at the ends, and
one-sided beside a pose jump of the data (:func:`pose_jumps`). Point velocities are then
``v = J(q) q̇``: MuJoCo's ``cvel`` (built from ``cdof`` by ``mj_comVel``) moved to each point, never
differences of positions.
"""

from __future__ import annotations

import functools

import mujoco
import numba
import numpy as np

from sim.model import quaternion as quat

#: A body's turn between two source frames is a pose jump (a glitch of the capture's solver, not
#: motion: e.g. a femur turning 180 deg in 1/120 s while the ankle stays put) when it is faster
#: than JUMP_RATE [rad/s] (50 rad/s: 25 deg per frame at 120 fps) and more than JUMP_RATIO times
#: the median of the JUMP_WINDOW steps either side, so fast but steady motion never is one; the
#: bones of its chain that turn as suddenly (any rate) jump with it.
JUMP_RATE, JUMP_RATIO, JUMP_WINDOW = 50.0, 3.0, 4


def body_joint_rotations(model, qpos: np.ndarray) -> np.ndarray:
    """(T, nbody, 4) rotation ``wxyz`` of each body relative to its parent made by its own joints
    (hinges, ball and free joints, composed as MuJoCo does; slides and jointless bodies:
    identity) in each frame of ``qpos`` (T, nq). The body's fixed offset is left out.

    Composed on contiguous component rows (:func:`_body_rows`), each product term for term
    :func:`sim.model.quaternion.mul`'s in one compiled pass (:func:`_mul_rows`): the same
    numbers, faster than numpy's products of (T, 4) columns strided across the bodies."""
    return np.ascontiguousarray(_body_rows(model, qpos).transpose(2, 0, 1))


def _body_rows(model, qpos: np.ndarray, only: int = -1) -> np.ndarray:
    """(nbody, 4, T): :func:`body_joint_rotations`, each component a contiguous row (``only``
    >= 0: that body's alone, the others left the identity)."""
    T = qpos.shape[0]
    rot = np.zeros((model.nbody, 4, T))
    rot[:, 0] = 1.0
    moved = np.zeros(model.nbody, dtype=bool)  # bodies whose rotation is no longer the identity
    for j in range(model.njnt):
        kind, adr, b = model.jnt_type[j], model.jnt_qposadr[j], model.jnt_bodyid[j]
        if only >= 0 and b != only:
            continue
        if kind == mujoco.mjtJoint.mjJNT_HINGE:
            half = 0.5 * qpos[:, adr]
            local = np.empty((4, T))
            local[0] = np.cos(half)
            np.multiply(np.sin(half), model.jnt_axis[j][:, None], out=local[1:])
        elif kind == mujoco.mjtJoint.mjJNT_BALL:
            local = np.ascontiguousarray(qpos[:, adr : adr + 4].T)
        elif kind == mujoco.mjtJoint.mjJNT_FREE:
            local = np.ascontiguousarray(qpos[:, adr + 3 : adr + 7].T)
        else:
            continue
        # a body's joints compose left to right (the first needs no product with the identity)
        if moved[b]:
            _mul_rows(rot[b], local, rot[b])
        else:
            rot[b] = local
        moved[b] = True
    return rot


@numba.njit(cache=True, nogil=True)
def _mul_rows(a, b, out):
    """The Hamilton products ``a * b`` of quaternions laid out as (4, T) component rows, into
    ``out`` (4, T) (may be ``a``): :func:`sim.model.quaternion.mul`'s terms in its order (no
    fused or reordered operation: the same numbers)."""
    for t in range(a.shape[1]):
        aw, ax, ay, az = a[0, t], a[1, t], a[2, t], a[3, t]
        bw, bx, by, bz = b[0, t], b[1, t], b[2, t], b[3, t]
        out[0, t] = aw * bw - ax * bx - ay * by - az * bz
        out[1, t] = aw * bx + ax * bw + ay * bz - az * by
        out[2, t] = aw * by - ax * bz + ay * bw + az * bx
        out[3, t] = aw * bz + ax * by - ay * bx + az * bw


def rotation_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...) angle [rad] of the turn from unit quaternions ``a`` to ``b`` (..., 4), in [0, pi]."""
    rel = quat.mul(quat.conj(a), b)
    return 2 * np.arctan2(np.linalg.norm(rel[..., 1:], axis=-1), np.abs(rel[..., 0]))


def body_rotation_steps(model, qpos: np.ndarray) -> np.ndarray:
    """(T-1, nbody) angle [rad] by which each body turns relative to its parent from frame t to
    t+1 of ``qpos`` (T, nq), by its own joints (:func:`body_joint_rotations`).

    :func:`rotation_angle` of consecutive frames with its conjugate and product on the rows of
    :func:`_body_rows` (term for term) and its norm and arctangent on the same (..., 3) and
    (...) layouts it uses: the same numbers."""
    rows = _body_rows(model, qpos)
    nb, T = rows.shape[0], rows.shape[2]
    sign = np.array([1.0, -1.0, -1.0, -1.0])
    conj = rows[:, :, :-1].transpose(1, 0, 2) * sign[:, None, None]  # quat.conj's product
    after = np.ascontiguousarray(rows[:, :, 1:].transpose(1, 0, 2))  # (4, nbody, T-1)
    rel = np.empty((4, nb, T - 1))
    _mul_rows(conj.reshape(4, -1), after.reshape(4, -1), rel.reshape(4, -1))
    vec = np.stack([rel[1], rel[2], rel[3]], axis=-1)  # (nbody, T-1, 3), as rel[..., 1:]
    angle = 2 * np.arctan2(np.linalg.norm(vec, axis=-1), np.abs(rel[0]))
    return np.ascontiguousarray(angle.T)


def kin_related(model) -> np.ndarray:
    """(nbody, nbody) bool: body a is body b, one of its ancestors or one of its descendants
    (the world is related to none)."""
    n = model.nbody
    related = np.eye(n, dtype=bool)
    for b in range(1, n):
        a = model.body_parentid[b]
        while a > 0:
            related[a, b] = related[b, a] = True
            a = model.body_parentid[a]
    related[0] = related[:, 0] = False
    return related


def point_cuts(model, jumps: np.ndarray, body_ids) -> np.ndarray:
    """(T-1, J) bool: pose jumps (``jumps`` (T-1, nbody)) that move points on bodies
    ``body_ids`` (J,): a jump of the point's body or of any body above it."""
    body_ids = np.asarray(body_ids)
    above = np.zeros((model.nbody, len(body_ids)), dtype=bool)
    for j, b in enumerate(body_ids):
        while b > 0:
            above[b, j] = True
            b = model.body_parentid[b]
    return (np.asarray(jumps, dtype=np.int64) @ above.astype(np.int64)) > 0


def pose_jumps(steps: np.ndarray, fps: float, related: np.ndarray | None = None) -> np.ndarray:
    """(T-1, nbody) bool: the step from frame t to t+1 is a pose jump of that body.

    Args:
        steps: (T-1, nbody) turn of each body between frames [rad]
            (:func:`body_rotation_steps`).
        fps: frames per second of the stream.
        related: (nbody, nbody) bool, which bodies share a chain (:func:`kin_related`; None:
            every body with every body).

    A body's step is an outlier when it is more than :data:`JUMP_RATIO` times the median of the
    :data:`JUMP_WINDOW` steps on each side of it (itself left out). It is a jump when it is
    also faster than :data:`JUMP_RATE`, or when a body of its chain (an ancestor or descendant)
    jumps in the same step: one glitch of the capture solver turns a whole limb, some bones less
    than the rate.
    """
    s = np.asarray(steps, dtype=np.float64)
    jumps = np.zeros(s.shape, dtype=bool)
    rows = np.flatnonzero((s * fps > JUMP_RATE).any(axis=1))  # the only candidates
    if len(rows) == 0:
        return jumps
    w, n = JUMP_WINDOW, s.shape[0]
    near = rows[:, None] + np.array([d for d in range(-w, w + 1) if d != 0])
    inside = (near >= 0) & (near < n)
    around = np.where(inside[..., None], s[np.clip(near, 0, n - 1)], np.nan)
    typical = np.zeros((len(rows), s.shape[1]))
    some = inside.any(axis=1)
    typical[some] = np.nanmedian(around[some], axis=1)
    outlier = s[rows] > JUMP_RATIO * typical
    core = outlier & (s[rows] * fps > JUMP_RATE)
    if related is None:
        jumps[rows] = outlier & core.any(axis=1, keepdims=True)
        return jumps
    link = related.astype(np.int64)
    jumping = core
    while True:  # spread through chains of outliers: a whole-body glitch reaches every limb
        grown = outlier & ((jumping.astype(np.int64) @ link) > 0)
        if (grown == jumping).all():
            break
        jumping = grown
    jumps[rows] = jumping
    return jumps


def qvel_from_qpos(
    model,
    qpos: np.ndarray,
    fps: float,
    frames: np.ndarray | None = None,
    *,
    across_jumps: bool = True,
    jumps: np.ndarray | None = None,
):
    """(F, nv) generalised velocities at ``frames`` of a ``qpos`` stream sampled at ``fps``.

    Central differences ``(q[t+1] ⊖ q[t-1]) / 2h`` inside, one-sided at the first and last frame.

    Unless ``across_jumps``, the dofs of a body beside one of its pose jumps (:func:`pose_jumps`)
    are differenced away from it: a jump on one side, the one-sided difference on the other; on
    both sides, the central difference when the frame is a lone outlier (its neighbours agree
    with each other), else, inside a run of jumps, the one-sided difference of the nearest step
    without a jump. The data's jump stays in the positions; it does not become a velocity of
    hundreds of rad/s.

    Args:
        qpos: (T, nq) positions sampled every ``1 / fps`` seconds.
        frames: indices where velocities are wanted (default: all T).
        across_jumps: difference straight across pose jumps (the plain stencil).
        jumps: (T-1, nbody) the stream's pose jumps when already known (default: found here).
    """
    T = qpos.shape[0]
    frames = np.arange(T) if frames is None else np.asarray(frames)
    out = np.zeros((len(frames), model.nv))
    if T < 2:
        return out
    h = 1.0 / fps
    for k, t in enumerate(frames):
        a, b = max(t - 1, 0), min(t + 1, T - 1)
        mujoco.mj_differentiatePos(model, out[k], (b - a) * h, qpos[a], qpos[b])
    if across_jumps or T < 3:
        return out
    if jumps is None:
        jumps = pose_jumps(body_rotation_steps(model, qpos), fps, kin_related(model))
    bodies = np.flatnonzero(jumps.any(axis=0))
    ks = np.flatnonzero((frames > 0) & (frames < T - 1))
    if len(bodies) == 0 or len(ks) == 0:
        return out
    J = jumps[:, bodies]  # (T-1, B)
    t = frames[ks][:, None]  # (F', 1)
    before, after = J[t[:, 0] - 1], J[t[:, 0]]  # (F', B): the steps into and out of each frame
    # the step whose one-sided difference each (frame, body) takes; -1: keep the central one
    use = np.where(before & ~after, t, np.where(after & ~before, t - 1, -1))
    steps_idx = np.arange(T - 1)[:, None]
    last_clean = np.maximum.accumulate(np.where(~J, steps_idx, -1), axis=0)
    next_clean = np.minimum.accumulate(np.where(~J, steps_idx, T)[::-1], axis=0)[::-1]
    for i, c in np.argwhere(before & after):  # frames between two jumps: rare
        f, b = int(t[i, 0]), bodies[c]
        rot = _body_rows(model, qpos[f - 1 : f + 2], only=b)[b].T  # frames f-1, f, f+1
        step_in, step_out = rotation_angle(rot[0], rot[1]), rotation_angle(rot[1], rot[2])
        if rotation_angle(rot[0], rot[2]) < min(step_in, step_out) / 2:
            continue  # a lone outlier frame: the central difference steps over it
        back = last_clean[f - 2, c] if f >= 2 else -1
        ahead = next_clean[f + 1, c] if f + 1 < T - 1 else T
        options = ([(f - 1 - back, back)] if back >= 0 else []) + (
            [(ahead - f, ahead)] if ahead < T else []
        )
        if options:
            use[i, c] = min(options)[1]
    rates = {}  # step s -> (nv,) one-sided difference from frame s to s + 1
    for i, c in np.argwhere(use >= 0):
        s = int(use[i, c])
        if s not in rates:
            rates[s] = np.zeros(model.nv)
            mujoco.mj_differentiatePos(model, rates[s], h, qpos[s], qpos[s + 1])
        dofs = model.dof_bodyid == bodies[c]
        out[ks[i], dofs] = rates[s][dofs]
    return out


#: Derivatives of the original's points from its source frames: a local polynomial of degree
#: SOURCE_DEGREE through SOURCE_WINDOW source samples around each frame (at CMU's 120 fps, 17
#: samples = +-67 ms, two 30 fps frames either side). Its gain (:func:`local_polynomial_gain`)
#: on an acceleration is 1.00 up to 3 Hz, 0.975 at 5 Hz and 0.72 at 10 Hz (velocity: 0.994,
#: 0.96, 0.59); an impulse spreads over +-2 frames at 30 fps and no further. Marker noise is why
#: it is not the exact 3-sample difference: at 120 Hz a second difference turns 1 mm of noise
#: into ~35 m/s^2. Near a take's ends (and a pose jump) the window shifts inward: a degree-4 fit
#: read at its first sample amplifies noise 5x more than the centred one, but a lower degree
#: there misses 60 % of a 1.5 Hz acceleration.
SOURCE_WINDOW, SOURCE_DEGREE = 17, 4
#: :func:`derivative_noise` where fewer than 3 samples lie on a point's side of its pose jumps
#: (its derivatives are then read across the jump: nothing is measured there).
NO_WINDOW_NOISE = 1e9


def local_polynomial_weights(k: int, where: int, h: float, degree: int) -> np.ndarray:
    """(2, k) weights giving the first and second derivative at sample ``where`` of ``k`` samples
    ``h`` [s] apart from the least-squares polynomial of ``degree`` through them."""
    x = (np.arange(k) - where) * h
    V = np.vander(x, degree + 1, increasing=True)
    coef = np.linalg.pinv(V)
    return np.stack([coef[1], 2 * coef[2] if degree >= 2 else 0 * coef[1]])


@functools.lru_cache(maxsize=4096)
def _unit_weights(k: int, where: int, degree: int) -> np.ndarray:
    w = local_polynomial_weights(k, where, 1.0, degree)
    w.flags.writeable = False
    return w


def local_polynomial_gain(freq, fps: float, k: int = SOURCE_WINDOW, degree: int = SOURCE_DEGREE):
    """(velocity, acceleration) gains of the centred local polynomial on a sinusoid of
    frequency ``freq`` [Hz] sampled at ``fps``: 1 where it differentiates exactly."""
    f = np.atleast_1d(np.asarray(freq, dtype=np.float64))
    W = local_polynomial_weights(k, k // 2, 1.0 / fps, degree)
    t = (np.arange(k) - k // 2) / fps
    w = 2 * np.pi * f[:, None]
    vel = (W[0] * np.sin(w * t)).sum(axis=1) / w[:, 0]
    acc = -(W[1] * np.cos(w * t)).sum(axis=1) / w[:, 0] ** 2
    return vel, acc


def _window(t: int, first: int, stop: int, k: int) -> tuple[int, int]:
    """(start, length) of the window of at most ``k`` samples of ``[first, stop)`` around ``t``."""
    n = min(k, stop - first)
    return int(np.clip(t - k // 2, first, stop - n)), n


def _cut_windows(frames: np.ndarray, T: int, window: int, cut: np.ndarray, starts):
    """The windows of the frames whose window straddles a cut of their point: yields
    ``(i, j, lo, n)``, frame ``frames[i]`` of point ``j`` reads samples ``[lo, lo + n)`` (``n < 3``:
    nothing better exists). ``cut`` (T-1, J) bool; ``starts`` the uncut ``(lo, n)`` per frame."""
    steps = np.arange(T - 1)
    lo_all = np.array([lo for lo, _ in starts])
    n_all = np.array([n for _, n in starts])
    for j in np.flatnonzero(cut.any(axis=0)):
        at = steps[cut[:, j]]  # sample t+1 starts a new piece after step t
        first = np.concatenate([[0], at + 1])
        stop = np.concatenate([at + 1, [T]])
        piece = np.searchsorted(first, frames, side="right") - 1
        long = np.flatnonzero(stop - first >= 3)
        k = np.searchsorted(at, lo_all)
        reach = (k < len(at)) & (at[np.minimum(k, len(at) - 1)] < lo_all + n_all - 1)
        for i in np.flatnonzero(reach):  # frames whose window straddles a cut
            t = frames[i]
            q = piece[i]
            if stop[q] - first[q] < 3 and len(long):  # one or two samples between two cuts:
                q = long[np.argmin(np.abs(long - q))]  # read the nearest longer piece's fit
            lo, n = _window(int(t), first[q], stop[q], window)
            yield int(i), int(j), lo, n


def point_derivatives(
    positions: np.ndarray,
    fps: float,
    frames: np.ndarray | None = None,
    *,
    window: int = SOURCE_WINDOW,
    degree: int = SOURCE_DEGREE,
    cuts: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations (F, J, 3) [m/s, m/s^2] at ``frames`` of points
    ``positions`` (T, J, 3) [m] sampled at ``fps``, by the local polynomial of
    :data:`SOURCE_WINDOW` (fewer than 3 samples: zeros).

    ``cuts``: (T-1, J) bool, the step from sample t to t+1 of point j is not to be differenced
    across (a pose jump of the data, :func:`pose_jumps`): the point's windows stay on the side of
    the frame, as at a take's ends. How much more noise such a shifted window lets through:
    :func:`derivative_noise`."""
    p = np.asarray(positions, dtype=np.float64)
    T = p.shape[0]
    frames = np.arange(T) if frames is None else np.asarray(frames)
    vel = np.zeros((len(frames),) + p.shape[1:])
    acc = np.zeros_like(vel)
    if min(window, T) < 3:
        return vel, acc
    h = 1.0 / fps

    def weights(n, w):
        W = _unit_weights(n, w, min(degree, n - 1))
        return W[0] / h, W[1] / h**2

    starts = [_window(int(t), 0, T, window) for t in frames]
    groups: dict = {}
    for i, (lo, n) in enumerate(starts):
        groups.setdefault((n, int(frames[i]) - lo), []).append(i)
    for (n, w), sel in groups.items():
        sel = np.array(sel)
        lo = np.array([starts[i][0] for i in sel])
        stack = p[lo[:, None] + np.arange(n)]  # (m, n, J, 3)
        Wv, Wa = weights(n, w)
        vel[sel] = np.einsum("k,nkjc->njc", Wv, stack)
        acc[sel] = np.einsum("k,nkjc->njc", Wa, stack)
    if cuts is None or not np.any(cuts):
        return vel, acc
    for i, j, lo, n in _cut_windows(frames, T, window, np.asarray(cuts, dtype=bool), starts):
        if n < 3:
            continue  # nothing better exists
        Wv, Wa = weights(n, int(frames[i]) - lo)
        vel[i, j] = Wv @ p[lo : lo + n, j]
        acc[i, j] = Wa @ p[lo : lo + n, j]
    return vel, acc


def _noise_gain(n: int, where: int, window: int, degree: int) -> float:
    """The acceleration noise gain of the fit through ``n`` samples read at ``where``, relative
    to the centred ``window``-sample fit (:data:`NO_WINDOW_NOISE` below 3 samples)."""
    if n < 3:
        return NO_WINDOW_NOISE
    centred = _unit_weights(window, window // 2, min(degree, window - 1))[1]
    own = _unit_weights(n, where, min(degree, n - 1))[1]
    return float(np.linalg.norm(own) / np.linalg.norm(centred))


def derivative_noise(
    T: int,
    frames: np.ndarray | None = None,
    *,
    window: int = SOURCE_WINDOW,
    degree: int = SOURCE_DEGREE,
    cuts: np.ndarray | None = None,
    points: int = 1,
) -> np.ndarray:
    """(F, J) how much more sample noise reaches the acceleration :func:`point_derivatives`
    gives at ``frames`` of T samples than reaches the centred fit of ``window`` samples
    (dimensionless RMS ratio; 1 where the window is centred, :data:`NO_WINDOW_NOISE` where
    fewer than 3 samples exist). ``cuts`` (T-1, J) as there; without them every one of ``points`` points (J) is alike.

    A window shifted against a take's end or a pose jump reads its polynomial near the edge,
    where it extrapolates: degree 4 through 17 samples read at the first one passes 5.3 times
    the centred fit's noise (3.9, 2.7, 1.7 at the second to fourth; a 9-sample piece between two
    jumps 27 times), turning the 1-2 mm of a marker's jitter into body weights of force. Nothing
    measures those frames better: a longer one-sided window that lets no more noise through
    misses more than the signal (its acceleration is off by 135 % at 3 Hz), a lower degree
    misses the curvature."""
    frames = np.arange(T) if frames is None else np.asarray(frames)
    J = points if cuts is None else np.shape(cuts)[1]
    out = np.ones((len(frames), J))
    starts = [_window(int(t), 0, T, window) for t in frames]
    for i, (lo, n) in enumerate(starts):
        out[i] = _noise_gain(n, int(frames[i]) - lo, window, degree)
    if cuts is None or not np.any(cuts):
        return out
    for i, j, lo, n in _cut_windows(frames, T, window, np.asarray(cuts, dtype=bool), starts):
        out[i, j] = _noise_gain(n, int(frames[i]) - lo, window, degree)
    return out


def point_kinematics(model, data, qpos, qvel, body_ids, site_ids):
    """Positions, velocities and body orientations along a trajectory.

    Args:
        qpos: (T, nq); qvel: (T, nv) (None: at rest; the velocities are zeros and not computed).
        body_ids: (J,) body of each point; site_ids: (J,) site at each point (-1: the body origin).

    Returns:
        positions (T, J, 3) [m], velocities (T, J, 3) [m/s], body quaternions (T, J, 4) ``wxyz``,
        body angular velocities (T, J, 3) [rad/s], all in the world frame.
    """
    if qvel is None:
        return _point_poses(model, data, qpos, body_ids, site_ids)
    T = qpos.shape[0]
    body_ids = np.asarray(body_ids)
    site_ids = np.asarray(site_ids)
    has_site = site_ids >= 0
    root_of = model.body_rootid[body_ids]
    xpos = np.empty((T, model.nbody, 3))
    xquat = np.empty((T, model.nbody, 4))
    site_xpos = np.empty((T, model.nsite, 3))
    cvel = np.empty((T, model.nbody, 6))  # [angular; linear] at the subtree com of the root body
    com = np.empty((T, model.nbody, 3))
    # MjData's arrays are views of its buffers, made anew at every attribute access: once here
    d_qpos, d_qvel, d_xpos, d_xquat = data.qpos, data.qvel, data.xpos, data.xquat
    d_site, d_cvel, d_com = data.site_xpos, data.cvel, data.subtree_com
    for t in range(T):
        d_qpos[:] = qpos[t]
        d_qvel[:] = qvel[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_comVel(model, data)
        xpos[t] = d_xpos
        xquat[t] = d_xquat
        site_xpos[t] = d_site
        cvel[t] = d_cvel
        com[t] = d_com
    pos = xpos[:, body_ids]
    pos[:, has_site] = site_xpos[:, site_ids[has_site]]
    v = cvel[:, body_ids]
    vel = v[..., 3:] + np.cross(v[..., :3], pos - com[:, root_of])
    return pos, vel, xquat[:, body_ids], v[..., :3]


def _point_poses(model, data, qpos, body_ids, site_ids):
    """:func:`point_kinematics` at rest: positions and orientations, zero velocities."""
    T = qpos.shape[0]
    body_ids = np.asarray(body_ids)
    site_ids = np.asarray(site_ids)
    has_site = site_ids >= 0
    xpos = np.empty((T, model.nbody, 3))
    xquat = np.empty((T, model.nbody, 4))
    site_xpos = np.empty((T, model.nsite, 3))
    data.qvel[:] = 0.0
    d_qpos, d_xpos, d_xquat, d_site = data.qpos, data.xpos, data.xquat, data.site_xpos
    for t in range(T):
        d_qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        xpos[t] = d_xpos
        xquat[t] = d_xquat
        site_xpos[t] = d_site
    pos = xpos[:, body_ids]
    pos[:, has_site] = site_xpos[:, site_ids[has_site]]
    zero = np.zeros((T, len(body_ids), 3))
    return pos, zero, xquat[:, body_ids], zero.copy()
