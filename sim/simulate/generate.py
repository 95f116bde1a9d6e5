"""Synthetic clips from MuJoCo's forward simulation, in the ``sidql dataset`` clip format.

Clips last :data:`CLIP_SECONDS` (the protocol's 60 frames at 30 fps) unless a task says
otherwise. Kinds (each clip's parameters are drawn from its own seed, :func:`episode_rng`):

* ``track``: perturbed tracking of a real trial: the fastest of 4 random windows
  (:func:`fastest_window`) time-warped 1-1.6x (:data:`TRACK_SPEED`: velocity-rich on purpose,
  never slower than recorded unless the trial is too short to fill the clip), body size
  0.85-1.15x (mass scaling with its cube), controller stiffness 0.6-1.5x, 0-1 push in a 2 s
  clip, 0-2 in 4 s (:data:`PUSH_SECONDS`) of 100-300 N for 0.1-0.2 s on the thorax or the
  pelvis (impulse recorded);
* ``fall``: falls and recoveries: a real trial sped up 1-2x, a push for 0.2 s and the controller
  weakened from the push on, then restored (the recovery attempt); one severity s ~ U(0, 1) sets
  the push (250-900 N), the weakening (to 60-5 % of its effort) and its length (0.3-1.5 s), so
  mild draws stumble and recover and severe ones fall (``fell`` in the clip's record);
* ``follow`` (not in the default mix): unperturbed tracking of a real trial, the baseline;
* ``procedural`` (not in the default mix): the sinusoidal motion of ``sim.motion.synthetic``
  (amplitude 35-60 % of each joint's half range) replayed 1-2x faster, tracked in simulation
  with up to :data:`PROCEDURAL_ASSIST` body weight of recorded root assistance.

The real-motion kinds get no assistance unless their task asks for it (``SynthTask.assist``):
only the joints, within the human torque limits, and the floor move the body. They are tracked
in the scene inferred from their trial unless their task says otherwise (``SynthTask.terrain``,
:data:`SYNTH_TERRAIN`; ``sim.simulate.episode_scene``): static boxes under feet that stand on
raised supports, held in the episode's MJCF and recorded in its parameters (``scene``).

Positions, point velocities and ``qvel`` of a clip are the simulator's state sampled at the clip
rate; point velocities come from the kinematic chain (``point_kinematics`` with the simulator's
``qvel``), never from differences.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from sim.errors import UnknownNameError, UsageError
from sim.model.humanoid import canonical_skeleton
from sim.model.kinematics import point_names, point_parents
from sim.motion.clip import Clip
from sim.motion.retarget import local_rotations_from_world
from sim.motion.velocities import point_kinematics
from sim.simulate.controller import ROOT_TORQUE_LEVER, Push, Tracking, Weakening, track
from sim.simulate.episode import FRAME_SKIP, Recorder, text_array, torque_limits
from sim.simulate.episode_scene import SYNTH_TERRAIN, episode_setup
from sim.simulate.gainchoice import GainChoice, choice_track
from sim.simulate.model import CONTROL_HZ, G, Gains, scaled_skeleton, total_mass
from sim.simulate.sampling import BALANCE, LOOKAHEAD, CostWeights, sample_track
from sim.simulate.validate import CONTROLLERS, DEFAULT_BALANCE, STIFF_GAINS, chosen_controller
from sim.simulate.wholebody import track_wholebody

KINDS = ("track", "fall")  # the default mix: real motion, no assistance
#: [s] a clip's length unless asked otherwise: the protocol's 60 frames at 30 fps (the length
#: the controller's figures are measured on; longer clips fall more often)
CLIP_SECONDS = 2.0
# a clip is "physical" when its mean root assistance force is within this share of its body
# weight and its mean root assistance torque within this share of body weight x 1 m
PHYSICAL_BUDGET = 0.05
# learning labels stored in each clip file (``save_npz``'s ``extra``), with shapes: F frames,
# T control ticks (F = ceil(T / record_every): frame i is tick i * record_every), U = nu
# actuators (one per hinge, the order of the clip's ``joint_names``), B bodies, S state size
EPISODE_LABELS = {
    "sim_actions": "(T, U) actuator controls at each control tick, as they act on the body "
    "the MJCF builds (sim.simulate.episode.Recorder): PD target [rad], the feed-forward "
    "folded in, inside each actuator's control range (the joint range widened: "
    "sim.simulate.model.sim_spec), or with the whole-body QP the torque [N m] within its limit",
    "sim_actuator_gains": "(T, 2, U) position actuators only: the feedback gains acting at each "
    "tick, kp [N m/rad] and kv [N m s/rad] (the gain set the sampler chose, else the MJCF's): "
    "a replay sets them before stepping (sim.simulate.episode.set_gains)",
    "sim_xfrc_applied": "(T, B, 6) applied body wrenches at each tick (pushes): force [N], "
    "torque [N m], world frame",
    "sim_qfrc_applied": "(T, nv) applied generalised forces at each tick (root assistance: "
    "zero unless the task asked for it or the clip is procedural)",
    "sim_tick_qpos": "(T + 1, nq) qpos before each tick and after the last",
    "sim_tick_qvel": "(T + 1, nv) qvel likewise",
    "sim_initial_state": "(S,) mj_getState(mjSTATE_INTEGRATION) before the first tick",
    "sim_mjcf": "(n,) uint8: the body's MJCF (UTF-8; sim.simulate.episode.array_text), the "
    "model simulated, with its scene's static boxes (terrain<k>) where it has any",
    "sim_frame_skip": "() int: physics steps per action",
    "sim_torque_limit": "(U,) each actuator's torque limit [N m] (the human peak torque)",
    "sim_generation": "(n,) uint8: JSON (UTF-8) of the generation parameters, the episode's "
    "seed included",
    "sim_fall_tick": "() int: the tick whose state is the first fallen one, -1 if none (an "
    "episode for learners ends there: sim.simulate.export)",
}
LABELS = {
    **EPISODE_LABELS,
    "sim_joint_torque": "(F, U) applied hinge torques [N m] (within the human limits)",
    "sim_assist_wrench": "(F, 6) root assistance: force [N] world frame, torque [N m] root frame",
    "sim_foot_contact": "(F, 2) bool: left, right foot (foot or toe) touches the floor (or a "
    "box of the scene)",
    "sim_foot_force": "(F, 2, 3) floor (and boxes') contact force [N, world frame] on the left, "
    "right foot",
    "sim_contact_penetration": "(F,) deepest floor (or box) contact penetration [m], 0 without "
    "contact",
    "sim_fallen": "(F,) bool: the figure has fallen (sim.simulate.falls: a part other than the feet on the floor where the reference has none, or the head below half the reference's)",
}
ALL_KINDS = (*KINDS, "follow", "procedural")
REAL_KINDS = ("track", "fall", "follow")
# root assistance bound [body weight] of the procedural kind: its motion is not physically
# plausible (its feet slide and its root glides), so asking for it asks for a hand of up to the
# whole body weight, recorded per tick and per frame; the real-motion kinds get none unless a
# task asks for it (``SynthTask.assist``)
PROCEDURAL_ASSIST = 1.0
#: [s] the ``track`` kind draws 0 to 1 + (its length // this) pushes: 0-1 in a 2 s clip, 0-2
#: in 4 s (a short clip is not pushed more often than a long one)
PUSH_SECONDS = 4.0
#: the ``track`` kind's time warp, uniform over this range: faster than recorded (a source too
#: short to fill a clip at the drawn warp is played at the fastest warp that fills it)
TRACK_SPEED = (1.0, 1.6)
#: controllers of the real-motion kinds: ``eval --simulate``'s (``sim.simulate.validate``)
SYNTH_CONTROLLERS = CONTROLLERS
#: the controller of the real-motion kinds unless a task names one: ``eval --simulate``'s
#: default (``sim.simulate.validate.chosen_controller``: the sampler, at its default count of
#: rollouts), no assistance; the plain tracker costs about a twentieth of it but falls in
#: nearly every clip (docs/results/synth.md)
SYNTH_DEFAULT_CONTROLLER = chosen_controller()[0]
#: unless a task says otherwise: the sampler's balance feedback with eval's drift lead
#: (``validate.DEFAULT_BALANCE``, else ``sampling.BALANCE``), its reference contact-consistent
#: (else lifted 1 cm), the body stepped lean (``sim_spec(lean=True)``: the same motion). Off:
#: on bench_synth's 20 clips none kept more up or met more targets; the contact-consistent
#: reference kept fewer up on 60 clips x 2 seeds too (docs/synthetic.md)
SYNTH_DRIFT, SYNTH_CONTACT_REFERENCE, SYNTH_LEAN = False, False, False
#: the sampler's share of candidates per window on the stiff gains (``sim.simulate.gainchoice``,
#: ``validate.STIFF_GAINS`` times the episode's gain draw), the gains stored per tick; 0: the
#: body's gains alone. Not the default: on 60 clips x 2 seeds 0.25 kept more up and skated less,
#: but lowered the p95 speed ratio on one seed (docs/synthetic.md)
SYNTH_GAIN_CHOICE = 0.0
#: the sampler's rollouts per window unless a task names one (not eval's 40: docs/synthetic.md)
SYNTH_SAMPLES = 28
#: the contact-consistent reference foot-locked (``sim.simulate.footlock``: its stance soles
#: held still, flat on the floor, by the legs), as ``ForwardValidation(foot_lock=True)``. Off:
#: on 60 clips it kept fewer up on one of two seeds (docs/synthetic.md)
SYNTH_FOOT_LOCK = False
#: :class:`SynthTask`'s options: in a task's dict and a run's journal only where True (non-zero)
#: (``terrain`` is on by default: a run without it in its journal, from before it, was on the
#: empty floor, as one with ``--flat-floor`` is)
TASK_OPTIONS = ("drift", "contact_reference", "lean", "gain_choice", "foot_lock", "terrain")


def is_physical(mean_force_bw: float, mean_torque_bw_m: float) -> bool:
    """Whether a clip's mean root assistance, force [body weight] and torque [body weight x
    1 m], is within :data:`PHYSICAL_BUDGET`: the motion is (nearly) the body's own doing."""
    return mean_force_bw <= PHYSICAL_BUDGET and mean_torque_bw_m <= PHYSICAL_BUDGET


