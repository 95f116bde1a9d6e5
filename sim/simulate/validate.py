"""Validation by forward simulation: could a body with human strength perform this motion?

A motion given as configurations (``qpos`` fitted to its points, e.g. by ``sim.physics``'s IK)
is tracked in ``mj_step`` by a torque-limited controller (by default the sampler of
``sim.simulate.sampling``, :data:`DEFAULT_CONTROLLER`, choosing its feedback gains per window:
:data:`DEFAULT_GAIN_CHOICE`) with no root assistance at all (``assist_limit = 0``): only the joints (within their human limits) and
the floor move the body. The figures say how far the simulated body strays from the motion it
tracks and from the original motion, whether and when it falls, and the torque it used.

A reconstruction and its original are tracked on the same floor: both are shifted vertically
by the original's floor track (``sim.simulate.reference.floor_track``), so a reconstruction's
own height errors stay in it.

Controllers (``ForwardValidation(controller=...)``): ``"plain"`` (``track``), ``"sampling"``
(``sim.simulate.sampling``), ``"lqr"`` (``sim.simulate.lqr``, either body, the
contact-consistent reference by default) and ``"wholebody"`` (``sim.simulate.wholebody``'s
inverse-dynamics QP; it needs the torque-actuated body, ``sim_model(..., actuators="motor")``, and tracks a
contact-consistent reference: no floor lift, stance soles laid on the floor). The plain
tracker tracks a reference lifted by ``FLOOR_LIFT`` unless asked for the contact-consistent
one (``ForwardValidation(contact_reference=True)``); the sampler tracks the contact-consistent
one unless asked for the lifted one (:data:`DEFAULT_CONTACT_REFERENCE`).
"""

from __future__ import annotations

import mujoco
import numpy as np

from sim.errors import UsageError
from sim.simulate.balance import Balance
from sim.simulate.controller import track
from sim.simulate.footholding import CONTACT_HEIGHT, sole_ids
from sim.simulate.footlock import foot_locked
from sim.simulate.gainchoice import GainChoice, choice_track, common_body
from sim.simulate.handholds import find_handholds
from sim.simulate.lqr import track_lqr
from sim.simulate.model import CONTROL_HZ, Gains, sim_spec, total_mass
from sim.simulate.reference import (
    FLOOR_LIFT,
    contact_consistent,
    contact_shift,
    flat_soles,
    floor_track,
    time_warp,
)
from sim.simulate.sampling import sample_track
from sim.simulate.terrain import find_terrain, scene_model, surface_height, terrain_geoms
from sim.simulate.wholebody import track_wholebody
from sim.simulate.wholebody_reference import sole_corners

