"""A sampling-based tracker (SAMCON, Liu et al. 2010): corrections of the hinge targets found by
trying them in ``mj_step``.

The plain tracker (:func:`sim.simulate.controller.track`) applies the reference's own targets
and feed-forward; without assistance small errors (a lean, a sinking stance) grow until the
body falls. Here the reference is cut into windows of ``window`` control ticks; from each of
the ``keep`` best simulation states reached so far, ``samples`` candidate corrections in all
are tried: per window one offset [rad] per corrected hinge (:data:`CORRECTED`; the legs and
the trunk), the parent's previous offset times ``persistence`` plus Gaussian noise of standard
deviation ``torque_sigma`` times the joint's torque limit over its stiffness (the offset that
asks ``torque_sigma`` of its peak torque; or over a capped one, ``noise_deflection``). Each
candidate runs through the window with the same torque-limited actuators, perturbations,
balance feedback (``sim.simulate.balance``, :data:`BALANCE`: stance hips and ankles keep the
pelvis upright and the centre of mass over the feet, a function of the state alone) and no
assistance, then on for ``lookahead`` more ticks with the same offset; its cost there
(:func:`window_cost`: a correction that only delays a fall costs what the fall costs) is added
to its parent's, and the ``keep`` cheapest states, taken at the window's end, go on. A fall
as ``sim.simulate.falls`` defines it (a part other than the feet on the floor, or the head low)
is looked for after every tick of a rollout: the rollout stops there (or at its window's end,
whose state is kept) and pays ``CostWeights.fall``, more the earlier it fell. At the end the
cheapest sequence of offsets is replayed by ``track(..., offsets=...)``, so the result is an
ordinary :class:`sim.simulate.tracking.Tracking` of one simulation (the replay is the same
deterministic computation as the sampled rollout). Deterministic given ``seed``, whatever the
number of ``threads`` the rollouts run on.

Cost: ``samples`` rollouts of up to ``window + lookahead`` ticks per window plus one replay:
with the balance feedback about 4.9 CPU s per simulated second at 28 samples, 5.2 at 32
(without it 4.4 at 32; ``docs/results/simulate_controllers.md``); on ``sim_model(lean=True)``
0.90-0.94 times that, the same motion (``docs/results/simulate_step.md``).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import mujoco
import numpy as np

from sim.simulate.balance import Balance, balance_plan, held_torques
from sim.simulate.controller import (
    Push,
    Tracking,
    Weakening,
    apply_pushes,
    set_controls,
    track,
    weakening_factor,
)
from sim.simulate.drift import drift_lead
from sim.simulate.falls import fall_reference, has_fallen
from sim.simulate.feedforward import reference_feedforward
from sim.simulate.footholding import as_slice, reference_soles, sole_ids
from sim.simulate.footprints import sole_costs, sole_terms
from sim.simulate.model import CONTROL_HZ, SUBSTEPS
from sim.simulate.noisescale import hinge_bone
from sim.simulate.searchsteps import backtrack, check_window, first_state
from sim.simulate.tracking import clear_divergences, divergences

#: bones whose hinges get sampled corrections (the ones that carry and balance the body)
CORRECTED = ("femur", "tibia", "foot", "toes", "lowerback", "upperback", "thorax")
#: control ticks (0.3 s) a candidate is rolled on past its window before it is judged (0 to 72
#: measured, with and without falls in the cost: docs/synthetic.md, "Looking ahead")
LOOKAHEAD = 36
#: the balance feedback (``sim.simulate.balance``) every rollout and the replay add by default
#: (``balance=None``: none, the sampler before it; measured: docs/synthetic.md)
BALANCE = Balance()
#: a candidate whose simulation diverged (MuJoCo reset its state) costs this: never kept
DIVERGED_COST = 1e15
#: bodies whose positions relative to the root enter the cost
END_EFFECTORS = ("lfoot", "rfoot", "ltoes", "rtoes", "lhand", "rhand", "head")


@dataclass(frozen=True)
class CostWeights:
    """Weights of :func:`window_cost`'s terms (each a squared error in SI units)."""

    pose: float = 1.0  # hinge angles [rad^2], mean weighted by the mass each hinge moves
    root_rot: float = 2.0  # root orientation error [rad^2]
    height: float = 100.0  # root height [m^2]
    root_xy: float = 20.0  # root horizontal position [m^2]: holds the path (see LOOKAHEAD)
    sink: float = 500.0  # root height below the reference's by more than ``sink_margin`` [m]
    sink_margin: float = 0.03
    end_effectors: float = 10.0  # end-effector positions relative to the root [m^2], mean
    balance: float = 50.0  # CoM minus the ankles' mid-point, horizontal [m^2]
    root_vel: float = 0.5  # root linear velocity [m^2/s^2]
    #: [1/s] the root velocity term's horizontal target leads by this times the root's
    #: horizontal position error (reference less simulated, clipped to ``drift_max`` [m]); 0:
    #: off (screened on 5 clips only, no better: docs/synthetic.md)
    drift_rate: float = 0.0
    drift_max: float = 0.3
    fallen: float = 1e4  # root below half its reference height
    #: a fall (``sim.simulate.falls``) in the rollout, doubled if at its start; 0: the rollouts
    #: do not look for falls and run to their end (the sampler as first built)
    fall: float = 1e4
    #: foot holding (``sim.simulate.footholding.slide_cost``) over the window's ticks: a stance
    #: sole sliding faster than the reference's [m^2/s^2]; 0: not looked at (off: it held the
    #: feet but fell more, docs/synthetic.md)
    hold: float = 0.0
    #: foot holding also costs a simulated sole that touches the floor where the reference lifts
    #: it (a dragged foot); False: stance soles only
    hold_contact: bool = True
    #: foot holding gives the feet up where balance needs a step: only ticks with the capture
    #: point inside the support polygon count (``footholding.capture_supported``). Off: on 11
    #: clips (hold 5) 128 mm root-relative error against 114 (docs/synthetic.md)
    hold_capture: bool = False
    #: with ``hold_capture``: only where the reference's capture point is inside its support
    hold_capture_ref: bool = False
    #: footprints (``sim.simulate.footprints``) [1/m^2], 0: off; ``footprint_landing``: at
    #: touch-down only; ``footprint_lookahead``: over the window and its lookahead
    footprint: float = 0.0
    footprint_landing: bool = False
    footprint_lookahead: bool = False
    #: swing clearance [1/m^2] and stance pivot [s^2/rad^2] (``sim.simulate.swingstance``) over
    #: the window's ticks: a sole lower than the reference's swing sole (capped at 3 cm), a
    #: stance sole turning faster than the reference's; 0: off
    clearance: float = 0.0
    pivot: float = 0.0


