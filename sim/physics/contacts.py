"""Foot contacts of the original and PhysDiff-style contact metrics of a reconstruction.

Labels: a foot point (heel, ball, toes; :data:`sim.physics.feet.FOOT_POINTS`) is in contact when
its height above its stance level on the trial's floor (:meth:`sim.physics.ground.Ground.heights`)
is low and it is slow, with hysteresis so that marker noise does not flicker the label: it
*enters* contact below ``h_on`` and ``v_on`` and *leaves* above ``h_off`` or ``v_off``
(thresholds in :mod:`sim.physics.feet`). A foot rolling heel to toe moves its lifting points at
0.5-2 m/s while they are still 1-2 cm up: while another point of the same foot is low and slow
(the pivot), a low point counts as in contact up to ``v_roll``.

Metrics of a motion against the original's contacts (Yuan et al., PhysDiff, ICCV 2023, adapted to
per-point contacts), each a mean with its sample count:

* ``penetration_mm``: depth below the stance level, ``max(0, -height)``, over every
  (frame, foot point) sample;
* ``float_mm``: ``max(0, height)`` over the samples where the *original's* point is in contact;
* ``skate_mm_s``: horizontal speed over the same samples;
* ``contact_precision``/``contact_recall``: the motion's own labels against the original's.

Units: metres and m/s in, millimetres and mm/s out.
"""

from __future__ import annotations

import numpy as np

from sim.motion.points import PointMotion
from sim.physics.feet import H_OFF, H_ON, V_OFF, V_ON, V_ROLL, side
from sim.physics.ground import Ground, horizontal_speed
from sim.replay.foot_state import FootState


def point_speed(positions: np.ndarray, fps: float) -> np.ndarray:
    """(T, ...) speed [m/s] of ``positions`` (T, ..., 3) [m] by central differences."""
    p = np.asarray(positions, dtype=np.float64)
    if p.shape[0] < 2:
        return np.zeros(p.shape[:-1])
    return np.linalg.norm(np.gradient(p, 1.0 / fps, axis=0), axis=-1)


def label_contacts(
    height: np.ndarray,
    speed: np.ndarray,
    *,
    h_on: float = H_ON,
    h_off: float = H_OFF,
    v_on: float = V_ON,
    v_off: float = V_OFF,
    v_roll: float = V_ROLL,
    points=None,
) -> np.ndarray:
    """(T, F) contact labels with hysteresis.

    Args:
        height: (T, F) height of each foot point above its stance level [m].
        speed: (T, F) its speed [m/s].
        points: (F,) foot point names (:data:`sim.physics.feet.FOOT_POINTS`): points of one foot
            roll together. None: every point on its own (no rolling allowance).
    Returns:
        bool (T, F): a point enters contact when ``height < h_on`` and ``speed < v_on``, stays in
        contact until ``height > h_off`` or ``speed > v_off``; while another point of its foot
        is low and slow (``height < h_on``, ``speed < v_on``), ``v_roll`` replaces ``v_on`` and
        ``v_off``.
    """
    height, speed = np.asarray(height), np.asarray(speed)
    if height.shape != speed.shape or height.ndim != 2:
        raise ValueError(f"height and speed must both be (T, F); got {height.shape}, {speed.shape}")
    if not (h_on <= h_off and v_on <= v_off):
        raise ValueError("hysteresis needs h_on <= h_off and v_on <= v_off")
    F = height.shape[1]
    if points is None:
        same = np.eye(F, dtype=bool)
    else:
        if len(points) != F:
            raise ValueError(f"points must name the {F} columns; got {len(points)}")
        same = np.array([[side(a) == side(b) for b in points] for a in points])
    np.fill_diagonal(same, False)
    pivot_now = (height < h_on) & (speed < v_on)  # (T, F)
    rolling = (pivot_now.astype(int) @ same.T.astype(int)) > 0  # another point of the foot pivots
    v_in = np.where(rolling, max(v_on, v_roll), v_on)
    v_out = np.where(rolling, max(v_off, v_roll), v_off)
    enter_all = (height < h_on) & (speed < v_in)
    leave_all = (height > h_off) | (speed > v_out)
    out = np.zeros(height.shape, dtype=bool)
    state = np.zeros(F, dtype=bool)
    for t in range(height.shape[0]):
        state = np.where(state, ~leave_all[t], enter_all[t])
        out[t] = state
    return out


def foot_heights(positions: np.ndarray, ground: Ground, names) -> np.ndarray:
    """(T, F) height [m] of foot points ``positions`` (T, F, 3) named ``names`` above their stance
    levels on ``ground`` (:meth:`sim.physics.ground.Ground.heights`)."""
    return ground.heights(positions, names)