#: figures of :meth:`ForwardValidation.run`, in table order
SIMULATE_KEYS = (
    "sim_error_mm", "sim_error_local_mm", "sim_error_original_mm", "sim_fell", "sim_fall_s",
    "sim_torque_rms_nm_kg", "sim_torque_saturated",
)  # fmt: skip
#: further figures of :meth:`ForwardValidation.run` (not in the evaluation's tables)
SIMULATE_EXTRA_KEYS = ("sim_skate_mm_s", "sim_skate_ref_mm_s", "sim_steps")
CONTROLLERS = ("plain", "sampling", "wholebody")
#: what ``ForwardValidation`` runs besides: the time-varying LQR (``sim.simulate.lqr``), an
#: option measured against the others (``benchmarks/bench_simulate.py --controllers lqr``), not
#: offered by the commands (``synth`` and ``eval`` keep :data:`CONTROLLERS`)
OPTIONAL_CONTROLLERS = ("lqr",)
#: the controllers that compute torques themselves (the body's torque actuators,
#: ``sim_model(actuators="motor")``); ``"lqr"`` runs on either body
TORQUE_CONTROLLERS = ("wholebody",)
#: the controller of ``eval --physics --simulate`` and ``report --simulate`` without
#: ``--samples``: the sampler with falls in its cost and the balance feedback with the drift
#: lead (:data:`DEFAULT_BALANCE`) at :data:`DEFAULT_SAMPLES`, because within the budget of 5 CPU
#: s per simulated second it beats the other controllers on falls and error
#: (``docs/synthetic.md``, ``docs/results/simulate_default.md`` and ``simulate_controllers.md``,
#: 22 clips: 0.27 falls, 105 mm root-relative, 272 mm global error; without the drift lead 0.27,
#: 113, 322 mm at 4.85-4.98 CPU s per simulated s, with it 0.99x that in one run; the sampler
#: without the feedback at 32 samples: 0.32, 138, 466 mm; the plain tracker 0.95, 316, 694 mm;
#: the whole-body QP 0.91, 362, 665 mm; foot holding or elite reuse added: not kept)
DEFAULT_CONTROLLER = "sampling"
#: the sampler's balance feedback here unless ``search`` names one: ``sampling.BALANCE`` with
#: the drift lead (``sim.simulate.drift``): the root velocity target leads by 2/s times the root's
#: horizontal position error beyond 0.1 m (clipped at 0.4 m). On the 22 clips, in one run with
#: the feedback without it: the same 6 falls, 105 against 113 mm root-relative, 272 against 322
#: mm global error, 0.99x the CPU (docs/results/simulate_default.md); per clip within the
#: sampler's chaos (lower global error in 7 of the 16 clips both keep up, higher in 5).
#: ``synth`` keeps ``sampling.BALANCE`` (20 clips: 10 up with the lead, 11 without; synthetic.md)
DEFAULT_BALANCE = Balance(k_drift=2.0, drift_max=0.4, drift_dead=0.1)
#: the sampler's rollouts per window where it is chosen without a count: 40 (all 107 clips of
#: ``../shared``, one run against 28 with the same rows: falls 0.19 against 0.21, medians 82 /
#: 217 mm root-relative / global against 88 / 245, 4.43 against 3.30 CPU s per simulated s on
#: 2 workers; docs/results/simulate_samples.md)
DEFAULT_SAMPLES = 40
#: the position actuators' feedback gains of the body ``eval --simulate`` and ``report
#: --simulate`` track with (:func:`validation_model`): bandwidth and stiffness cap are the
#: controller's (``Gains.min_deflection``); the torque limits stay the human ones whatever these
DEFAULT_GAINS = Gains()
#: the second gain set the sampler chooses from per window (:data:`DEFAULT_GAIN_CHOICE`): the
#: stiff controller, stiffness cap 0.1 rad at 12 Hz, on the same body and torque limits
STIFF_GAINS = Gains(min_deflection=0.1, omega=2 * np.pi * 12.0)
#: the sampler's candidates spread per window over :data:`DEFAULT_GAINS` and
#: :data:`STIFF_GAINS` (``sim.simulate.gainchoice``): half on each, the cost (falls included)
#: choosing. On all 107 clips in one run (docs/results/simulate_stiffness.md, ``mix0.5``) against
#: the default gains alone (``default28``, eval's default before): falls 0.23 against 0.24
#: (paired -0.01 [-0.07, +0.05]), median root-relative error 89 against 110 mm (-17 [-25, -8]),
#: global 245 against 267 mm (-15 [-39, +9]), skating 350 against 445 mm/s, 1.02x the CPU; the
#: stiff gains alone (``ccstiff0.1w12``) 0.28 falls, 79 mm, 238 mm. None: the default gains only
DEFAULT_GAIN_CHOICE = GainChoice(share=0.5)
#: [rad] the sampler's ``noise_deflection`` here unless ``search`` names one (0: its noise a
#: share of peak torque over the body's stiffness; a stiffer body's ``min_deflection`` before
#: it: the noise keeps the angles it had on that body)
DEFAULT_NOISE_DEFLECTION = 0.0
#: the body is stepped lean (``sim_model(lean=True)``: MuJoCo skips the stages this body has
#: nothing for; the same motion bit for bit, 0.85-0.94x the CPU per simulated second:
#: docs/results/simulate_step.md)
DEFAULT_LEAN = True
#: the sampler tracks the contact-consistent reference (no floor lift, its stance soles on the
#: floor) unless told otherwise. On 86 of the 107 clips in one run (docs/results/
#: simulate_screen.md) against the lifted one: 0.22 falls against 0.23 (6 clips kept up, 5
#: lost), median root-relative error 109 against 113 mm, global 266 against 286 mm, 1.01x the
#: CPU; every paired interval includes 0 (the sampler's chaos), the skating on the clips both
#: keep up lower (median change -29 mm/s)
DEFAULT_CONTACT_REFERENCE = True
#: the contact-consistent reference may take a flight that floats instead of falling for stance
#: (``sim.simulate.reference.contact_shift(floating=True)``: its lowest sole on the floor, as
#: the scene has no other support). Off: on 22 and 21 clips it took falls -0.05 [-0.14, 0.00]
#: each and errors a little lower, but on all 107 clips one fall in 107 (0.234 -> 0.224),
#: medians -4 / -7 mm, skating higher, and eval's decision lost pitch on every figure (falls
#: +0.08 [+0.00, +0.17]; docs/synthetic.md)
DEFAULT_FLOATING = False
#: the tracked reference's stance soles held still, flat on the floor, by the legs' angles
#: (``ForwardValidation(foot_lock=True)``, ``sim.simulate.footlock``): off (docs/synthetic.md)
DEFAULT_FOOT_LOCK = False
#: eval's and report's bodies (:func:`forward_validation`) track each clip in the scene inferred
#: from its original motion (``ForwardValidation(terrain=True)``, ``sim.simulate.terrain``:
#: boxes under feet that stand on steps). On all 107 clips (docs/results/simulate_terrain.md)
#: it found steps in 11 (01_02, 03_01, 03_02) and left the other 96 rows the same bit for bit;
#: falls 0.16 against 0.19 (3 kept up, none lost), root-relative error -5 [-10, -2] mm, global
#: -14 [-35, +4] mm, 1.01x the CPU (the boxes then weighed 20-70 kg in ``total_mass``; massless,
#: 18 falls against 17: docs/synthetic.md). A ``ForwardValidation`` built directly has it only
#: on request (it needs the bodies' specs)
DEFAULT_TERRAIN = True
#: [m] a sole whose lowest corner is this high or lower is in contact (skating's estimator; the
#: sampler's foot holding uses the same height)
SKATE_CONTACT = CONTACT_HEIGHT