class UnstableSimulation(RuntimeError):
    """MuJoCo reported a diverging simulation; the clip is dropped (and listed), not written."""


@dataclass(frozen=True)
class SynthTask:
    """One clip to generate: its kind, seed, source trial (None for procedural), length, rate."""

    kind: str
    seed: int
    index: int
    asf: str | None = None
    amc: str | None = None
    seconds: float = CLIP_SECONDS
    fps: float = 30.0
    samples: int = 0  # the sampler's rollouts per window; 0: its default count
    controller: str = SYNTH_DEFAULT_CONTROLLER  # of the real-motion kinds (SYNTH_CONTROLLERS)
    assist: float = 0.0  # root assistance bound [body weight] of the real-motion kinds: none
    threads: int = 1  # the sampler's rollouts run on this many threads (same result for any)
    drift: bool = SYNTH_DRIFT  # the sampler's balance feedback with the drift lead
    contact_reference: bool = SYNTH_CONTACT_REFERENCE  # the sampler's (else lifted 1 cm)
    lean: bool = SYNTH_LEAN  # the body stepped lean (its MJCF says so)
    gain_choice: float = SYNTH_GAIN_CHOICE  # the sampler's share on the stiff gains (0: none)
    foot_lock: bool = SYNTH_FOOT_LOCK  # the contact-consistent reference foot-locked
    terrain: bool = SYNTH_TERRAIN  # real motion in the scene inferred from its trial


