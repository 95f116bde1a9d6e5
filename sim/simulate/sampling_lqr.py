"""The LQR as the sampler's base policy: one full-state gain per sampler window, shared by all of
that window's rollouts and by the replay.

The sampler (``sim.simulate.gainchoice.choice_search``) tries constant offsets on the servo
targets for a window of ticks; between its windows nothing but the balance feedback
(``sim.simulate.balance``) reacts to the state. Here, before a window's rollouts (in the main
thread), the body is linearised once (``sim.simulate.lqr.online_gain``: ``mjd_transitionFD``
chained over a tick, Riccati steps of that frozen system from the value matrix the last window
left, ``LQRWeights.sweeps`` of them) at the cheapest kept state of the window's start; in every
tick of that window's rollouts, lookahead included, and of the replay the target is

    reference target + sampled offset - scale K (x - x_ref(t))

(``dx`` by ``sim.simulate.lqr.state_error``, then the balance feedback, the sum clipped to the
control range as the tracker's ``set_controls`` clips it). ``K`` is kept as torque per unit
state error (the linearised model's ``kp`` times its target gain), so a rollout on other gains
(``gainchoice``) gets the same torque (over its own ``kp``). The replay
(``controller.track(..., feedback=...)``) applies the same gains, window by window, to the same
states: the committed trajectory is the rolled-out one bit for bit, and ``data.ctrl`` (what the
episode stores) is the target that acted. Cost: one linearisation per window (about 9 ms: some
0.1 CPU s per simulated s at 12-tick windows).
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d

from sim.simulate.lqr import LQRWeights, control_weights, online_gain, state_error
from sim.simulate.model import CONTROL_HZ
from sim.simulate.wholebody_reference import SMOOTH_S

#: [rad per unit state error] a target gain beyond this is a linearisation that blew up (the
#: LQR tracker's gains on the walks: up to about 10)
MAX_GAIN = 1e3


class WindowLQR:
    """One LQR gain per sampler window (module docstring). ``scale``: the share of the gain
    applied; ``weights``: the LQR's costs (``sweeps`` None: one Riccati step per tick of the
    window, the tracker's horizon growth)."""

    def __init__(self, scale: float, weights: LQRWeights | None = None):
        self.scale = float(scale)
        self.weights = weights
        self.gains: dict[int, np.ndarray] = {}  # window index -> (nu, 2nv) [N m per unit dx]
        self._P = None
        self._ref = None

    def start(self, ref_qpos: np.ndarray, ref_qvel: np.ndarray, window: int) -> None:
        """Bind the reference (T, nq) and its velocities (T, nv; smoothed here as the LQR
        tracker's, ``wholebody_reference.SMOOTH_S``) and the window length [ticks]; forget
        the gains."""
        if len(ref_qvel) > 1:
            ref_qvel = gaussian_filter1d(ref_qvel, SMOOTH_S * CONTROL_HZ, axis=0, mode="nearest")
        self._ref, self.window = (ref_qpos, ref_qvel), int(window)
        self.gains, self._P = {}, None
        if self.weights is None:
            self.weights = dataclasses.replace(LQRWeights(), sweeps=self.window)

    def set_window(self, k0: int, model, data, state: np.ndarray, spec, ctrl) -> np.ndarray:
        """The gain of the window starting at tick ``k0`` (a multiple of the window), linearised
        at the full ``state`` (``spec``) with the operating control ``ctrl`` (nu,) [rad] (the
        reference's target, clipped to the range) on ``model`` (the gains that state was reached
        with); ``data`` is overwritten. Gains not finite or beyond :data:`MAX_GAIN` (a
        linearisation that blew up: measured at the sampler's first state, whose unsmoothed
        reference velocity makes a perturbed step explode): zero, the sampler alone, and the
        value matrix starts again. Returns the (nu, 2nv) torque gain, stored for the rollouts
        and the replay."""
        mujoco.mj_setState(model, data, state, spec)
        lo, hi = model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1]
        data.ctrl[:] = np.clip(ctrl, lo, hi)
        mujoco.mj_forward(model, data)
        R = control_weights(model, self.weights)
        with np.errstate(over="ignore", invalid="ignore"):
            K, P = online_gain(model, data, R, self._P, self.weights)
        kp = model.actuator_gainprm[:, 0]
        gain = self.scale * kp[:, None] * K
        if not (np.isfinite(P).all() and np.abs(K).max() <= MAX_GAIN):
            gain, P = np.zeros_like(gain), None
        self.gains[k0 // self.window], self._P = gain, P
        return gain

    def feedback(self, model, data, k: int, k0: int | None = None) -> np.ndarray:
        """(nu,) the target offset [rad] on ``model`` at tick ``k`` of the window that starts at
        ``k0`` (None: the one holding ``k``; a rollout's lookahead keeps its own window's):
        ``-K dx / kp``, ``dx`` the state's deviation from the reference at ``k``."""
        K = self.gains[(k if k0 is None else k0) // self.window]
        ref_q, ref_v = self._ref
        dx = state_error(model, data.qpos, data.qvel, ref_q[k], ref_v[k], np.empty(K.shape[1]))
        return -(K @ dx) / model.actuator_gainprm[:, 0]
