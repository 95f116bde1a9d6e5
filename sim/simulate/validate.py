"""Validation by forward simulation: could a body with human strength perform this motion?

A motion given as configurations (``qpos`` fitted to its points, e.g. by ``sim.physics``'s IK)
is tracked in ``mj_step`` by the torque-limited controller of ``sim.simulate.controller`` with no
root assistance at all (``assist_limit = 0``): only the joints (within their human limits) and
the floor move the body. The figures say how far the simulated body strays from the motion it
tracks and from the original motion, whether and when it falls, and the torque it used.

A reconstruction and its original are tracked on the same floor: both are shifted vertically
by the original's floor track (``sim.simulate.reference.floor_track``), so a reconstruction's
own height errors stay in it.
"""

from __future__ import annotations

import mujoco
import numpy as np

from sim.simulate.controller import track
from sim.simulate.model import CONTROL_HZ, total_mass
from sim.simulate.reference import FLOOR_LIFT, flat_soles, floor_track, time_warp
from sim.simulate.sampling import sample_track

#: figures of :func:`simulate_figures`, in table order
SIMULATE_KEYS = (
    "sim_error_mm", "sim_error_original_mm", "sim_fell", "sim_fall_s", "sim_torque_rms_nm_kg",
    "sim_torque_saturated",
)  # fmt: skip


class ForwardValidation:
    """One subject's simulated body and the points the errors are measured on.

    Args:
        model: ``sim.simulate.model.sim_model`` of the subject's skeleton.
        names: (P,) point names (``"root"`` and bone names with sites ``<name>_end``).
        samples: 0: the plain tracker (``track``); N > 0: the sampling tracker
            (``sim.simulate.sampling.sample_track``, N rollouts per 0.1 s window, each judged
            0.4 s on, seed 0), which
            corrects the joints' targets so the body keeps its balance where it can.
    """

    def __init__(self, model, names, samples: int = 0):
        self.model = model
        self.names = tuple(names)
        self.samples = int(samples)
        self.data = mujoco.MjData(model)
        self._sites = [-1 if n == "root" else model.site(f"{n}_end").id for n in self.names]
        self._root = model.body("root").id

    def __reduce__(self):  # to another process: rebuilt there with fresh MuJoCo data
        return (ForwardValidation, (self.model, self.names, self.samples))

    def points(self, qpos: np.ndarray) -> np.ndarray:
        """(T, P, 3) the model's points [m] at each ``qpos`` (T, nq)."""
        out = np.empty((len(qpos), len(self.names), 3))
        for t, q in enumerate(qpos):
            self.data.qpos[:] = q
            mujoco.mj_kinematics(self.model, self.data)
            for k, s in enumerate(self._sites):
                out[t, k] = self.data.xpos[self._root] if s < 0 else self.data.site_xpos[s]
        return out

    def reference(self, qpos: np.ndarray, fps: float, floor: np.ndarray | None = None):
        """``qpos`` (T, nq) at ``fps`` resampled at the control rate and shifted vertically by
        ``floor`` ((T', ,) the original's floor track, from :meth:`floor_of`; default its own),
        its soles near the floor laid flat where the model has soles
        (``sim.simulate.reference.flat_soles``)."""
        ref = time_warp(self.model, qpos, fps, 1.0, CONTROL_HZ)
        floor = self.floor_of(ref) if floor is None else floor
        ref[:, 2] -= floor - FLOOR_LIFT
        return flat_soles(self.model, ref)

    def floor_of(self, ref120: np.ndarray) -> np.ndarray:
        """(T',) floor height [m] under a control-rate ``qpos`` stream."""
        return floor_track(self.model, ref120, CONTROL_HZ)

    def run(self, qpos: np.ndarray, fps: float, original_qpos: np.ndarray | None = None) -> dict:
        """Track ``qpos`` (T, nq, at ``fps``) without assistance; the figures of
        :data:`SIMULATE_KEYS` (JSON-ready):

        * ``sim_error_mm``: mean distance [mm] of the simulated points to the tracked motion's;
        * ``sim_error_original_mm``: the same against ``original_qpos`` (the motion itself when
          None);
        * ``sim_fell`` (0/1) and ``sim_fall_s``: the time of the fall [s] (None: no fall), a fall
          as ``sim.simulate.falls`` defines it (a part other than the feet on the floor where
          the reference has none, or the head below half the reference's);
        * ``sim_torque_rms_nm_kg``: RMS joint torque [N m / kg] applied;
        * ``sim_torque_saturated``: share of (frame, joint) samples at their torque limit.
        """
        original_qpos = qpos if original_qpos is None else original_qpos
        orig = time_warp(self.model, original_qpos, fps, 1.0, CONTROL_HZ)
        floor = self.floor_of(orig)
        ref = self.reference(qpos, fps, floor)
        orig[:, 2] -= floor - FLOOR_LIFT
        orig = flat_soles(self.model, orig)  # the same feet as the tracked reference's
        every = int(round(CONTROL_HZ / fps))
        if self.samples:
            r = sample_track(self.model, ref, samples=self.samples, record_every=every)
        else:
            r = track(self.model, ref, assist_limit=0.0, record_every=every)
        sim = self.points(r.qpos)
        n = len(sim)
        target = self.points(ref[::every][:n])
        original = self.points(orig[::every][:n])
        lim = self.model.actuator_forcerange[:, 1]
        tau = r.joint_torque
        return {
            "sim_error_mm": 1e3 * float(np.linalg.norm(sim - target, axis=-1).mean()),
            "sim_error_original_mm": 1e3 * float(np.linalg.norm(sim - original, axis=-1).mean()),
            "sim_fell": int(r.fell),
            "sim_fall_s": None if r.fall_frame < 0 else r.fall_frame / fps,
            "sim_torque_rms_nm_kg": float(np.sqrt(np.mean(tau**2)) / total_mass(self.model)),
            "sim_torque_saturated": float(np.mean(np.abs(tau) >= lim * (1 - 1e-6))),
        }