def trial_contacts(positions: np.ndarray, names, fps: float, ground: Ground):
    """The contact labels of a whole trial, labelled once (the hysteresis' memory runs through).

    Args:
        positions: (T, J, 3) the trial's points [m]; names: (J,); fps [1/s].
    Returns:
        feet (F,) the foot points of ``ground`` present, contact (T, F) bool.
    """
    names = tuple(names)
    feet = tuple(n for n in ground.points if n in names)
    pf = np.asarray(positions, dtype=np.float64)[:, [names.index(n) for n in feet]]
    h = ground.heights(pf, feet)
    return feet, label_contacts(h, point_speed(pf, fps), points=feet)


def _mean(x: np.ndarray) -> tuple[float, int]:
    return (float(x.mean()) if x.size else float("nan")), int(x.size)


def contact_metrics(
    reference_contact: np.ndarray,
    height: np.ndarray,
    horizontal_speed: np.ndarray,
    contact: np.ndarray,
) -> dict[str, float]:
    """PhysDiff-style metrics of a motion's foot points against the original's contacts.

    Args:
        reference_contact: (T, F) the original's contact labels.
        height: (T, F) the motion's heights above stance level [m].
        horizontal_speed: (T, F) its horizontal speeds [m/s].
        contact: (T, F) its own contact labels.
    Returns:
        ``penetration_mm`` (+ ``penetration_n``, ``penetration_max_mm``), ``float_mm``
        (+ ``float_n``), ``skate_mm_s`` (+ ``skate_n``), ``contact_precision`` (+
        ``contact_precision_n``: the motion's contact samples), ``contact_recall`` (+
        ``contact_recall_n``: the original's). Means over no samples are NaN.
    """
    ref = np.asarray(reference_contact, dtype=bool)
    own = np.asarray(contact, dtype=bool)
    h = np.asarray(height, dtype=np.float64)
    v = np.asarray(horizontal_speed, dtype=np.float64)
    if not (ref.shape == own.shape == h.shape == v.shape):
        raise ValueError("contact metrics need arrays of one shape (T, F)")
    pen, n_pen = _mean(np.maximum(-h, 0.0).ravel())
    flo, n_flo = _mean(np.maximum(h[ref], 0.0))
    sk, n_sk = _mean(v[ref])
    tp = int((ref & own).sum())
    return {
        "penetration_mm": 1e3 * pen,
        "penetration_n": n_pen,
        "penetration_max_mm": 1e3 * float(np.maximum(-h, 0.0).max(initial=0.0)),
        "float_mm": 1e3 * flo,
        "float_n": n_flo,
        "skate_mm_s": 1e3 * sk,
        "skate_n": n_sk,
        "contact_precision": tp / own.sum() if own.any() else float("nan"),
        "contact_precision_n": int(own.sum()),
        "contact_recall": tp / ref.sum() if ref.any() else float("nan"),
        "contact_recall_n": int(ref.sum()),
    }


#: Flags of a reconstruction's foot point against the original's contacts, for drawing: floating
#: higher than this above its stance level [m] while the original's is in contact, sinking deeper
#: than this below it [m], skating this much faster horizontally [m/s] while the original's stands.
FLOAT_HEIGHT, SINK_DEPTH, SKATE_SPEED = 0.03, 0.02, 0.3


def foot_states(
    original: PointMotion, reconstruction: PointMotion | None, ground: Ground
) -> FootState:
    """What the renderer draws at the foot points of ``ground`` that both motions have.

    The original's contacts are :func:`label_contacts` of its heights above the stance levels
    and speeds; the reconstruction's own contacts by the same rule, and its flags by
    :data:`FLOAT_HEIGHT`, :data:`SINK_DEPTH` and :data:`SKATE_SPEED` (``None``: no flags).
    """
    names = [n for n in ground.points if n in original.names]
    if reconstruction is not None:
        names = [n for n in names if n in reconstruction.names]

    def measure(m: PointMotion):
        p = m.positions[:, [m.names.index(n) for n in names]]
        h = ground.heights(p, names)
        c = label_contacts(h, point_speed(p, m.fps), points=names)
        return h, c, horizontal_speed(p, m.fps)

    _, contact, s_o = measure(original)
    if reconstruction is None:
        no = np.zeros_like(contact)
        return FootState(tuple(names), contact, contact.copy(), no, no.copy(), no.copy())
    h_r, rec_contact, s_r = measure(reconstruction)
    return FootState(
        points=tuple(names),
        contact=contact,
        rec_contact=rec_contact,
        floating=contact & (h_r > FLOAT_HEIGHT),
        sinking=h_r < -SINK_DEPTH,
        skating=contact & (s_r - s_o > SKATE_SPEED),
    )