@dataclass(frozen=True)
class Features:
    """What the cost compares at one instant: root height (scalar), horizontal position (2,)
    and orientation (4,, quaternion), hinge angles (nu,) [rad], end effectors relative to the root
    (E, 3), CoM minus the mid-point of the ankles (2,, horizontal) [m], and the root's linear
    velocity (3,) [m/s] (world frame)."""

    z: float
    xy: np.ndarray
    quat: np.ndarray
    hinges: np.ndarray
    ee: np.ndarray
    balance: np.ndarray
    vel: np.ndarray


def features(model, data, ee_ids: np.ndarray, foot_ids: np.ndarray) -> Features:
    """:class:`Features` of ``data``'s ``qpos``/``qvel`` (kinematics and CoM recomputed;
    state untouched). ``ee_ids``/``foot_ids``: body ids of the end effectors and the two feet."""
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    root = data.xpos[1]
    com = data.subtree_com[1]
    mid = data.xpos[foot_ids].mean(axis=0)
    return Features(
        z=float(data.qpos[2]),
        xy=data.qpos[:2].copy(),
        quat=data.qpos[3:7].copy(),
        hinges=data.qpos[7:].copy(),
        ee=data.xpos[ee_ids] - root,
        balance=(com - mid)[:2].copy(),
        vel=data.qvel[:3].copy(),
    )


