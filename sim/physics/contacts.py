"""Foot contacts of the original and PhysDiff-style contact metrics of a reconstruction.

Labels: a foot point (ankle ~ heel, ball, toes; :data:`sim.physics.ground.FOOT_POINTS`) is in
contact when its height above its stance level (``z - ground_z - clearance``, see
:mod:`sim.physics.ground`) and its speed are both low, with hysteresis so that marker noise does
not flicker the label: it *enters* contact below ``h_on`` and ``v_on`` and *leaves* above ``h_off``
or ``v_off``.

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
from sim.physics.ground import Ground, horizontal_speed
from sim.replay.foot_state import FootState

H_ON, H_OFF = 0.03, 0.05  # [m] enter contact below H_ON, leave above H_OFF
V_ON, V_OFF = 0.3, 0.5  # [m/s] enter contact below V_ON, leave above V_OFF


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
) -> np.ndarray:
    """(T, F) contact labels with hysteresis.

    Args:
        height: (T, F) height of each foot point above its stance level [m].
        speed: (T, F) its speed [m/s].
    Returns:
        bool (T, F): a point enters contact when ``height < h_on`` and ``speed < v_on``, stays in
        contact until ``height > h_off`` or ``speed > v_off``.
    """
    height, speed = np.asarray(height), np.asarray(speed)
    if height.shape != speed.shape or height.ndim != 2:
        raise ValueError(f"height and speed must both be (T, F); got {height.shape}, {speed.shape}")
    if not (h_on <= h_off and v_on <= v_off):
        raise ValueError("hysteresis needs h_on <= h_off and v_on <= v_off")
    out = np.zeros(height.shape, dtype=bool)
    state = np.zeros(height.shape[1], dtype=bool)
    for t in range(height.shape[0]):
        enter = (height[t] < h_on) & (speed[t] < v_on)
        leave = (height[t] > h_off) | (speed[t] > v_off)
        state = np.where(state, ~leave, enter)
        out[t] = state
    return out


def foot_heights(positions: np.ndarray, ground_z: float, clearance: np.ndarray) -> np.ndarray:
    """(T, F) height [m] of foot points ``positions`` (T, F, 3) above their stance levels."""
    return np.asarray(positions)[..., 2] - ground_z - np.asarray(clearance)


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
    clearance = ground.clearance_of(names)

    def measure(m: PointMotion):
        p = m.positions[:, [m.names.index(n) for n in names]]
        h = foot_heights(p, ground.z, clearance)
        return h, label_contacts(h, point_speed(p, m.fps)), horizontal_speed(p, m.fps)

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