def chosen_controller(
    samples: int = 0, controller: str | None = None, default_samples: int = DEFAULT_SAMPLES
) -> tuple[str, int]:
    """The controller and sample count a forward validation runs with: ``samples`` > 0 the
    sampler with that count, else ``controller`` (default :data:`DEFAULT_CONTROLLER`; the
    sampler at ``default_samples``, eval's :data:`DEFAULT_SAMPLES`); the count is 0 for the
    other controllers."""
    controller = controller or ("sampling" if samples else DEFAULT_CONTROLLER)
    return controller, int(samples or default_samples) if controller == "sampling" else 0


class ForwardValidation:
    """One subject's simulated body and the points the errors are measured on.

    Args:
        model: ``sim.simulate.model.sim_model`` of the subject's skeleton.
        names: (P,) point names (``"root"`` and bone names with sites ``<name>_end``).
        samples: N > 0: the sampling tracker (``sim.simulate.sampling.sample_track``, N
            rollouts per 0.1 s window, each judged 0.3 s on, seed 0), which corrects the
            joints' targets so the body keeps its balance where it can; 0: ``controller``'s
            default count (:data:`DEFAULT_SAMPLES`) where it is the sampler.
        controller: ``"plain"``, ``"sampling"`` or ``"wholebody"``; None: the sampler if
            ``samples`` is given, else :data:`DEFAULT_CONTROLLER`.
        search: further keywords of the sampler's search (``sim.simulate.sampling.
            search_offsets``: ``lookahead``, ``weights``, ...; with ``alternates``, models of
            ``model``'s body with other gains, ``sim.simulate.gainchoice.choice_search``'s,
            its gains chosen per window); None: its defaults, but for
            ``balance`` and ``noise_deflection``: :data:`DEFAULT_BALANCE` and
            :data:`DEFAULT_NOISE_DEFLECTION` unless ``search`` names them.
            The whole-body QP and the LQR take theirs (``track_wholebody``'s ``gains``,
            ``track_lqr``'s keywords).
        threads: the sampler's rollouts run on this many threads (the same result for any).
        contact_reference: the plain tracker and the sampler track the contact-consistent
            reference (no floor lift, stance soles on z = 0, as the whole-body QP always does)
            instead of the lifted one; None: the sampler :data:`DEFAULT_CONTACT_REFERENCE`,
            the plain tracker the lifted one. The figures are measured as with the lifted one
            either way (:meth:`run`).
        foot_lock: the contact-consistent reference tracked has its stance soles held still,
            flat on the floor, by the legs' angles (``sim.simulate.footlock.foot_locked``);
            off by default (:data:`DEFAULT_FOOT_LOCK`); it needs the contact-consistent
            reference. The figures are measured as without it.
        terrain: each clip is tracked in the scene inferred from its original motion
            (``sim.simulate.terrain.find_terrain``: boxes under the feet that stand on steps,
            the ground tracked from the ground-level stances only); where none is found the
            clip runs exactly as without it. Needs ``specs``; off unless asked here,
            :func:`forward_validation` asks by default (:data:`DEFAULT_TERRAIN`).
        specs: the ``MjSpec`` (or its XML) of ``model`` and of each of ``search``'s
            ``alternates``, in that order: a clip with terrain compiles copies with its boxes
            (the models here are not changed).
        hand_supports: with ``terrain``, holds under the hands too (``sim.simulate.handholds``).
    """

    def __init__(
        self,
        model,
        names,
        samples: int = 0,
        controller: str | None = None,
        search: dict | None = None,
        threads: int = 1,
        contact_reference: bool | None = None,
        foot_lock: bool = DEFAULT_FOOT_LOCK,
        terrain: bool = False,
        specs: tuple = (),
        hand_supports: bool = False,
    ):
        controller, samples = chosen_controller(samples, controller)
        known = CONTROLLERS + OPTIONAL_CONTROLLERS
        if controller not in known:
            raise UsageError(f"unknown controller {controller!r}; known: {', '.join(known)}")
        torque = controller in TORQUE_CONTROLLERS
        if controller != "lqr" and torque != (not model.actuator_biasprm[:, 1].any()):
            raise UsageError(
                f"controller {controller!r} needs sim_model(..., actuators="
                f"{'motor' if torque else 'position'!r})"
            )
        self.model = model
        self.names = tuple(names)
        self.samples = samples
        self.controller = controller
        self.search = dict(search or {})
        self.threads = int(threads)
        #: the tracked reference is contact-consistent (always for the whole-body QP)
        if contact_reference is None:
            contact_reference = controller == "lqr" or (
                controller == "sampling" and DEFAULT_CONTACT_REFERENCE
            )
        self.contact = bool(contact_reference) or controller == "wholebody"
        if foot_lock and not self.contact:
            raise UsageError("foot_lock needs the contact-consistent reference")
        self.foot_lock = bool(foot_lock)
        self.specs = tuple(mujoco.MjSpec.from_string(x) if isinstance(x, str) else x for x in specs)
        if terrain and len(self.specs) != 1 + len(self.search.get("alternates", ())):
            raise UsageError("terrain needs the specs of the model and of its alternates")
        self.terrain, self.hand_supports = bool(terrain), bool(hand_supports)
        self.last_boxes, self.last_ground = [], None  # the last scene's boxes, ground (T',) [m]
        self.data = mujoco.MjData(model)
        self._sites = [-1 if n == "root" else model.site(f"{n}_end").id for n in self.names]
        self._root = model.body("root").id

    def __reduce__(self):  # to another process: rebuilt there with fresh MuJoCo data
        args = self.model, self.names, self.samples, self.controller, self.search, self.threads
        specs = tuple(x.to_xml() for x in self.specs)  # an MjSpec does not pickle
        return (ForwardValidation, (*args, self.contact, self.foot_lock, self.terrain, specs,
                                    self.hand_supports))  # fmt: skip

    def points(self, qpos: np.ndarray) -> np.ndarray:
        """(T, P, 3) the model's points [m] at each ``qpos`` (T, nq)."""
        out = np.empty((len(qpos), len(self.names), 3))
        for t, q in enumerate(qpos):
            self.data.qpos[:] = q
            mujoco.mj_kinematics(self.model, self.data)
            for k, s in enumerate(self._sites):
                out[t, k] = self.data.xpos[self._root] if s < 0 else self.data.site_xpos[s]
        return out

    def reference(
        self,
        qpos: np.ndarray,
        fps: float,
        floor: np.ndarray | None = None,
        shift: np.ndarray | None = None,
        *,
        contact: bool | None = None,
        model=None,
    ):
        """``qpos`` (T, nq) at ``fps`` resampled at the control rate and shifted vertically by
        ``floor`` ((T', ,) the original's floor track, from :meth:`floor_of`; default its own),
        its soles near the floor laid flat where the model has soles
        (``sim.simulate.reference.flat_soles``); then lifted by ``FLOOR_LIFT``, or, where
        ``contact`` (default: the reference this body tracks), lowered by ``shift`` ((T',)
        [m], :meth:`stance_shift` of the original; default its own), so that the stance soles
        stand on z = 0 (``contact_consistent``). ``model``: the scene whose supports the
        stance soles stand on (a clip's terrain, ``sim.simulate.terrain``; default the body's)."""
        scene = self.model if model is None else model
        ref = time_warp(self.model, qpos, fps, 1.0, CONTROL_HZ)
        floor = self.floor_of(ref) if floor is None else floor
        if self.contact if contact is None else contact:  # no lift, stance soles on the floor
            ref[:, 2] -= floor
            ref = flat_soles(scene, ref)
            if shift is None:
                shift = contact_shift(scene, ref, floating=DEFAULT_FLOATING)
            ref[:, 2] -= shift
            return ref
        ref[:, 2] -= floor - FLOOR_LIFT
        return flat_soles(self.model, ref)

    def stance_shift(
        self, qpos: np.ndarray, fps: float, floor: np.ndarray, model=None
    ) -> np.ndarray:
        """(T',) [m] the contact-consistent shift (``contact_shift``) of ``qpos`` (T, nq at
        ``fps``) on ``floor`` (T',), its soles laid flat: what :meth:`reference` takes off a
        contact-consistent reference after the floor; on ``model``'s scene (default the
        body's)."""
        scene = self.model if model is None else model
        ref = time_warp(self.model, qpos, fps, 1.0, CONTROL_HZ)
        ref[:, 2] -= floor
        return contact_shift(scene, flat_soles(scene, ref), floating=DEFAULT_FLOATING)

    def skating_reference(self, ref: np.ndarray, model=None) -> np.ndarray:
        """The tracked motion as :meth:`skating` measures it: ``ref`` (T, nq, from
        :meth:`reference`) with its floor at z = 0 and its stance soles on it
        (``contact_consistent``), whatever the controller: a lifted reference's soles reach the
        contact threshold only where its floor estimate is high, so its contact frames are not
        the simulated body's (which stands on z = 0). ``model``: the scene whose supports its
        stance soles stand on (default the body's: the floor)."""
        if self.controller == "wholebody":  # its reference is contact-consistent already
            return ref
        out = ref.copy()
        out[:, 2] -= FLOOR_LIFT  # its floor back at z = 0
        scene = self.model if model is None else model
        return contact_consistent(scene, out, floating=DEFAULT_FLOATING)

    def floor_of(self, ref120: np.ndarray) -> np.ndarray:
        """(T',) floor height [m] under a control-rate ``qpos`` stream."""
        return floor_track(self.model, ref120, CONTROL_HZ)

    def run(self, qpos: np.ndarray, fps: float, original_qpos: np.ndarray | None = None) -> dict:
        """Track ``qpos`` (T, nq, at ``fps``) without assistance; the figures of
        :data:`SIMULATE_KEYS` (JSON-ready):

        * ``sim_error_mm``: mean distance [mm] of the simulated points to the tracked motion's
          (placed as :meth:`reference` places it without ``contact``, lifted, for the plain
          tracker and the sampler even where they track the contact-consistent one);
        * ``sim_error_original_mm``: the same against ``original_qpos`` (default the motion);
        * ``sim_error_local_mm``: as ``sim_error_mm``, each frame's points relative to the root;
        * ``sim_skate_mm_s`` and ``sim_skate_ref_mm_s``: foot skating in contact of the
          simulated and the tracked motion, one estimator for both (:meth:`skating`), the
          tracked motion's with its stance soles on the floor (:meth:`skating_reference`);
        * ``sim_fell`` (0/1) and ``sim_fall_s``: the time of the fall [s] (None: no fall), a fall
          as ``sim.simulate.falls`` defines it (a part other than the feet on the floor where
          the reference has none, or the head below half the reference's);
        * ``sim_torque_rms_nm_kg``: RMS joint torque [N m / kg] applied;
        * ``sim_torque_saturated``: share of (frame, joint) samples at their torque limit;
        * ``sim_steps``: the inferred scene's boxes (:attr:`terrain`; 0: the empty floor).
        """
        original_qpos = qpos if original_qpos is None else original_qpos
        orig = time_warp(self.model, original_qpos, fps, 1.0, CONTROL_HZ)
        floor = self.floor_of(orig)
        floor, model, search = self._terrain(orig, floor)
        terrain = terrain_geoms(model) if self.last_boxes else None  # skating on the steps too
        # The yardstick: the motion and the original on the original's floor, with the same
        # feet (``ref``, ``orig``): lifted for the plain tracker and the sampler, contact-
        # consistent for the QP, whatever they track. With ``contact_reference`` the body
        # tracks the motion lowered by the original's stance shift instead (``tracked``: its
        # stance soles on z = 0 and a reconstruction's own height errors kept, as the floor
        # track keeps them), but its errors are still measured against the lifted ``ref`` and
        # ``orig`` and its skating against the same ``skating_reference(ref)``: every figure
        # is taken against the same points and floor as the lifted reference's run, so the two
        # compare clip by clip (the root-relative error does not see a vertical shift at all).
        lifted = self.controller != "wholebody"
        ref = self.reference(qpos, fps, floor, contact=not lifted, model=model)
        orig = self.reference(original_qpos, fps, floor, contact=not lifted, model=model)
        tracked = ref
        if self.contact and lifted:
            shift = self.stance_shift(original_qpos, fps, floor, model)
            tracked = self.reference(qpos, fps, floor, shift, contact=True, model=model)
        if self.foot_lock:  # its stance soles held still on the floor by the legs
            tracked = foot_locked(self.model, tracked, CONTROL_HZ)
        every = int(round(CONTROL_HZ / fps))
        if self.controller == "sampling":
            search = {"balance": DEFAULT_BALANCE, "noise_deflection": DEFAULT_NOISE_DEFLECTION,
                      **search}  # fmt: skip
            tracker = choice_track if search.get("alternates") else sample_track  # gains chosen
            r = tracker(model, tracked, samples=self.samples, record_every=every,
                        threads=self.threads, **search)  # fmt: skip
        elif self.controller == "wholebody":
            r = track_wholebody(model, tracked, record_every=every, **search)
        elif self.controller == "lqr":
            r = track_lqr(model, tracked, record_every=every, **search)
        else:
            r = track(model, tracked, assist_limit=0.0, record_every=every)
        self.last_qpos = r.qpos  # the simulated states (F, nq) of the last run: for pictures
        self.last_tracked = tracked  # the reference (T, nq, control rate) it tracked
        self.last_fall_tick = int(getattr(r, "fall_tick", -1))  # the first fallen tick, or -1
        self.last_unstable = bool(r.unstable)  # MuJoCo flagged a diverging acceleration in it
        sim = self.points(r.qpos)
        n = len(sim)
        target = self.points(ref[::every][:n])
        original = self.points(orig[::every][:n])
        lim = self.model.actuator_forcerange[:, 1]
        tau = r.joint_torque
        local = (sim - sim[:, :1]) - (target - target[:, :1])
        return {
            "sim_error_mm": 1e3 * float(np.linalg.norm(sim - target, axis=-1).mean()),
            "sim_error_local_mm": 1e3 * float(np.linalg.norm(local, axis=-1).mean()),
            "sim_skate_mm_s": self.skating(r.qpos, fps, terrain),
            "sim_skate_ref_mm_s": self.skating(
                self.skating_reference(ref, model)[::every][:n], fps, terrain
            ),
            "sim_error_original_mm": 1e3 * float(np.linalg.norm(sim - original, axis=-1).mean()),
            "sim_fell": int(r.fell),
            "sim_fall_s": None if r.fall_frame < 0 else r.fall_frame / fps,
            "sim_steps": len(self.last_boxes),  # the scene's inferred steps (0: the empty floor)
            "sim_torque_rms_nm_kg": float(np.sqrt(np.mean(tau**2)) / total_mass(self.model)),
            "sim_torque_saturated": float(np.mean(np.abs(tau) >= lim * (1 - 1e-6))),
        }

    def _terrain(self, orig: np.ndarray, floor: np.ndarray) -> tuple:
        """The floor track (T',), model and ``search`` a clip whose original is ``orig`` (T', nq,
        control rate) is tracked with: with :attr:`terrain` and supports found in ``orig``
        (kept in :attr:`last_boxes` and :attr:`last_ground`), its ground track and :meth:`scene`;
        else ``floor`` and this object's own."""
        self.last_boxes, self.last_ground = [], None
        if self.terrain:  # the scene of the original motion: its steps, its ground track
            find = find_handholds if self.hand_supports else find_terrain
            boxes, ground = find(self.model, orig, CONTROL_HZ)
            if boxes:
                self.last_boxes, self.last_ground = boxes, ground
                return (ground, *self.scene(boxes))
        return floor, self.model, self.search

    def scene(self, boxes: list) -> tuple:
        """The body's model and ``search`` (its ``alternates``) compiled anew with ``boxes``
        (``sim.simulate.terrain.scene_model`` of :attr:`specs`; this object's models are not
        changed)."""
        alternates = self.search.get("alternates", ())
        models = tuple(scene_model(x, boxes) for x in self.specs)
        if alternates:  # one body again, as forward_validation made this object's (common_body)
            models = common_body(models)
        search = {**self.search, "alternates": models[1:]} if alternates else self.search
        return models[0], search

    def skating(self, qpos: np.ndarray, fps: float, terrain: tuple | None = None) -> float | None:
        """Foot skating in contact [mm/s] of a motion ``qpos`` (F, nq at ``fps``): the mean
        horizontal speed of each sole box's bottom centre over the frames where its lowest
        corner is at most :data:`SKATE_CONTACT` high (central differences) above the floor or
        a ``terrain`` box under that centre (``sim.simulate.terrain.terrain_geoms``); NaN
        without soles or without contact: None. One geometric estimator for simulated and
        reference motion alike."""
        soles = sole_ids(self.model)
        if soles is None or len(qpos) < 3:
            return None
        low = np.empty((len(qpos), 2, 3))
        for t, q in enumerate(qpos):
            self.data.qpos[:] = q
            mujoco.mj_kinematics(self.model, self.data)
            for s, g in enumerate(soles):
                c = sole_corners(self.model, self.data, g)
                low[t, s] = c.mean(axis=0)[0], c.mean(axis=0)[1], c[:, 2].min()
        speed = np.linalg.norm(np.gradient(low[..., :2], 1.0 / fps, axis=0), axis=-1)
        if terrain is not None:  # a sole on a step touches it
            low[..., 2] -= surface_height(terrain, low[..., :2])
        contact = low[..., 2] <= SKATE_CONTACT
        return 1e3 * float(speed[contact].mean()) if contact.any() else None