def window_cost(sim: Features, ref: Features, w: CostWeights, hinge_w: np.ndarray) -> float:
    """Tracking cost of one simulated instant against the reference (dimensionless, >= 0).

    ``hinge_w`` (nu,): per-hinge weights of the pose term (they sum to 1)."""
    rot = np.zeros(3)
    mujoco.mju_subQuat(rot, ref.quat, sim.quat)
    c = w.pose * float(hinge_w @ (sim.hinges - ref.hinges) ** 2)
    c += w.root_rot * float(rot @ rot)
    c += w.height * (sim.z - ref.z) ** 2
    c += w.root_xy * float(np.sum((sim.xy - ref.xy) ** 2))
    c += w.sink * max(0.0, ref.z - w.sink_margin - sim.z)
    c += w.end_effectors * float(np.mean(np.sum((sim.ee - ref.ee) ** 2, axis=1)))
    c += w.balance * float(np.sum((sim.balance - ref.balance) ** 2))
    dv = sim.vel - ref.vel
    dv[:2] -= drift_lead(ref.xy, sim.xy, w.drift_rate, w.drift_max)  # zeros where it is off
    c += w.root_vel * float(np.sum(dv**2))
    if ref.z > 0.5 and sim.z < 0.5 * ref.z:
        c += w.fallen
    return c


def sample_track(
    model,
    ref_qpos: np.ndarray,
    *,
    record_every: int = 4,
    pushes: tuple[Push, ...] = (),
    weakenings: tuple[Weakening, ...] = (),
    recorder=None,
    **search,
) -> Tracking:
    """Track ``ref_qpos`` (T, nq at ``CONTROL_HZ``) without assistance, the hinge targets
    corrected by sampling (see the module docstring): :func:`search_offsets` (``search``: its
    keyword arguments), then their replay.

    Returns:
        ``track(model, ref_qpos, assist_limit=0, offsets=best, record_every=record_every,
        pushes=pushes, weakenings=weakenings, recorder=recorder, balance=...)``: the replay of
        the cheapest offsets (T, nu) with the search's balance feedback (default
        :data:`BALANCE`).
    """
    offsets, _ = search_offsets(model, ref_qpos, pushes=pushes, weakenings=weakenings, **search)
    return track(
        model, ref_qpos, assist_limit=0.0, record_every=record_every, offsets=offsets,
        pushes=pushes, weakenings=weakenings, recorder=recorder,
        balance=search.get("balance", BALANCE),
    )  # fmt: skip


@dataclass(frozen=True)
class _Problem:
    """What the search needs of the reference and the body: the uncorrected hinge targets
    ``base`` (T, nu) [rad] (reference angle, velocity lead and feed-forward, as ``track``), the
    reference's velocities (T, nv), the noise ``sigma`` (nu,) [rad] of each hinge's offset (0
    for the uncorrected), the pose term's hinge weights (nu,), the reference's
    :class:`Features` per tick, the cost's body ids and the pushes' body ids."""

    base: np.ndarray
    ref_qvel: np.ndarray
    sigma: np.ndarray
    hinge_w: np.ndarray
    ref_feat: list
    ee_ids: np.ndarray
    foot_ids: np.ndarray
    push_ids: list
    fall_ref: object | None
    kp: np.ndarray | None = None
    balance: object | None = None
    soles: slice | None = None  # the sole geoms' rows where a sole term is costed
    ref_soles: tuple | None = None  # footholding.reference_soles, capture=True
    lqr: object | None = None  # sampling_lqr.WindowLQR: its gain's feedback in every rollout


