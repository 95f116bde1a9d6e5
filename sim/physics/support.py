"""Whether the floor supports a motion: frames needing support found nowhere on it, forces held
by something else, and why a frame's required force is not all the floor's.

Read per motion by :class:`sim.analysis.job.PhysicsJob` (its ``support_*`` figures and
``residual_force_bw_by_cause``) and per trial by :func:`support_verdict`.

Units: newtons, body weights (BW), metres, seconds.
"""

from __future__ import annotations

import numpy as np

from sim.physics.dynamics import MU, PYRAMID_EDGES

#: A frame whose motion needs this much external force [body weights] with nothing on the floor
#: lacks support the labels found (a jump's flight needs none: it falls freely).
SUPPORT_MISSING_BW = 0.5
#: A trial whose original lacks found support in more than this share of frames is flagged.
SUPPORT_FLAG_SHARE = 0.05
#: [m/s] the lower foot slower than this horizontally, higher than HOLD_GAP above the floor,
#: while support is missing, stands on something above the floor (a box, a climbing frame).
PLANTED_SPEED = 0.25

#: [BW] a horizontal residual force this large, for at least HELD_S [s], is held by something
#: else: the floor cannot push sideways beyond friction nor at all without contact, and the
#: source filter spreads an impact over +-2 frames at 30 fps (5 frames, 0.17 s), shorter than
#: HELD_S. 0.15 BW is 20x the residual's noise floor (0.007 BW at 1.5 mm of marker noise); the
#: CMU captures' own jitter in flight reaches it in single frames, never for HELD_S. On
#: ../shared/cmu no trial whose support is found holds a run of it; 61_01 (salsa) is held in
#: 6.7 % of its frames (3.9 % at 0.25 BW; at 0.27 s instead of 0.2 s, 1.5 %: its partner's pulls
#: last 0.2-0.25 s).
HELD_BW, HELD_S = 0.15, 0.2
#: A trial whose original is held in more than this share of its measured frames is flagged.
HELD_FLAG_SHARE = 0.02


def held_frames(
    residual_force: np.ndarray, weight: float, fps: float, measured: np.ndarray | None = None
) -> np.ndarray:
    """(T,) bool: frames in runs of at least :data:`HELD_S` seconds of consecutive measured
    frames whose residual force ``residual_force`` (T, 3) [N] has a horizontal part over
    :data:`HELD_BW` body weights (``weight`` [N]): a sustained sideways pull or push no floor
    contact can supply (a partner, a prop, a rail). An impact's force spread by the derivative
    filter lasts less; so do single bad frames."""
    r = np.asarray(residual_force, dtype=np.float64)
    on = np.linalg.norm(r[:, :2], axis=1) > HELD_BW * weight
    if measured is not None:
        on &= np.asarray(measured, dtype=bool)
    need = int(np.ceil(HELD_S * fps - 1e-9))
    out = np.zeros(len(on), dtype=bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], on.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if b - a >= need:
            out[a:b] = True
    return out


#: The causes of :func:`residual_causes`, in order.
RESIDUAL_CAUSES = ("no contact", "pulling", "outside the friction cone")


def residual_causes(
    force: np.ndarray, supported: np.ndarray, mu: float = MU, edges: int = PYRAMID_EDGES
) -> np.ndarray:
    """(T,) int index into :data:`RESIDUAL_CAUSES` of why a frame's required force ``force``
    (T, 3) [N] is not all supplied by the floor: 0 nothing on the floor where ground forces may
    act (``supported`` (T,) False), 1 it needs pulling down (F_z < 0), 2 it is too horizontal
    for friction (outside the ``edges``-edge pyramid of coefficient ``mu`` that
    :func:`sim.physics.dynamics.residual_wrench` fits: for 4 edges |F_x| + |F_y| > mu F_z),
    -1 none (inside it: the contacts supply it all)."""
    F = np.asarray(force, dtype=np.float64)
    out = np.full(len(F), -1)
    # the pyramid's faces: outward normals between its edges, at mu F_z cos(pi / edges)
    a = 2 * np.pi * (np.arange(edges) + 0.5) / edges
    reach = (F[:, :2] @ np.stack([np.cos(a), np.sin(a)])).max(axis=1)
    out[reach > mu * np.cos(np.pi / edges) * F[:, 2] + 1e-9 * np.abs(F).max(initial=1.0)] = 2
    out[F[:, 2] < 0] = 1
    out[~np.asarray(supported, dtype=bool)] = 0
    return out


def capture_unsupported(missing: float | None) -> bool:
    """Whether a clip's original capture lacks support on the floor, from the share of its
    measured frames that need more than :data:`SUPPORT_MISSING_BW` from outside with nothing on
    the floor (``missing``: its ``support_missing_share``; None: not measured, False): more than
    :data:`SUPPORT_FLAG_SHARE`, the trial's rule (:func:`support_verdict`) applied to the clip. No
    body performs such a capture as captured on that floor: a squat held up by nothing, a climb
    on equipment, a partner's hold."""
    return missing is not None and missing > SUPPORT_FLAG_SHARE


def support_verdict(
    missing: float,
    above: float,
    floor_fits: bool,
    above_mm: float | None = None,
    held: float = 0.0,
) -> tuple[bool, str]:
    """Whether a trial's support is off the floor, and why, from the shares of its original's
    frames with support missing (``missing``), of them with it missing while a foot stands
    still above the floor (``above``; ``above_mm`` how high, median), and with a sustained
    horizontal force no contact supplies (``held``, :func:`held_frames`)."""
    if not (missing > SUPPORT_FLAG_SHARE or held > HELD_FLAG_SHARE):
        return False, ""
    if not missing > SUPPORT_FLAG_SHARE:
        share = (
            f"{100 * held:.0f} % of frames need a horizontal force over {HELD_BW:g} BW for "
            f"{HELD_S:g} s or longer that no floor contact supplies"
        )
        if not floor_fits:
            return True, f"{share}; the floor does not fit"
        return True, f"{share}; held by something else (a partner, a prop)"
    share = f"{100 * missing:.0f} % of frames need support found nowhere on the floor"
    if above >= missing / 2:
        high = "" if above_mm is None else f" about {above_mm / 10:.0f} cm"
        return True, (
            f"{share}; the lower foot stands still{high} above it then (a box, a climbing frame, "
            "or a sole unlike the humanoid's)"
        )
    if not floor_fits:
        return True, f"{share}; the floor does not fit"
    return True, f"{share}; held by something else (a partner, a prop) or touching unseen"
