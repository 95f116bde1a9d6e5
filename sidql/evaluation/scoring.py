"""The scores of one clip rebuilt from a method's keyframes, and the physics figures of a row.

A clip is rebuilt with the reconstruction its method declares
(:mod:`sidql.keyframes.reconstructions`: spherical cubic Hermite for every method except
``pitch``, which declares Li et al.'s slerp) and scored (:func:`score`) by

* ``q``: the paper's eq. 18 [rad] on the reconstruction's angles (22 bones);
* ``q_hermite``: eq. 18 of the same keyframes under the Hermite reconstruction (equal to ``q``
  for methods that declare Hermite: it separates the choice of keyframes from the way they are interpolated);
* ``geodesic_deg``: mean angle between true and rebuilt bone directions [deg];
* ``mpjpe_mm``: mean joint position error over the 23 points [mm];
* ``velocity_error_mm_s``: mean joint velocity error over the 23 points [mm/s];
* ``li_error_mm``: Li et al. 2015's error as we read it (:func:`sidql.keyframes.pitch.pitch_error`) [mm];
* ``decision_ms`` (measured by :func:`sidql.evaluation.evaluate.evaluate`): wall time of the
  method's choice, chart included [ms].

Everything but the physics (:class:`sidql.evaluation.trial_physics.TrialPhysics`) is pure numpy.
The noise floor's rows (:data:`NOISE_FLOOR`): per figure, how far the original re-captured with
marker noise departs from the original (:func:`noise_figures`).
"""

from __future__ import annotations

import numpy as np

from sidql.evaluation.cases import Case
from sidql.evaluation.significance import CLOSENESS
from sidql.keyframes import methods, reconstructions
from sidql.keyframes.metrics import (
    geodesic_deg,
    mpjpe_mm,
    q_error,
    q_from_angles,
    velocity_error_mm_s,
)
from sidql.keyframes.pitch import pitch_error
from sim.analysis.figures import HEIGHT_KEYS


def score(
    case: Case,
    keyframes: np.ndarray,
    method: str,
    physics=None,
    simulate=None,
    original_qpos=None,
    reconstruction: str | None = None,
) -> dict:
    """Every error measure of one clip rebuilt from ``keyframes`` with the reconstruction
    ``method`` declares (:func:`sidql.keyframes.methods.reconstruction_of`; see the module
    docstring).

    ``physics``: the trial's :class:`sidql.evaluation.trial_physics.TrialPhysics` adds the :mod:`sim.physics` figures of the
    reconstruction (its curve's own velocities and accelerations, the original's contacts
    labelled over the whole trial); ``simulate`` (a
    :class:`sim.simulate.validate.ForwardValidation`, with ``physics``) adds its forward
    simulation's figures (the IK fit tracked without assistance; ``original_qpos``: the
    original's fit, computed here when None). ``reconstruction``: rebuild with this registered
    reconstruction instead of the method's own (its name and ``side_bytes`` join the row)."""
    s = case.series
    name = reconstruction or methods.reconstruction_of(method)
    rec = reconstructions.rebuild(name, case.clip, keyframes, s)
    phys = {}
    if physics:
        analysis = physics.analyse(case.clip, rec)
        phys = physics_figures(analysis, physics.analyse(case.clip))
        if simulate is not None:
            if original_qpos is None:
                original_qpos = physics.analyse(case.clip)["per_frame"]["qpos"]
            phys.update(simulate.run(analysis["per_frame"]["qpos"], case.clip.fps, original_qpos))
    return {
        **phys,
        "reconstruction": name,
        "side_bytes": rec.side_bytes,
        "q": q_from_angles(s, rec.theta, rec.phi),
        "q_hermite": q_error(s, keyframes, "hermite"),
        "geodesic_deg": geodesic_deg(case.pos, rec.positions, rec.parents),
        "mpjpe_mm": mpjpe_mm(case.pos, rec.positions),
        "velocity_error_mm_s": velocity_error_mm_s(case.vel, rec.velocities),
        "li_error_mm": 1000.0 * pitch_error(case.pos, rec.positions),
    }


#: The :mod:`sim.physics` figures ``evaluate(..., physics=True)`` adds to rows (means over clips).
PHYSICS_KEYS = (
    "penetration_mm", "float_mm", "skate_mm_s", "contact_precision", "contact_recall",
    "physdiff_penetrate_mm", "physdiff_float_mm", "physdiff_skate",
    "self_pen_excess_mm", "lost_contacts", "limit_excess_deg", "residual_force_bw",
    "residual_force_bw_p95", "residual_torque_nm_kg", "joint_torque_rms_nm_kg",
    "joint_torque_rms_nm_kg_distance",
    "residual_force_bw_excess", "residual_torque_nm_kg_excess", "joint_torque_rms_nm_kg_excess",
    "ik_error_mm",
)  # fmt: skip

#: Heights above the floor: not scored (None) in a trial whose floor does not fit.
FLOOR_KEYS = HEIGHT_KEYS


def physics_figures(analysis: dict, original: dict | None = None) -> dict:
    """The per-clip numbers of a :mod:`sim.physics` analysis (no per-frame arrays; NaN, a mean
    over no samples, becomes None so that the JSON is standard). With the ``original``'s
    analysis, figures of :data:`sidql.evaluation.significance.CLOSENESS` also get
    ``<key>_distance``, |value - original's|. Where the floor does not fit, the heights above it
    (:data:`FLOOR_KEYS`) are None."""
    out = {k: _none_if_nan(v) for k, v in analysis.items() if k != "per_frame"}
    base = analysis if original is None else original
    for k in CLOSENESS:
        if out.get(k) is not None and base.get(k) is not None:
            out[f"{k}_distance"] = abs(float(out[k]) - float(base[k]))
    if not analysis.get("floor_fits", True):
        for k in FLOOR_KEYS:
            out[k] = None
    return out


def _none_if_nan(v):
    return None if isinstance(v, float) and np.isnan(v) else v


#: The method name of the noise-floor rows: the original re-captured with marker noise.
NOISE_FLOOR = "noise floor"


def noise_figures(noisy: dict, original: dict) -> dict:
    """A noise-floor row: per figure, how far the original re-captured with marker noise
    (:meth:`sim.analysis.job.PhysicsJob.noise_floor`) departs from the original,
    ``|noisy - original|`` (None where either lacks it)."""
    out = {}
    for k, v in noisy.items():
        o = original.get(k)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        out[k] = None if v is None or o is None else abs(float(v) - float(o))
    return out