def _problem(
    model,
    ref_qpos,
    data,
    torque_sigma: float,
    pushes: tuple[Push, ...],
    falls: bool = True,
    balance: Balance | None = None,
    hold: bool = False,
    noise_deflection: float = 0.0,
) -> _Problem:
    """:class:`_Problem` of ``ref_qpos`` (T, nq); ``data`` is overwritten. ``falls``: the
    rollouts look for falls (``fall_ref`` set) or not (None); ``hold``: they record the soles
    for the foot-holding and footprint costs (where the body has soles)."""
    nu = model.nu
    ref_qvel, ref_force = reference_feedforward(model, ref_qpos, data)
    kp = model.actuator_gainprm[:, 0].copy()
    lead = model.actuator_biasprm[:, 2] / model.actuator_biasprm[:, 1]
    base = ref_qpos[:, 7:] + lead * ref_qvel[:, 6:] + ref_force[:, 6:] / kp  # (T, nu) targets
    names = [model.actuator(a).name for a in range(nu)]
    corrected = np.array([hinge_bone(n) in CORRECTED for n in names])
    lim = model.actuator_forcerange[:, 1]
    stiff = np.minimum(kp, lim / noise_deflection) if noise_deflection else kp
    sigma = np.where(corrected, torque_sigma * lim / stiff, 0.0)
    sub = model.body_subtreemass[model.jnt_bodyid[model.actuator_trnid[:, 0]]]
    ee_ids = np.array([model.body(n).id for n in END_EFFECTORS])
    foot_ids = np.array([model.body(n).id for n in ("lfoot", "rfoot")])
    ref_feat = []
    for k in range(ref_qpos.shape[0]):
        data.qpos[:], data.qvel[:] = ref_qpos[k], ref_qvel[k]
        ref_feat.append(features(model, data, ee_ids, foot_ids))
    ids = sole_ids(model) if hold else None
    return _Problem(
        base=base,
        ref_qvel=ref_qvel,
        sigma=sigma,
        hinge_w=sub / sub.sum(),  # a hinge that moves more mass weighs more
        ref_feat=ref_feat,
        ee_ids=ee_ids,
        foot_ids=foot_ids,
        push_ids=[model.body(p.body).id for p in pushes],
        fall_ref=fall_reference(model, ref_qpos) if falls else None,
        kp=kp,
        balance=None if balance is None else balance_plan(model, ref_qpos, ref_qvel, balance),
        soles=None if ids is None else as_slice(ids),
        ref_soles=None if ids is None else reference_soles(model, ref_qpos, ids, capture=True),
    )


def _rollout(model, data, prob: _Problem, off, ticks: tuple[int, int, int], perturb, keep) -> int:
    """Roll ``data`` (set to the parent's state) on with hinge offset ``off`` (nu,) [rad] from
    tick ``k0`` through the window's end ``k1`` and on to ``k2`` (``ticks``), meeting the
    ``perturb`` = (pushes, weakenings); at the window's end its state and ``qpos`` go into
    ``keep`` = (state row, qpos row, state spec, soles), ``soles`` None or the sole boxes'
    positions (R, 2, 3), orientations (R, 2, 9) and the centre of mass (R, 3) at the window's
    start, then after each of its first R - 1 ticks (R - 1 >= k1 - k0; ``prob.soles``; as the
    tick's last substep computed them; rows after a stop left as they were). A rollout that falls (``sim.simulate.falls``, checked after every tick where
    ``prob.fall_ref`` is set) stops at the fall or at the window's end, whichever is later.

    Returns:
        the tick ``data`` is left at, negated where the body fell (``-k``, k >= 1) or the
        simulation diverged (:func:`~sim.simulate.tracking.divergences`; stopped there).
    """
    k0, k1, k2 = ticks
    clear_divergences(data)
    pushes, weakenings = perturb
    state, qpos, spec, soles = keep
    T = len(prob.base)
    fell = False
    fb = np.zeros(model.nu)
    if soles is not None:  # the window's start (kinematics only: the step recomputes them)
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        soles[0][0], soles[1][0] = data.geom_xpos[prob.soles], data.geom_xmat[prob.soles]
        soles[2][0] = data.subtree_com[1]
    for k in range(k0, k2):  # the window, then on with the same offset
        t = k / CONTROL_HZ
        if pushes:  # else no external force: the kept states carry none
            apply_pushes(data, pushes, prob.push_ids, t)
        target = prob.base[k] + off
        if prob.lqr is not None:  # as track's feedback: this window's gain, the same state
            target += prob.lqr.feedback(model, data, k, k0)
        if prob.balance is not None:  # as track's: the same state, the same torques
            target += held_torques(model, data, prob.balance, k, fb) / prob.kp
        set_controls(model, data, target, weakening_factor(weakenings, t))
        mujoco.mj_step(model, data, nstep=SUBSTEPS)
        if divergences(data):  # MuJoCo reset the state: no motion goes on from it
            return -(k + 1)
        if soles is not None and k - k0 + 1 < len(soles[0]):
            i = k - k0 + 1
            soles[0][i], soles[1][i] = data.geom_xpos[prob.soles], data.geom_xmat[prob.soles]
            soles[2][i] = data.subtree_com[1]
        if k == k1 - 1:  # the window's end: the state kept
            mujoco.mj_getState(model, data, state, spec)
            qpos[:] = data.qpos
        if prob.fall_ref is not None and not fell:
            fell = has_fallen(model, data, prob.fall_ref, min(k + 1, T - 1))
        if fell and k >= k1 - 1:
            return -(k + 1)
    return k2