def synth_controller(samples: int = 0, controller: str | None = None) -> tuple[str, int]:
    """``validate.chosen_controller`` at synth's default count (:data:`SYNTH_SAMPLES`)."""
    return chosen_controller(samples, controller, SYNTH_SAMPLES)


def task_controller(task: SynthTask) -> tuple[str, int]:
    """The controller that tracks ``task`` and its sample count (0 but for the sampler): the
    plain tracker for procedural motion (its assistance), else ``task.controller`` (the
    sampler at ``task.samples`` rollouts per window, synth's default count where 0:
    :func:`synth_controller`).

    Raises:
        UnknownNameError: an unknown controller.
        UsageError: samples asked of a controller that does not sample.
    """
    if task.kind == "procedural":
        return "plain", 0
    if task.controller not in SYNTH_CONTROLLERS:
        raise UnknownNameError("controller", task.controller, SYNTH_CONTROLLERS)
    if task.samples and task.controller != "sampling":
        raise UsageError(f"{task.samples} samples: only the sampling controller samples, not "
                         f"{task.controller!r}")  # fmt: skip
    return synth_controller(task.samples, task.controller)


def episode_seed(task: SynthTask) -> int:
    """The seed of ``task``'s episode, its own (not the run's): the run's seed times 2**32 plus
    the task's index; every random draw of the episode comes from :func:`episode_rng` of it."""
    if not 0 <= task.seed < 2**31 or not 0 <= task.index < 2**32:
        raise UsageError(f"seed {task.seed} and index {task.index}: expected 0 <= seed < 2**31")
    return task.seed * 2**32 + task.index


