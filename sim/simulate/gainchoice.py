"""The sampler choosing, window by window, between feedback gains: a stiff controller where it
tracks, the default one where the stiff one falls.

A stiffer controller (``sim.simulate.model.Gains``: a smaller ``min_deflection``, a higher
bandwidth) tracks the pose better wherever the body stays up, but has less give where the
search's offsets are wrong and falls more (docs/synthetic.md, "The controllers, measured").
Feedback gains are the controller's, not the body's: the same body (masses, armature, human
torque limits) may be driven with either set from one 0.1 s window to the next. Here each
window's candidates (:mod:`sim.simulate.sampling`'s rollouts) are rolled out with one of several
gain sets, ``models`` (the same body compiled with each set's actuators; :func:`common_body`),
the first the fallback (the default gains):

* ``GainChoice.share`` of the ``samples`` candidates use ``models[1]``, the rest ``models[0]``;
  the cost (falls included) picks among all of them, and a kept state goes on from the gains
  it was reached with;
* ``GainChoice.fallback``: where every candidate of a window falls (the cheapest pays
  ``CostWeights.fall``), ``samples`` more are rolled out with ``models[0]`` from the same
  parents and the kept states are chosen from both.

A parent's offset [rad] carries over to a child on other gains as the same torque (times the
parent's ``kp`` over the child's). The chosen offsets and gains are replayed by
``sim.simulate.controller.track(..., switch=(models, choice))``: one ordinary simulation.
How the rollouts are spent (recovery, staged windows, the window-end cost, proposal adaptation)
is ``plan``'s (``sim.simulate.searchplan``; its defaults change nothing). Deterministic given
``seed``; with ``share`` 0, no fallback and the default plan it is ``sampling.search_offsets``
bit for bit.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import mujoco
import numpy as np

from sim.errors import UsageError
from sim.simulate.balance import Balance
from sim.simulate.controller import Push, Tracking, Weakening, track
from sim.simulate.footprints import sole_terms
from sim.simulate.noisescale import NoiseScale, scaled_sigma
from sim.simulate.sampling import (
    BALANCE,
    LOOKAHEAD,
    CostWeights,
    _candidate_costs,
    _problem,
)
from sim.simulate.sampling_lqr import WindowLQR
from sim.simulate.searchplan import (
    SearchPlan,
    adapted_scale,
    boosted,
    may_recover,
    narrowed,
    stage_sizes,
    window_end_costs,
)
from sim.simulate.searchsteps import backtrack, check_window, first_state


@dataclass(frozen=True)
class GainChoice:
    """How a window's candidates are spread over the gain sets (module docstring):
    ``share`` (0..1) of them on ``models[1]``; ``fallback``: a window whose candidates all fall
    is tried again with ``models[0]``."""

    share: float = 0.5
    fallback: bool = False

    def __post_init__(self):
        if not 0.0 <= self.share <= 1.0:
            raise UsageError(f"GainChoice.share must be within 0..1; got {self.share}")


def common_body(models) -> tuple:
    """``models`` (the same skeleton compiled with different ``Gains``) made one body: each
    hinge's armature the largest of theirs (``sim_spec`` raises it with ``kp`` for
    stability), set in place, and the constants compiled from it (``mj_setConst``: the
    constraint solver's ``dof_invweight0``) recomputed. Refuses models that differ in anything but the actuators'
    gains and control ranges: sizes, masses or torque limits (the limits are anatomy)."""
    first = models[0]
    for m in models[1:]:
        same = (m.nq, m.nv, m.nu, m.ngeom, m.nbody) == (
            first.nq, first.nv, first.nu, first.ngeom, first.nbody
        )  # fmt: skip
        if not same or not (
            np.array_equal(m.actuator_forcerange, first.actuator_forcerange)
            and np.array_equal(m.body_mass, first.body_mass)
        ):
            raise UsageError("gain sets must share one body: sizes, masses and torque limits")
    armature = np.max([m.dof_armature for m in models], axis=0)
    for m in models:
        m.dof_armature[:] = armature
        mujoco.mj_setConst(m, mujoco.MjData(m))  # the constants that follow from it (invweight0)
    return tuple(models)


def _offsets(rng, last, last_set, parents, cand_set, probs, persistence, scale=None) -> tuple:
    """(S, nu) the candidates' offsets [rad]: each parent's last offset (``last`` (K, nu), on
    gains ``last_set`` (K,)) as the same torque on the candidate's gains ``cand_set`` (S,),
    shrunk by ``persistence``, plus that set's noise (``probs[j].sigma``) times ``scale`` (nu,
    or per candidate (S, nu); None: 1); and the standard normal draws (S, nu) of that noise."""
    noise = rng.standard_normal((len(parents), last.shape[1]))
    start = last[parents]
    moved = last_set[parents] != cand_set
    if moved.any():  # the same torque on the new gains
        kp = np.array([p.kp for p in probs])
        start[moved] *= kp[last_set[parents][moved]] / kp[cand_set[moved]]
    sigma = np.array([p.sigma for p in probs])[cand_set]
    if scale is not None:
        sigma = sigma * scale
    return persistence * start + sigma * noise, noise


def _costs(models, datas, probs, search, parents, offs, cand_set, ticks, out, pool):
    """(S,) each candidate's cost (``sampling._candidate_costs``), the candidates of each gain
    set rolled out on its model; ``cand_set`` (S,) is sorted so each set's rows are one block
    (``out``'s rows are written in place)."""
    cost = np.empty(len(offs))
    for j in np.unique(cand_set):
        a, b = np.searchsorted(cand_set, [j, j + 1])
        rows = (out[0][a:b], out[1][a:b])
        cost[a:b] = _candidate_costs(
            models[j], datas[j], probs[j], search, parents[a:b], offs[a:b], ticks, rows, pool
        )
    return cost


@dataclass(frozen=True)
class _Search:
    """What every window of :func:`choice_search` shares: the gain sets' models, their
    ``MjData`` per thread and problems, the cost's weights, the state spec, the proposal's
    persistence, the choice, the plan, the thread pool, the state's size and the perturbations
    (pushes, weakenings) every rollout meets."""

    models: tuple
    datas: list
    probs: list
    weights: CostWeights
    spec: object
    persistence: float
    choice: GainChoice
    plan: SearchPlan
    pool: object
    size: int
    perturb: tuple = ((), ())


def _stage(ctx: _Search, rng, idx: np.ndarray, kept, ticks, sets=None, first=True) -> tuple:
    """Candidates ``idx`` (n,) of a window rolled out from the kept states ``kept`` = (states,
    last offsets, last gain sets): their parents (``idx`` modulo the kept), gain sets (``sets``,
    else ``choice.share`` of them on ``models[1]``, last), offsets, costs and window-end
    (states, ``qpos``). ``first``: the window's first stage (``searchplan.narrowed``)."""
    states, last, last_set, scale = kept
    parents = idx % len(states)
    if sets is None:
        n_alt = int(round(ctx.choice.share * len(idx))) if len(ctx.models) > 1 else 0
        sets = np.r_[np.zeros(len(idx) - n_alt, int), np.ones(n_alt, int)]
    factor = narrowed(ctx.plan, rng, len(idx), first)  # (n, 1) or None: some drawn narrow
    scale = scale if factor is None else scale * factor
    offs, noise = _offsets(rng, last, last_set, parents, sets, ctx.probs, ctx.persistence, scale)
    out = np.empty((len(idx), ctx.size)), np.empty((len(idx), ctx.models[0].nq))
    search = states, ctx.weights, ctx.perturb, ctx.spec
    cost = _costs(ctx.models, ctx.datas, ctx.probs, search, parents, offs, sets, ticks, out,
                  ctx.pool)  # fmt: skip
    return parents, offs, sets, cost, out, noise


def _join(parts: list) -> tuple:
    """The stages' (parents, offsets, sets, costs, (states, qpos), noise) as one window's."""
    if len(parts) == 1:
        return parts[0]
    cat = [np.concatenate([p[i] for p in parts]) for i in range(4)]
    out = tuple(np.concatenate([p[4][i] for p in parts]) for i in range(2))
    return (*cat, out, np.concatenate([p[5] for p in parts]))


def _window(ctx: _Search, rng, n: int, kept, ticks) -> tuple:
    """One window's ``n`` candidates from ``kept`` (:func:`_stage`), staged as ``plan.first``
    says, with the fallback on the default gains (``choice.fallback``) and the window-end cost
    (``plan.end_cost``) added: (parents, offsets, sets, costs, (states, qpos)), and whether
    every candidate fell."""
    fall = ctx.weights.fall
    n1, n2 = stage_sizes(n, ctx.plan.first)
    parts = [_stage(ctx, rng, np.arange(n1), kept, ticks)]
    if n2 and fall > 0 and parts[0][3].max() >= fall:  # one fell: a hard window, all of them
        parts.append(_stage(ctx, rng, np.arange(n1, n), kept, ticks, first=False))
    cand = _join(parts)
    fell = fall > 0 and cand[3].min() >= fall
    if fell and ctx.choice.fallback and cand[2].any():  # the default gains too
        n = len(cand[3])
        cand = _join([cand, _stage(ctx, rng, np.arange(n), kept, ticks, np.zeros(n, int), False)])
    parents, offs, sets, cost, out, noise = cand
    if ctx.plan.end_cost:
        prob = ctx.probs[0]  # the kinematics and the reference are every gain set's
        end = window_end_costs(ctx.models[0], ctx.datas[0][0], prob, out[0], ctx.spec,
                               ticks[1], ctx.weights, cost)  # fmt: skip
        cost = cost + ctx.plan.end_cost * end
    return (parents, offs, sets, cost, out, noise), fell


def _select(kept, costs: np.ndarray, cand: tuple, keep: int, adapt: float) -> tuple:
    """The ``keep`` cheapest of a window's candidates ``cand`` = (parents, offsets, sets,
    costs, (states, qpos), noise), each paying its parent's cost ``costs`` too: the next
    ``kept`` (states, offsets, sets, the noise's scale adapted at ``adapt``), their costs, and
    the window's steps of the offsets' and the sets' histories (for ``searchsteps.backtrack``)."""
    parents, offs, sets, cost, out, noise = cand
    new_costs = costs[parents] + cost
    best = np.argsort(new_costs, kind="stable")[:keep]
    chosen_sets = sets[best][:, None].astype(float)  # backtracked as a 1-wide offset
    steps = (
        (parents[best], offs[best], out[1][best].copy()),
        (parents[best], chosen_sets, np.zeros((len(best), 1))),
    )
    scale = adapted_scale(kept[3], noise[best], adapt)
    return (out[0][best].copy(), offs[best], sets[best], scale), new_costs[best], steps


def _problems(models, datas, ref_qpos, how: tuple, lqr, window: int) -> list:
    """Each gain set's ``sampling._problem`` (``how`` = torque_sigma, pushes, falls, balance,
    noise_deflection, soles: the rollouts record the soles for their cost terms, noise_scale:
    ``sim.simulate.noisescale.NoiseScale`` or None), carrying ``lqr`` (bound to the reference
    here; None: none)."""
    sigma, pushes, falls, balance, deflection, soles, noise = how
    probs = [
        _problem(m, ref_qpos, d[0], sigma, pushes, falls=falls, balance=balance, hold=soles,
                 noise_deflection=deflection)
        for m, d in zip(models, datas, strict=True)
    ]  # fmt: skip
    if noise is not None:  # the noise of some bones' hinges scaled
        pairs = zip(models, probs, strict=True)
        probs = [replace(p, sigma=scaled_sigma(m, p.sigma, noise)) for m, p in pairs]
    if lqr is None:
        return probs
    lqr.start(ref_qpos, probs[0].ref_qvel, window)
    return [replace(p, lqr=lqr) for p in probs]


def _window_gain(ctx: _Search, lqr, kept, k0: int) -> None:
    """``lqr``'s gain for the window from tick ``k0``, in the main thread before its rollouts:
    linearised at the cheapest kept state on the gains it was reached with, the reference's
    target the operating control."""
    j = kept[2][0]
    lqr.set_window(k0, ctx.models[j], ctx.datas[j][0], kept[0][0], ctx.spec, ctx.probs[j].base[k0])


def choice_search(
    models,
    ref_qpos: np.ndarray,
    *,
    choice: GainChoice = GainChoice(),
    plan: SearchPlan | None = None,
    samples: int = 64,
    keep: int = 8,
    window: int = 12,
    torque_sigma: float = 0.3,
    persistence: float = 0.8,
    lookahead: int = LOOKAHEAD,
    seed: int = 0,
    weights: CostWeights | None = None,
    threads: int = 1,
    balance: Balance | None = BALANCE,
    noise_deflection: float = 0.0,
    pushes: tuple[Push, ...] = (),
    weakenings: tuple[Weakening, ...] = (),
    lqr=None, noise_scale: NoiseScale | None = None,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The cheapest hinge-target corrections and gain sets for tracking ``ref_qpos`` (T, nq at
    ``CONTROL_HZ``) on ``models`` (:func:`common_body`; ``models[0]`` the fallback), found by
    sampling rollouts as ``sampling.search_offsets`` (the same arguments, the perturbations
    ``pushes`` and ``weakenings`` met by every rollout) with each window's candidates spread
    over the gain sets by ``choice`` (module docstring), the rollouts spent as ``plan`` says.
    ``lqr``: a ``sampling_lqr.WindowLQR``, its gain per window in every rollout; ``noise_scale``:
    some bones' offset noise scaled (``sim.simulate.noisescale``); None: none (either).

    Returns:
        ``offsets`` (T, nu) [rad], ``sets`` (T,) the gain set of each tick (ints), and
        ``window_qpos`` (W, nq): on the chosen path, the rolled out ``qpos`` at each window's
        end (what the replay reaches there while the body is up).
    """
    weights, plan = weights or CostWeights(), plan or SearchPlan()
    T, nu, rng = ref_qpos.shape[0], models[0].nu, np.random.default_rng(seed)
    n_threads = max(1, min(int(threads), samples))
    datas = [[mujoco.MjData(m) for _ in range(n_threads)] for m in models]
    check_window(window, balance)
    how = torque_sigma, pushes, weights.fall > 0, balance, noise_deflection, sole_terms(weights)
    probs = _problems(models, datas, ref_qpos, (*how, noise_scale), lqr, window)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    states = first_state(models[0], datas[0][0], ref_qpos[0], probs[0].ref_qvel[0], spec)
    # the kept states, their last offsets and gain sets, and the noise's scale (nu,)
    kept = states, np.zeros((1, nu)), np.zeros(1, dtype=int), np.ones(nu)
    costs = np.zeros(1)
    n_windows = -(-T // window)
    pool = ThreadPoolExecutor(n_threads) if n_threads > 1 else None
    ctx = _Search(tuple(models), datas, probs, weights, spec, persistence, choice, plan, pool,
                  states.shape[1], (pushes, weakenings))  # fmt: skip
    history, set_history, snaps = [], [], []
    tried, boost_to, spent, w = set(), -1, 0, 0
    try:
        while w < n_windows:
            k0 = w * window
            ticks = k0, min(T, k0 + window), min(T, k0 + window + lookahead)
            del snaps[w:]
            snaps.append((kept, costs))
            n = boosted(plan, samples) if w <= boost_to else samples
            if lqr is not None:  # one gain for the window, at its cheapest kept state
                _window_gain(ctx, lqr, kept, k0)
            (parents, offs, sets, cost, out, noise), fell = _window(ctx, rng, n, kept, ticks)
            spent += len(cost)
            back = may_recover(plan, w, tried, spent, (samples, n_windows)) if fell else -1
            if back >= 0:  # every candidate fell: back up and search again with more
                tried.add(w)
                boost_to, (kept, costs), w = w, snaps[back], back
                del history[back:], set_history[back:]
                continue
            kept, costs, steps = _select(kept, costs, (parents, offs, sets, cost, out, noise),
                                         keep, plan.adapt)  # fmt: skip
            history.append(steps[0])
            set_history.append(steps[1])
            w += 1
    finally:
        if pool is not None:
            pool.shutdown()
    offsets, window_qpos = backtrack(history, T, window, nu, models[0].nq)
    chosen, _ = backtrack(set_history, T, window, 1, 1)
    return offsets, chosen[:, 0].astype(int), window_qpos


def choice_track(
    model, ref_qpos: np.ndarray, *, alternates=(), record_every: int = 4, recorder=None,
    pushes: tuple[Push, ...] = (), weakenings: tuple[Weakening, ...] = (), **search,
) -> Tracking:  # fmt: skip
    """Track ``ref_qpos`` (T, nq at ``CONTROL_HZ``) without assistance on ``model`` and
    ``alternates`` (the same body with other gains: :func:`common_body`), the hinge targets
    corrected and the gains chosen per window by :func:`choice_search` (``search``: its
    keyword arguments; ``pushes``, ``weakenings`` met by the search and the replay), then
    replayed: ``track(model, ref_qpos, offsets=..., switch=((model, *alternates), sets),
    balance=..., recorder=recorder)``; ``search["lqr_feedback"]`` (a scale; None: off): the
    LQR's gain per window in the rollouts and the replay (``sim.simulate.sampling_lqr``)."""
    models = (model, *alternates)
    perturb = {"pushes": pushes, "weakenings": weakenings}
    scale = search.pop("lqr_feedback", None)
    lqr = None if scale is None else WindowLQR(scale)
    offsets, sets, _ = choice_search(models, ref_qpos, lqr=lqr, **perturb, **search)
    return track(
        model, ref_qpos, assist_limit=0.0, record_every=record_every, offsets=offsets,
        balance=search.get("balance", BALANCE), switch=(models, sets), recorder=recorder,
        feedback=None if lqr is None else lqr.feedback, **perturb,
    )  # fmt: skip