def _candidate_costs(model, datas, prob, search, parents, offs, ticks, out, pool) -> np.ndarray:
    """(S,) each candidate's cost, its parent's cost not included: candidate ``s`` rolled out
    (:func:`_rollout`) from kept state ``parents[s]`` with offset ``offs[s]`` (nu,), judged by
    :func:`window_cost` where it stopped plus ``CostWeights.fall`` (more the earlier) if it
    fell. ``search`` = (kept states, weights, perturbations, state spec); ``out`` = (window-end
    states (S, size), qpos (S, nq)), written. The candidates are split in contiguous runs over
    ``datas`` (one ``MjData`` per thread of ``pool``; ``pool`` None: one run): every rollout
    starts from a full state, so the result does not depend on the split. A rollout that
    diverged costs :data:`DIVERGED_COST`."""
    states, weights, perturb, spec = search
    k0, k1, k2 = ticks
    T = len(prob.base)
    S = len(offs)
    cost = np.empty(S)
    hold = prob.soles is not None and sole_terms(weights)
    K = (k2 if weights.footprint_lookahead else k1) - k0 + 1  # the start and each tick
    soles = tuple(np.full((S, K, *n), np.nan) for n in ((2, 3), (2, 9), (3,))) if hold else None

    def run(chunk: np.ndarray, data) -> None:
        for s in chunk:
            mujoco.mj_setState(model, data, states[parents[s]], spec)
            rec = (soles[0][s], soles[1][s], soles[2][s]) if hold else None
            keep_at = (out[0][s], out[1][s], spec, rec)
            end = _rollout(model, data, prob, offs[s], ticks, perturb, keep_at)
            if divergences(data):  # never kept: its window-end state is a reset
                cost[s] = DIVERGED_COST
                continue
            f = features(model, data, prob.ee_ids, prob.foot_ids)
            cost[s] = window_cost(f, prob.ref_feat[min(abs(end), T - 1)], weights, prob.hinge_w)
            if end < 0:  # fell: a later fall costs less
                cost[s] += weights.fall * (1.0 + (k2 + end) / max(1, k2 - k0))

    chunks = np.array_split(np.arange(len(offs)), len(datas))
    if pool is None:
        run(chunks[0], datas[0])
    else:
        list(pool.map(run, chunks, datas))
    if hold:  # rows a rollout did not reach are NaN: they count nothing
        cost += np.nan_to_num(sole_costs(model, prob, weights, ticks, soles), nan=0.0)
    return cost


def _proposals(rng, last: np.ndarray, parents: np.ndarray, sigma: np.ndarray, how) -> np.ndarray:
    """(S, nu) the candidates' offsets [rad]: from each parent's last offset (``last`` (K, nu),
    the cheapest kept state first; ``parents`` (S,)), moved by ``recentre`` towards the
    cheapest's, shrunk by ``persistence``, plus noise of ``sigma`` (nu,); the first ``elite``
    go on with their parent's offset unchanged. ``how`` = (persistence, recentre, elite)."""
    persistence, recentre, elite = how
    centre = (1.0 - recentre) * last[parents] + recentre * last[0]
    offs = persistence * centre + sigma * rng.standard_normal((len(parents), last.shape[1]))
    n_elite = min(int(elite), len(last), len(parents))
    offs[:n_elite] = last[parents[:n_elite]]
    return offs