def episode_rng(seed: int) -> np.random.Generator:
    """The random stream of the episode whose seed (:func:`episode_seed`) is ``seed``:
    ``SeedSequence([run seed, task index])``."""
    return np.random.default_rng(np.random.SeedSequence(list(divmod(int(seed), 2**32))))


def draw_parameters(task: SynthTask, rng: np.random.Generator) -> dict:
    """The generation parameters of ``task`` (JSON-ready), drawn from ``rng``."""
    p: dict = {"kind": task.kind, "seed": episode_seed(task), "run_seed": task.seed}
    if task.kind == "track":
        # velocity-rich on purpose, never slower than recorded (TRACK_SPEED)
        p["speed"] = float(rng.uniform(*TRACK_SPEED))
        p["scale"] = float(rng.uniform(0.85, 1.15))
        p["gain"] = float(rng.uniform(0.6, 1.5))
        pushes = []
        for _ in range(int(rng.integers(0, 2 + int(task.seconds // PUSH_SECONDS)))):
            d = rng.normal(size=2)
            d /= np.linalg.norm(d)
            mag = rng.uniform(100, 300)
            pushes.append(
                {
                    "body": str(rng.choice(["thorax", "root"])),
                    "start": float(rng.uniform(0.3, max(0.3, task.seconds - 0.5))),
                    "duration": float(rng.uniform(0.1, 0.2)),
                    "force": [float(mag * d[0]), float(mag * d[1]), 0.0],
                }
            )
        p["pushes"] = pushes
        p["weakenings"] = []
    elif task.kind == "fall":
        p["speed"] = float(rng.uniform(1.0, 2.0))
        p["scale"] = float(rng.uniform(0.9, 1.1))
        p["gain"] = 1.0
        d = rng.normal(size=2)
        d /= np.linalg.norm(d)
        # One severity in [0, 1] sets push, weakening and its length together: mild draws stumble
        # and recover once the controller is restored, severe ones end on the floor.
        severity = float(rng.uniform(0.0, 1.0))
        mag = 250.0 + 650.0 * severity
        start = float(rng.uniform(0.5, 1.5))
        p["severity"] = severity
        p["pushes"] = [
            {"body": "thorax", "start": start, "duration": 0.2,
             "force": [float(mag * d[0]), float(mag * d[1]), 0.0]}
        ]  # fmt: skip
        p["weakenings"] = [
            {"start": start, "duration": 0.3 + 1.2 * severity,
             "factor": 0.6 - 0.55 * severity}
        ]  # fmt: skip
    elif task.kind == "follow":
        p.update(speed=1.0, scale=1.0, gain=1.0, pushes=[], weakenings=[])
    elif task.kind == "procedural":
        p.update(scale=1.0, gain=1.0, pushes=[], weakenings=[])
        p["speed"] = float(rng.uniform(1.0, 2.0))
        p["energy"] = float(rng.uniform(0.35, 0.6))
        p["motion_seed"] = int(rng.integers(0, 2**31 - 1))
    else:
        raise UnknownNameError("kind", task.kind, ALL_KINDS)
    if not 0 <= task.assist <= 1:
        raise UsageError(f"assistance {task.assist} body weights: expected 0 .. 1")
    if not 0 <= task.gain_choice <= 1:
        raise UsageError(f"gain choice {task.gain_choice}: expected a share 0 .. 1")
    p["controller"] = task_controller(task)[0]
    if p["controller"] == "wholebody":  # its feedback gains are its own: no stiffness factor
        p["gain"] = 1.0
    p["assist_limit"] = PROCEDURAL_ASSIST if task.kind == "procedural" else float(task.assist)
    if p["controller"] != "plain" and p["assist_limit"]:
        raise UsageError(f"the {p['controller']} controller takes no assistance")
    for push in p["pushes"]:
        push["impulse"] = [f * push["duration"] for f in push["force"]]
    return p


def generate(task: SynthTask) -> tuple[Clip, dict]:
    """Simulate one clip; returns it and a record of its parameters and tracking measures.

    The record holds ``generation`` (parameters and seed), ``tracking_mpjpe_mm`` (and
    ``tracking_local_mm``, root-relative), ``fell`` (and ``fall_frame``), ``mean_assistance``
    (root assistance force [body weight], mean over frames), ``mean_assist_torque`` (its torque
    [body weight x 1 m]), ``physical`` (:func:`is_physical`), ``penetration_mm`` (deepest floor
    contact), ``self_penetration_mm`` (deepest contact between two body geoms) and ``labels``:
    the per-frame arrays of :data:`LABELS`, for the clip file, not the index.

    Raises:
        MotionDataError: the source trial is unreadable or shorter than one clip.
        UnstableSimulation: the simulation diverged.
    """
    rng = episode_rng(episode_seed(task))
    p = draw_parameters(task, rng)
    skeleton = scaled_skeleton(canonical_skeleton(), p["scale"])
    stiff = (STIFF_GAINS,) if p["controller"] == "sampling" and task.gain_choice > 0 else ()
    p["lean"] = bool(task.lean)
    n = int(round(task.seconds * CONTROL_HZ))
    models, mjcf, gains, ref = episode_setup(task, p, skeleton, stiff, n, rng)  # in its scene
    model = models[0]
    recorder = Recorder(model, mjcf, n, FRAME_SKIP)
    result = simulate_episode(task, p, models, gains, ref, recorder, rng)
    if result.unstable:
        raise UnstableSimulation(f"{task.kind} task {task.index} (seed {task.seed}): diverged")
    out = simulated_clip(
        model, skeleton, result.qpos, result.qvel, task.fps, f"synth:{task.kind}:{p['source']}"
    )
    ref_pos = simulated_clip(
        model, skeleton, ref[:: int(round(CONTROL_HZ / task.fps))],
        np.zeros((len(result.qpos), model.nv)), task.fps, "",
    ).positions  # fmt: skip
    record = episode_record(p, model, result, out.positions, ref_pos)
    record["labels"] = episode_labels(p, model, mjcf, result, recorder.episode())
    return out, record


def simulate_episode(
    task: SynthTask, p: dict, models: tuple, gains: Gains, ref: np.ndarray, recorder: Recorder,
    rng: np.random.Generator,
) -> Tracking:  # fmt: skip
    """Track ``ref`` (T, nq) with ``p``'s pushes and weakenings, every tick recorded by
    ``recorder``, by ``p["controller"]``: the sampling tracker (no assistance; its settings,
    balance feedback (with the drift lead where ``task.drift``) and seed, drawn from ``rng``,
    recorded in ``p``; with ``models`` of two gain sets (``episode_bodies``) its gains chosen
    per window, ``task.gain_choice`` of its candidates on the second), the whole-body QP (no
    assistance) or the plain tracker with ``p["assist_limit"]`` (0 for real motion unless the
    task asked for it), all on ``models[0]``."""
    model = models[0]
    tracking = {  # what both trackers take: the perturbations and the clip rate
        "pushes": tuple(
            Push(**{k: v for k, v in q.items() if k != "impulse"}) for q in p["pushes"]
        ),
        "weakenings": tuple(Weakening(**w) for w in p["weakenings"]),
        "record_every": int(round(CONTROL_HZ / task.fps)),
        "recorder": recorder,
    }
    if p["controller"] == "wholebody":
        return track_wholebody(model, ref, **tracking)
    if p["controller"] == "sampling":  # the body's own doing, or a fall
        samples = task_controller(task)[1]
        balance = DEFAULT_BALANCE if task.drift else BALANCE
        p["sampling"] = {
            "samples": samples,
            "lookahead": LOOKAHEAD,
            "root_xy_weight": CostWeights().root_xy,
            "balance": asdict(balance) if balance is not None else None,
            "seed": int(rng.integers(0, 2**31 - 1)),
        }
        kw = {"samples": samples, "seed": p["sampling"]["seed"], "threads": task.threads,
              "balance": balance}  # fmt: skip
        if len(models) > 1:  # the gains chosen per window, recorded per tick
            stiff = {k: v if v is None else float(v)
                     for k, v in asdict(STIFF_GAINS.scaled(p["gain"])).items()}  # fmt: skip
            p["sampling"]["gain_choice"] = {"share": float(task.gain_choice), "stiff": stiff}
            choice = GainChoice(share=task.gain_choice)
            return choice_track(model, ref, alternates=models[1:], choice=choice, **kw, **tracking)
        return sample_track(model, ref, **kw, **tracking)
    return track(model, ref, gains=gains, assist_limit=p["assist_limit"], **tracking)


def episode_record(p: dict, model, result: Tracking, pos: np.ndarray, ref_pos: np.ndarray) -> dict:
    """The index record of an episode (:func:`generate`'s, without ``labels``): its parameters
    ``p``, assistance, tracking error of the simulated points ``pos`` (F, P, 3) [m] against the
    reference's ``ref_pos``, fall and penetration figures."""
    weight = total_mass(model) * G
    local = (pos - pos[:, :1]) - (ref_pos - ref_pos[:, :1])  # root-relative (the root first)
    torque = np.linalg.norm(result.assist_wrench[:, 3:], axis=1) / (weight * ROOT_TORQUE_LEVER)
    return {
        "generation": p,
        "mean_assistance": float(result.assistance.mean()),
        "mean_assist_torque": float(torque.mean()),
        "tracking_mpjpe_mm": float(1000 * np.linalg.norm(pos - ref_pos, axis=-1).mean()),
        "tracking_local_mm": float(1000 * np.linalg.norm(local, axis=-1).mean()),
        "fell": bool(result.fell),
        "fall_frame": int(result.fall_frame),
        "fall_tick": int(result.fall_tick),
        "physical": is_physical(float(result.assistance.mean()), float(torque.mean())),
        "penetration_mm": 1000 * result.penetration,
        "self_penetration_mm": 1000 * result.self_penetration,
    }


def episode_labels(p: dict, model, mjcf: str, result: Tracking, episode) -> dict:
    """The arrays of :data:`LABELS` for the clip file: the recorded ``episode``
    (``Recorder.episode()``), the body and the per-frame figures of ``result``."""
    fallen = np.zeros(len(result.qpos), dtype=bool)
    if result.fall_frame >= 0:
        fallen[result.fall_frame :] = True
    return {
        "sim_actions": episode.actions,
        **({} if episode.gains is None else {"sim_actuator_gains": episode.gains}),
        "sim_xfrc_applied": episode.xfrc_applied,
        "sim_qfrc_applied": episode.qfrc_applied,
        "sim_tick_qpos": episode.qpos,
        "sim_tick_qvel": episode.qvel,
        "sim_initial_state": episode.initial_state,
        "sim_mjcf": text_array(mjcf),
        "sim_frame_skip": np.int64(FRAME_SKIP),
        "sim_torque_limit": torque_limits(model),
        "sim_generation": text_array(json.dumps(p)),
        "sim_fall_tick": np.int64(result.fall_tick),
        "sim_joint_torque": result.joint_torque,
        "sim_assist_wrench": result.assist_wrench,
        "sim_foot_contact": np.linalg.norm(result.foot_force, axis=-1) > 0,
        "sim_foot_force": result.foot_force,
        "sim_contact_penetration": result.contact_penetration,
        "sim_fallen": fallen,
    }


def simulated_clip(model, skeleton, qpos, qvel, fps: float, source: str) -> Clip:
    """The clip of simulated states ``qpos`` (F, nq) and ``qvel`` (F, nv) sampled at ``fps``:
    points and their velocities from the kinematic chain (``point_kinematics``), never
    differences."""
    names, parents = point_names(skeleton), point_parents(skeleton)
    body_ids = [model.body(nm).id for nm in names]
    site_ids = [-1 if nm == "root" else model.site(f"{nm}_end").id for nm in names]
    data = mujoco.MjData(model)
    pos, vel, xquat, omega = point_kinematics(model, data, qpos, qvel, body_ids, site_ids)
    return Clip(
        names=tuple(names),
        parents=np.asarray(parents, dtype=np.int64),
        positions=pos,
        velocities=vel,
        qpos=np.asarray(qpos),
        qvel=np.asarray(qvel),
        rotations=local_rotations_from_world(xquat, np.asarray(parents)),
        fps=float(fps),
        source=source,
        start_frame=0,
        source_fps=CONTROL_HZ,
        joint_names=tuple(model.joint(j).name for j in range(1, model.njnt)),
        angular_velocities=omega,
    )


def task_dict(task: SynthTask) -> dict:
    """JSON-ready copy of ``task`` without ``threads`` (how it runs, not what it gives), its
    :data:`TASK_OPTIONS` only where True."""
    d = asdict(task)
    del d["threads"]
    return {k: v for k, v in d.items() if k not in TASK_OPTIONS or v}
