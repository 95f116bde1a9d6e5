"""Contact metrics of a motion against the original's foot-floor contacts
(:mod:`sim.physics.contacts`).

Per (frame, foot), each a mean with its sample count:

* ``penetration_mm``: depth of the foot's lowest sole point below the floor, over every sample;
* ``float_mm``: its height above the floor where the *original's* foot is in contact;
* ``skate_mm_s``: the horizontal speed of that point over the same samples;
* ``contact_precision``/``contact_recall``: the motion's own labels against the original's.

PhysDiff's definitions (Yuan et al., ICCV 2023, after UHC's evaluation; :func:`physdiff_metrics`),
named as such so our numbers can sit beside published tables: per frame the lowest point of the
whole body's surface (the sole spheres and every bone's capsule of :mod:`sim.model.capsules`)
against the floor, ``physdiff_penetrate_mm`` its depth below, ``physdiff_float_mm`` its height
above beyond a 5 mm tolerance, means over frames; ``physdiff_skate`` the share of frames in which
a foot in contact in both that frame and the previous one moves more than 2.5 cm horizontally.

Units: metres and m/s in, millimetres and mm/s out.
"""

from __future__ import annotations

import numpy as np

from sim.errors import UsageError
from sim.physics.contacts import Contacts
from sim.physics.feet import Sole
from sim.physics.ground import Ground

#: PhysDiff's float tolerance [m] and skate threshold [m of horizontal travel between frames].
PHYSDIFF_FLOAT_TOL, PHYSDIFF_SKATE_M = 0.005, 0.025


def _mean(x: np.ndarray) -> tuple[float, int]:
    return (float(x.mean()) if x.size else float("nan")), int(x.size)


def contact_metrics(reference: np.ndarray, motion: Contacts) -> dict[str, float]:
    """Contact metrics of ``motion`` against the original's labels ``reference`` (T, F) (same
    feet, same frames); see the module docstring.

    Returns:
        ``penetration_mm`` (+ ``penetration_n``, ``penetration_max_mm``), ``float_mm``
        (+ ``float_n``), ``skate_mm_s`` (+ ``skate_n``), ``contact_precision`` (+
        ``contact_precision_n``: the motion's contact samples), ``contact_recall`` (+
        ``contact_recall_n``: the original's). Means over no samples are NaN.
    """
    ref = np.asarray(reference, dtype=bool)
    own, h, v = motion.contact, motion.foot_gap, motion.foot_speed
    if not (ref.shape == own.shape == h.shape == v.shape):
        raise UsageError("contact metrics need arrays of one shape (T, F)")
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


def lowest_body_point(
    positions, names, parents, radius, ground: Ground, s: Sole, *, bones=None
) -> np.ndarray:
    """(T,) height [m] above the floor of the lowest point of the body's surface: the capsule of
    every bone (``radius`` (B,) for the B non-root points in order, on the segment from its
    parent; ``bones`` (B,) bool: which count, default all) and the sole spheres of ``s`` (their
    gaps, with the feet's stance offsets)."""
    p = np.asarray(positions, dtype=np.float64)
    parents = np.asarray(parents)
    child = np.flatnonzero(parents >= 0)
    keep = np.ones(len(child), dtype=bool) if bones is None else np.asarray(bones, dtype=bool)
    child, r = child[keep], np.asarray(radius, dtype=np.float64)[keep]
    sole_low = ground.gaps(s).min(axis=1)
    if not len(child):
        return sole_low
    ends = np.concatenate([p[:, child], p[:, parents[child]]], axis=1)  # (T, 2B, 3)
    h = ends[..., 2] - ground.level(ends[..., :2]) - np.concatenate([r, r])
    return np.minimum(h.min(axis=1), sole_low)


def physdiff_metrics(lowest: np.ndarray, contacts: Contacts, fps: float) -> dict[str, float]:
    """PhysDiff's ground metrics (see the module docstring) from the lowest body point's height
    ``lowest`` (T,) [m] and the motion's own foot contacts.

    Returns ``physdiff_penetrate_mm``, ``physdiff_float_mm`` (means over frames) and
    ``physdiff_skate`` (share of frame pairs), with ``physdiff_n`` frames."""
    lo = np.asarray(lowest, dtype=np.float64)
    c = contacts.contact
    step = np.linalg.norm(np.diff(contacts.lowest[..., :2], axis=0), axis=-1)  # (T-1, F)
    both = c[1:] & c[:-1]
    skate = (both & (step > PHYSDIFF_SKATE_M)).any(axis=1)
    return {
        "physdiff_penetrate_mm": 1e3 * float(np.maximum(-lo, 0.0).mean()) if lo.size else 0.0,
        "physdiff_float_mm": 1e3 * float(np.maximum(lo - PHYSDIFF_FLOAT_TOL, 0.0).mean())
        if lo.size
        else 0.0,
        "physdiff_skate": float(skate.mean()) if skate.size else 0.0,
        "physdiff_n": int(lo.size),
    }
