"""What :meth:`sim.analysis.job.PhysicsJob.analyse` returns for a motion (:class:`MotionPhysics`)
against its original, the original itself (``positions=None``) or a reconstruction's points:

* ``ground_z_m`` and the floor's fit (``floor_deviation_mm``, ``floor_fits``, ... of
  :meth:`sim.physics.ground.Ground.summary`): the trial's floor (:mod:`sim.physics.ground`);
  where it does not fit, float and penetration are measured against a floor the feet do not
  follow;
* ``penetration_mm``, ``float_mm``, ``skate_mm_s``, ``contact_precision``, ``contact_recall``
  against the original's contacts (:mod:`sim.physics.contacts`), each with ``*_n`` samples, and
  PhysDiff's ``physdiff_penetrate_mm``, ``physdiff_float_mm``, ``physdiff_skate``;
* ``self_pen_excess_mm``, ``lost_contacts``: self-penetration beyond the original's, pair by pair
  (:func:`sim.replay.checks.self_penetration_excess`);
* ``limit_excess_deg``: mean over frames of the worst wrapped anatomical hinge angle beyond its
  ASF range, on the humanoid fitted to the points (:mod:`sim.physics.ik`), ``limit_excess_max_deg``;
  only hinges the points observe count (a forearm's twist, say, is invisible without the hand);
* ``residual_force_bw`` (mean) and ``residual_force_bw_p95``: the force no ground contact can
  supply / body weight; ``residual_torque_nm_kg``: mean |residual torque| / body mass, the torque
  the ground forces that supply the force leave (:func:`sim.physics.dynamics.residual_wrench`);
  ``joint_torque_rms_nm_kg``: RMS anatomical joint torque / body mass, with ``dynamics_n``
  frames and ``derivatives`` (where the velocities and accelerations came from); all over the
  frames whose derivatives are measured: ``dynamics_unmeasured_n`` frames of the original
  (and so of every reconstruction of it) are not, where its source window is shifted against
  the take's ends or a pose jump (:data:`MAX_DERIVATIVE_NOISE`), and
  ``residual_force_bw_unmeasured`` is what they would have added (mean over them, None if
  none); ``residual_force_bw_by_cause``: the residual force's mean over the measured frames
  split by why no ground force supplies it (:func:`residual_causes`);
* ``ik_error_mm``: mean RMS distance of the fitted humanoid's points to the motion's (large when
  a reconstruction stretches bones);
* ``ground_parts``: per body point other than the feet that rests on the floor (a hand, a knee),
  the share of frames it does (:func:`sim.physics.contacts.body_contacts`); ``unsupported_share``
  the frames with nothing on the floor, ``support_missing_share`` those of them needing more than
  :data:`SUPPORT_MISSING_BW` from outside, ``support_above_floor_share`` those with the lower
  foot standing still above the floor (``support_above_floor_mm``: how high, median),
  ``support_held_share`` the frames needing a sustained horizontal force no contact supplies
  (:func:`held_frames`; :func:`support_verdict` reads them for a trial);
* ``<key>_excess``: the figure minus the original's, for the dynamics, contact and limit figures;
* ``per_frame``: arrays for plots (see :meth:`PhysicsJob.analyse`).

Units: metres and seconds in; millimetres, body weights (BW) and N m/kg out, as each key says.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.physics.contact_metrics import contact_metrics, physdiff_metrics
from sim.physics.contacts import Contacts
from sim.physics.dynamics import Dynamics, summarise_dynamics
from sim.physics.feet import HOLD_GAP
from sim.physics.ground import Ground
from sim.physics.ik import Fit
from sim.physics.support import (
    PLANTED_SPEED,
    RESIDUAL_CAUSES,
    SUPPORT_MISSING_BW,
    held_frames,
    residual_causes,
)
from sim.replay.checks import FrameChecks, self_penetration_excess

#: Figures whose excess over the original is reported as ``<key>_excess``.
EXCESS_KEYS = (
    "penetration_mm", "float_mm", "skate_mm_s", "limit_excess_deg", "residual_force_bw",
    "residual_force_bw_p95", "residual_torque_nm_kg", "joint_torque_rms_nm_kg",
    "physdiff_penetrate_mm", "physdiff_float_mm", "physdiff_skate",
)  # fmt: skip


#: Heights above the floor: meaningless where the trial's floor does not fit
#: (:attr:`sim.physics.ground.Ground.fits`), so not scored there (eval and the report say so).
HEIGHT_KEYS = ("penetration_mm", "float_mm", "physdiff_penetrate_mm", "physdiff_float_mm")


@dataclass(frozen=True)
class MotionPhysics:
    """Everything computed for one motion (T frames, F feet)."""

    positions: np.ndarray  # (T, P, 3) [m]
    fit: Fit
    dynamics: Dynamics
    contacts: Contacts
    checks: FrameChecks
    limit: np.ndarray  # (T,) [deg]
    lowest: np.ndarray  # (T,) [m] lowest body surface point above the floor
    derivatives: str  # where qvel/qacc came from
    measured: np.ndarray  # (T,) bool: the frame's derivatives are measured (MAX_DERIVATIVE_NOISE)
    force_points: np.ndarray  # (T,) int: points where ground forces may act


def figures(
    mp: MotionPhysics,
    orig: MotionPhysics,
    ground: Ground,
    fps: float,
    anatomical: np.ndarray,
    mu: float,
) -> dict:
    """The figures of motion ``mp`` against the original ``orig`` (see the module docstring), with
    ``per_frame``, but without the ``<key>_excess`` figures (those need the original's own).

    Args:
        ground: the trial's floor; fps: frame rate [1/s]; anatomical: (nv hinges,) bool, the
            hinges whose torques count; mu: the ground's friction coefficient.
    """
    out = {"ground_z_m": ground.z, **ground.summary()}
    out.update(contact_metrics(orig.contacts.contact, mp.contacts))
    out.update(physdiff_metrics(mp.lowest, mp.contacts, fps))
    out.update(self_penetration_excess(mp.checks, orig.checks))
    measured = mp.measured
    frames = summarise_dynamics(mp.dynamics, anatomical, measured)
    out.update(frames.pop("summary"))
    causes = residual_causes(mp.dynamics.force, mp.force_points > 0, mu)
    rf, n = frames["residual_force_bw"], max(int(measured.sum()), 1)
    out["residual_force_bw_by_cause"] = {
        c: float(rf[measured & (causes == k)].sum() / n) for k, c in enumerate(RESIDUAL_CAUSES)
    }
    held = held_frames(mp.dynamics.residual_force, mp.dynamics.weight, fps, measured)
    out["derivatives"] = mp.derivatives
    out["limit_excess_deg"] = float(mp.limit.mean())
    out["limit_excess_max_deg"] = float(mp.limit.max(initial=0.0))
    out["limit_excess_n"] = int(len(mp.limit))
    out["ik_error_mm"] = 1e3 * float(mp.fit.error.mean())
    body = mp.contacts.body
    out["ground_parts"] = {} if body is None else body.shares()
    out.update(support_figures(mp.contacts, rf, measured, held))
    out["per_frame"] = per_frame(mp, frames, held)
    return out


def support_figures(
    c: Contacts, residual_force_bw: np.ndarray, measured: np.ndarray, held: np.ndarray
) -> dict:
    """``unsupported_share``, ``support_missing_share``, ``support_above_floor_share``,
    ``support_held_share`` and ``support_above_floor_mm`` of a motion (see the module docstring)
    from its contacts, its residual force per frame (T,) [BW], its measured frames (T,) bool and
    its held frames (T,) bool (:func:`sim.physics.support.held_frames`)."""
    n = max(int(measured.sum()), 1)
    unsupported = ~c.supported
    missing = unsupported & measured & (residual_force_bw > SUPPORT_MISSING_BW)
    low = np.argmin(c.foot_gap, axis=1)  # the lower foot, the one that could bear the body
    t = np.arange(len(low))
    gap_low, speed_low = c.foot_gap[t, low], c.foot_speed[t, low]
    above = missing & (gap_low > HOLD_GAP) & (speed_low < PLANTED_SPEED)
    height = gap_low[above]
    return {
        "unsupported_share": float(unsupported.mean()),
        "support_missing_share": float(missing.sum() / n),
        "support_above_floor_share": float(above.sum() / n),
        "support_held_share": float(held.sum() / n),
        "support_above_floor_mm": 1e3 * float(np.median(height)) if above.any() else None,
    }


def per_frame(mp: MotionPhysics, frames: dict, held: np.ndarray) -> dict:
    """The per-frame arrays of a motion's figures, for plots (see
    :meth:`sim.analysis.job.PhysicsJob.analyse`); ``frames``: the per-frame dynamics of
    :func:`sim.physics.dynamics.summarise_dynamics`."""
    body = mp.contacts.body
    return {
        "foot_names": list(mp.contacts.sides),
        "contact": mp.contacts.contact.astype(int),
        "foot_height_mm": 1e3 * mp.contacts.foot_gap,
        "foot_speed_mm_s": 1e3 * mp.contacts.foot_speed,
        **frames,
        "dynamics_measured": mp.measured.astype(int),
        "support_held": held.astype(int),
        "limit_excess_deg": mp.limit,
        "ik_error_mm": 1e3 * mp.fit.error,
        "lowest_mm": 1e3 * mp.lowest,
        "body_points": [] if body is None else list(body.names),
        "body_contact": np.zeros((len(mp.lowest), 0), int)
        if body is None
        else body.contact.astype(int),
        "qpos": mp.fit.qpos,  # (T, nq) the fitted configurations (forward simulation's input)
    }