def search_offsets(
    model,
    ref_qpos: np.ndarray,
    *,
    samples: int = 64,
    keep: int = 8,
    window: int = 12,
    torque_sigma: float = 0.3,
    persistence: float = 0.8,
    lookahead: int = LOOKAHEAD,
    seed: int = 0,
    weights: CostWeights | None = None,
    pushes: tuple[Push, ...] = (),
    weakenings: tuple[Weakening, ...] = (),
    threads: int = 1,
    recentre: float = 0.0,
    balance: Balance | None = BALANCE,
    elite: int = 0,
    noise_deflection: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The cheapest hinge-target corrections for tracking ``ref_qpos`` (T, nq at
    ``CONTROL_HZ``) without assistance, found by sampling rollouts (the module docstring).

    Args:
        samples: rollouts per window (in all, over the kept states); keep: states kept after each.
        window: control ticks per window (12: 0.1 s).
        torque_sigma: noise of an offset, as a share of its joint's peak torque.
        noise_deflection: [rad] > 0: that share over the stiffness capped at peak torque / it.
        persistence: share of the parent's offset a child starts from.
        lookahead: control ticks each candidate is rolled on past its window (same offset)
            before its cost is taken: a correction that only delays a fall costs what the fall
            costs. The state kept is the one at the window's end.
        seed: seeds the noise (same seed, same result).
        pushes, weakenings: perturbations, as in ``track``; every candidate rollout meets them
            too, so the corrections are found against the perturbed body.
        recentre: share (0..1) by which a child's starting offset moves from its parent's
            towards the cheapest kept state's (0: its parent's alone).
        threads: rollouts run on this many threads (MuJoCo releases the GIL while it steps);
            the result is the same for any number.
        balance: the balance feedback (``sim.simulate.balance``) every rollout adds to its
            targets (and ``sample_track``'s replay); None: none.
        elite: candidates (one per kept state, the cheapest first) that go on with their
            parent's last offset as its lookahead was judged (no shrinking, no noise).

    Returns:
        ``offsets`` (T, nu) [rad], and ``window_qpos`` (W, nq): on the chosen path, the rolled
        out ``qpos`` at the end of each window (tick ``min(T, (w + 1) window)``): what
        ``track(..., offsets=offsets)`` reaches there while the body is up.
    """
    weights = weights or CostWeights()
    T, nu = ref_qpos.shape[0], model.nu
    rng = np.random.default_rng(seed)
    datas = [mujoco.MjData(model) for _ in range(max(1, min(int(threads), samples)))]
    check_window(window, balance)
    prob = _problem(
        model, ref_qpos, datas[0], torque_sigma, pushes, falls=weights.fall > 0, balance=balance,
        hold=sole_terms(weights), noise_deflection=noise_deflection,
    )  # fmt: skip
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    states = first_state(model, datas[0], ref_qpos[0], prob.ref_qvel[0], spec)
    costs = np.zeros(1)
    last = np.zeros((1, nu))  # each kept state's offset in its last window
    history: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    out = np.empty((samples, states.shape[1])), np.empty((samples, model.nq))
    pool = ThreadPoolExecutor(len(datas)) if len(datas) > 1 else None
    try:
        for k0 in range(0, T, window):
            ticks = k0, min(T, k0 + window), min(T, k0 + window + lookahead)
            parents = np.arange(samples) % len(states)
            offs = _proposals(rng, last, parents, prob.sigma, (persistence, recentre, elite))
            search = states, weights, (pushes, weakenings), spec
            cost = _candidate_costs(model, datas, prob, search, parents, offs, ticks, out, pool)
            new_costs = costs[parents] + cost
            best = np.argsort(new_costs, kind="stable")[:keep]
            history.append((parents[best], offs[best], out[1][best].copy()))
            states, costs, last = out[0][best].copy(), new_costs[best], offs[best]
    finally:
        if pool is not None:
            pool.shutdown()
    return backtrack(history, T, window, nu, model.nq)
