"""Audit of a synthetic clip by the physics room: is its residual force the recorded help?

A simulated clip's external forces are the floor's contact forces, the controller's root
assistance (recorded every frame, :func:`sim.simulate.controller.track`) and the pushes (recorded
with the generation parameters). :class:`sim.analysis.job.PhysicsJob` sees only the clip's
points: it fits the humanoid to them, differentiates, and explains the required external force by
ground forces at the foot points it labels in contact; what is left is the residual. So, per
frame, the residual must stay near zero where no help was recorded, and cannot exceed the
recorded help by more than the analysis' own error where some was; where nothing on the ground
can supply the help (feet in the air), the residual recovers it.

Two differences are expected and are not violations: assistance the feet could have given (the
vertical part of the help while a foot is in contact, inside the friction cone) is explained by
the ground and leaves no residual; and a body lying on the floor is held by contacts the physics
room does not model (hips, hands, knees: only foot points bear force there), so those frames
(any non-foot point below :data:`LYING_HEIGHT`) are counted apart.
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.signal import savgol_filter

from sim.analysis.job import PhysicsJob
from sim.model.humanoid import build_mjcf, canonical_skeleton
from sim.model.kinematics import FOOT_POINTS
from sim.model.mass import DEFAULT_BODY_MASS_KG
from sim.physics.ground import Ground, estimate_ground
from sim.simulate.model import G, scaled_skeleton

QUIET_BW = 0.02  # [body weight] recorded help below this: a frame "without assistance"
LYING_HEIGHT = 0.15  # [m] a non-foot point lower than this: the body lies on the floor


def clip_model(generation: dict):
    """The kinematic humanoid a synthetic clip was simulated on (its body scale and mass)."""
    scale = float(generation.get("scale", 1.0))
    skeleton = scaled_skeleton(canonical_skeleton(), scale)
    xml = build_mjcf(skeleton, body_mass_kg=DEFAULT_BODY_MASS_KG * scale**3)
    return mujoco.MjModel.from_xml_string(xml)


def floor_ground(clip) -> Ground:
    """The clip's ground (:func:`sim.physics.ground.estimate_ground`: its feet's stance offsets
    and fit) with its plane at the simulator's floor z = 0, where the ground forces act."""
    return estimate_ground(clip.positions, clip.names, clip.fps).moved(0.0)


def acceleration_kernel(window: int, polyorder: int = 3) -> np.ndarray:
    """(2 window - 1,) the kernel through which a Savitzky-Golay second derivative of positions
    sees the true accelerations: ``savgol(p)'' [t] = sum_m K[m] a[t + m]`` (sums to 1). Smoothing
    a recorded force by it gives the force the physics room's accelerations can show."""
    n = 4 * window + 1
    a = np.zeros(n)
    a[n // 2] = 1.0
    v = np.cumsum(a)
    p = np.concatenate([[0.0], np.cumsum(v)[:-1]])  # central second difference of p = a
    out = savgol_filter(p, window, polyorder, deriv=2, mode="interp")
    return out[n // 2 - window + 1 : n // 2 + window][::-1].copy()


def recorded_help(record: dict, n_frames: int, fps: float, weight: float) -> np.ndarray:
    """(T,) recorded external help per frame [body weight]: root assistance plus active pushes
    (push force magnitude over the frame's time), before any filtering."""
    help_ = np.asarray(record["assistance"], dtype=np.float64)[:n_frames].copy()
    t = np.arange(n_frames) / fps
    for p in record["generation"].get("pushes", []):
        on = (t >= p["start"]) & (t < p["start"] + p["duration"])
        help_[on] += np.linalg.norm(p["force"]) / weight
    return help_


def assistance_audit(clip, record: dict, *, ground: Ground | None = None, window: int = 9) -> dict:
    """Residual force found by the physics room against the recorded help, per frame.

    Args:
        clip: a synthetic clip (:class:`sim.motion.clip.Clip` from ``sidql synth``).
        record: its ``index.json`` entry (``generation``, per-frame ``assistance``).
        ground: default :func:`floor_ground` of the clip.
        window: the physics room's Savitzky-Golay window [frames]; the recorded help is smoothed
            by the kernel through which that filter's accelerations see the true ones
            (:func:`acceleration_kernel`), so both figures have the same bandwidth.
    Returns:
        ``residual`` (T,) and ``help`` (T,) [body weight] (help smoothed), ``lying`` (T,) bool,
        ``quiet`` (T,) bool (smoothed help < :data:`QUIET_BW`, upright), and the summary over the
        frames at least half a filter window from the clip's ends (where the filter fits its
        ends and the contact labels start) and upright unless said otherwise:
        ``corr`` (Pearson; nan if either is constant),
        ``residual_quiet_bw`` (mean residual in quiet frames, nan if none; ``quiet_n`` frames),
        ``residual_assisted_bw`` / ``help_assisted_bw`` (means over frames with help,
        ``assisted_n``), ``excess_bw_p95`` (95th percentile of residual - help: residual the
        help does not account for), ``residual_lying_bw`` (frames lying, ``lying_n``).
    """
    model = clip_model(record["generation"])
    job = PhysicsJob(model, clip.names, clip.parents, clip.fps, window=window)
    out = job.analyse(clip, None, ground or floor_ground(clip))
    res = np.asarray(out["per_frame"]["residual_force_bw"])
    weight = float(model.body_subtreemass[0]) * G
    raw = recorded_help(record, clip.n_frames, clip.fps, weight)
    w = min(window, len(raw) if len(raw) % 2 else len(raw) - 1)
    if w >= 3:
        k = acceleration_kernel(w, min(3, w - 1))
        help_ = np.convolve(np.pad(raw, len(k) // 2, mode="edge"), k[::-1], mode="valid")
    else:
        help_ = raw
    body = [k for k, n in enumerate(clip.names) if n not in FOOT_POINTS]
    lying = np.asarray(clip.positions)[:, body, 2].min(axis=1) < LYING_HEIGHT
    interior = np.zeros(len(res), dtype=bool)
    interior[w // 2 : len(res) - w // 2] = True  # the filter's end fits and contact hysteresis
    up = ~lying & interior
    quiet = up & (help_ < QUIET_BW)
    assisted = up & ~quiet

    def mean(x, m):
        return float(x[m].mean()) if m.any() else float("nan")

    ok = up.sum() > 2 and np.ptp(res[up]) > 0 and np.ptp(help_[up]) > 0
    return {
        "residual": res,
        "help": help_,
        "lying": lying,
        "quiet": quiet,
        "corr": float(np.corrcoef(res[up], help_[up])[0, 1]) if ok else float("nan"),
        "residual_quiet_bw": mean(res, quiet),
        "quiet_n": int(quiet.sum()),
        "residual_assisted_bw": mean(res, assisted),
        "help_assisted_bw": mean(help_, assisted),
        "assisted_n": int(assisted.sum()),
        "excess_bw_p95": float(np.percentile(res[up] - help_[up], 95)) if up.any() else 0.0,
        "residual_lying_bw": mean(res, lying & interior),
        "lying_n": int((lying & interior).sum()),
    }