def forward_validation(
    skeleton,
    names,
    *,
    samples: int = 0,
    controller: str | None = None,
    contact_reference: bool | None = None,
    gain_choice: GainChoice | None = DEFAULT_GAIN_CHOICE,
    threads: int = 1,
    terrain: bool = DEFAULT_TERRAIN,
    **body,
) -> ForwardValidation:
    """The :class:`ForwardValidation` of ``skeleton``'s simulated body
    (:func:`validation_model`: ``sim_model(skeleton, **body)`` with :data:`DEFAULT_GAINS` and
    the actuators its controller needs) on points ``names``: ``samples`` > 0 the
    sampling tracker with that count, else ``controller`` (default :data:`DEFAULT_CONTROLLER`,
    the sampler at :data:`DEFAULT_SAMPLES`); ``contact_reference``: it tracks the
    contact-consistent reference (:class:`ForwardValidation`). The sampler chooses its gains
    per window by ``gain_choice`` between the body's gains and :data:`STIFF_GAINS` (one body:
    ``common_body``); None or a share of 0: the body's gains only; ``threads``: the sampler's
    rollouts on that many threads (the same figures); ``terrain``: each clip in the scene
    inferred from its original motion (:class:`ForwardValidation`)."""
    controller, _ = chosen_controller(samples, controller)
    actuators = "motor" if controller in TORQUE_CONTROLLERS else "position"
    specs = [validation_spec(skeleton, actuators=actuators, **body)]
    search = {}
    if controller == "sampling" and gain_choice is not None and gain_choice.share > 0:
        specs.append(
            validation_spec(skeleton, actuators=actuators, **{**body, "gains": STIFF_GAINS})
        )
        model, stiff = common_body(tuple(x.compile() for x in specs))
        search = {"alternates": (stiff,), "choice": gain_choice}
    else:
        model = specs[0].compile()
    return ForwardValidation(
        model, names, samples=samples, controller=controller, search=search, threads=threads,
        contact_reference=contact_reference, terrain=terrain, specs=tuple(specs),
    )  # fmt: skip


def validation_model(skeleton, *, actuators: str = "position", **body) -> mujoco.MjModel:
    """``skeleton``'s simulated body as forward validation builds it: ``sim_model(skeleton,
    actuators=actuators, **body)`` with the feedback gains :data:`DEFAULT_GAINS` and
    :data:`DEFAULT_LEAN` unless ``body`` names them."""
    return validation_spec(skeleton, actuators=actuators, **body).compile()


def validation_spec(skeleton, *, actuators: str = "position", **body) -> mujoco.MjSpec:
    """The ``MjSpec`` :func:`validation_model` compiles (``sim_spec``)."""
    defaults = {"gains": DEFAULT_GAINS, "lean": DEFAULT_LEAN}
    return sim_spec(skeleton, actuators=actuators, **{**defaults, **body})
