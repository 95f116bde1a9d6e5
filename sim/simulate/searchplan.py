"""How the gain-choosing sampler (``sim.simulate.gainchoice.choice_search``) spends its
rollouts: where a window gets more or fewer candidates, when it backs up, and what its cost also
looks at.

Five options, each off by default (:class:`SearchPlan`), measured in docs/synthetic.md
("Spending the samples"):

* **Recovery** (SAMCON, Liu et al. 2010): where every candidate of a window falls, the search
  backs up ``recover`` windows and searches them again, and the failing window, with ``boost``
  times the samples; at most once per window, and only while the rollouts of the whole clip stay
  within ``1 + extra`` times the nominal ``samples`` per window (:func:`may_recover`).
* **Staged windows**: ``first`` (0..1) of a window's candidates are rolled out first; the rest
  only where one of those fell (an easy window ends there, a hard one gets them all).
* **The window-end cost**: besides the lookahead's end, a candidate's state at its window's end
  (the one kept and replayed) pays ``end_cost`` times its tracking cost
  (``sampling.window_cost``) there (:func:`window_end_costs`).
* **Proposal adaptation**: each hinge's noise widens or narrows with the spread of the kept
  candidates' draws (``adapt``, :func:`adapted_scale`).
* **Narrow candidates**: ``narrow_share`` of each stage's candidates, chosen at random, or
  (``narrow_first``) all of a window's first stage, draw their noise times ``narrow``
  (:func:`narrowed`): fine corrections of the posture, with wide ones to catch a fall
  ("Narrow candidates": a narrowed first stage tracks better but falls more).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from sim.errors import UsageError
from sim.simulate.sampling import DIVERGED_COST, features, window_cost


@dataclass(frozen=True)
class SearchPlan:
    """Where the sampler spends its rollouts (module docstring); the defaults change nothing.

    recover: windows backed up where every candidate of a window falls (0: never).
    boost: sample multiple of the windows searched again.
    extra: [share of ``samples`` x windows] rollouts the recoveries may add to a clip.
    first: share (0..1] of each window's candidates rolled out before looking at falls; 1: all.
    end_cost: weight of each candidate's tracking cost at its window's end (0: off).
    adapt: rate (0..1) at which each hinge's noise scale follows its kept candidates' spread
        (:func:`adapted_scale`; 0: the fixed Gaussian).
    narrow: factor (> 0) of the noise of the narrow candidates (:func:`narrowed`).
    narrow_share: share (0..1) of each stage's candidates drawn narrow (0: none).
    narrow_first: every candidate of a window's first stage narrow and the rest (``first``:
        rolled out only where one of those fell) and the fallback's at full noise; it replaces
        ``narrow_share``.
    """

    recover: int = 0
    boost: float = 2.0
    extra: float = 0.25
    first: float = 1.0
    end_cost: float = 0.0
    adapt: float = 0.0
    narrow: float = 1.0
    narrow_share: float = 0.0
    narrow_first: bool = False

    def __post_init__(self):
        if self.recover < 0 or self.boost < 1.0 or self.extra < 0.0 or self.end_cost < 0.0:
            raise UsageError(
                "SearchPlan needs recover >= 0, boost >= 1, extra >= 0 and end_cost >= 0; got "
                f"{self.recover}, {self.boost}, {self.extra}, {self.end_cost}"
            )
        if not 0.0 <= self.adapt <= 1.0:
            raise UsageError(f"SearchPlan.adapt must be within 0..1; got {self.adapt}")
        if not 0.0 < self.first <= 1.0:
            raise UsageError(f"SearchPlan.first must be within (0, 1]; got {self.first}")
        if not (self.narrow > 0.0 and 0.0 <= self.narrow_share <= 1.0):
            raise UsageError(
                "SearchPlan needs narrow > 0 and narrow_share within 0..1; got "
                f"{self.narrow}, {self.narrow_share}"
            )


def narrowed(plan: SearchPlan, rng, n: int, first: bool = True) -> np.ndarray | None:
    """(n, 1) the noise factor of each of ``n`` candidates of a stage (``first``: a window's
    first): ``plan.narrow`` for all of a first stage's with ``plan.narrow_first`` (none of a
    later one's), else for ``round(plan.narrow_share * n)`` of them chosen at random by
    ``rng``, 1 for the rest; None where none is narrow (``rng`` not drawn from). A small search
    noise tracks the posture better but catches fewer falls (docs/synthetic.md, "What the
    root-relative error is made of"): the wide candidates keep the reach."""
    if plan.narrow == 1.0:
        return None
    if plan.narrow_first:
        return np.full((n, 1), plan.narrow) if first else None
    k = int(round(plan.narrow_share * n))
    if k == 0:
        return None
    return np.where(rng.permutation(n) < k, plan.narrow, 1.0)[:, None]


def stage_sizes(samples: int, first: float) -> tuple[int, int]:
    """(n1, n2): a window's candidates rolled out first and those rolled out only where one of
    the first fell; ``n1 + n2 == samples``, ``n1 >= 1``."""
    n1 = max(1, min(samples, int(round(first * samples))))
    return n1, samples - n1


def may_recover(plan: SearchPlan, w: int, tried: set, spent: int, size: tuple[int, int]) -> int:
    """The window to back up to where every candidate of window ``w`` fell, or -1: no recovery
    (off, ``w`` recovered from before, or the budget would not hold it). ``size`` = (samples per
    window, windows in the clip); ``spent``: rollouts so far. The budget holds it where
    ``spent``, the recovery's rollouts (``boost`` x samples for windows ``back..w``) and the
    windows after ``w`` at ``samples`` each stay within ``(1 + extra)`` x samples x windows."""
    samples, n_windows = size
    if not plan.recover or w in tried:
        return -1
    back = max(0, w - plan.recover)
    need = (w - back + 1) * boosted(plan, samples) + (n_windows - w - 1) * samples
    return back if spent + need <= (1.0 + plan.extra) * samples * n_windows else -1


def boosted(plan: SearchPlan, samples: int) -> int:
    """Candidates of a window searched again: ``boost`` x ``samples``, rounded."""
    return int(round(plan.boost * samples))


#: bounds of :func:`adapted_scale` (a share of the fixed noise)
SCALE_RANGE = (0.25, 4.0)


def adapted_scale(scale: np.ndarray, elite_noise: np.ndarray, rate: float) -> np.ndarray:
    """(nu,) the next window's noise scale per hinge: ``scale`` (nu,) times ``exp(rate (v - 1)
    / 2)``, ``v`` the mean square over the kept candidates of their standard normal draws
    ``elite_noise`` (K, nu): selection that favoured larger steps along a hinge (``v`` > 1)
    widens its noise, smaller ones narrow it (the diagonal of CMA-ES's rank-mu update, as Liu
    et al. 2015 adapt SAMCON's proposal), within :data:`SCALE_RANGE`. ``rate`` 0: ``scale``."""
    if not rate:
        return scale
    v = np.mean(elite_noise**2, axis=0)
    return np.clip(scale * np.exp(0.5 * rate * (v - 1.0)), *SCALE_RANGE)


def window_end_costs(model, data, prob, states, spec, k1: int, weights, cost) -> np.ndarray:
    """(S,) each candidate's tracking cost (``sampling.window_cost``) at its window's end, tick
    ``k1``: ``states`` (S, size) the window-end states (``spec``), set into ``data`` in turn;
    0 for a diverged candidate (``cost`` (S,) at ``DIVERGED_COST``: never kept anyway)."""
    ref = prob.ref_feat[min(k1, len(prob.base) - 1)]
    out = np.zeros(len(states))
    for s in range(len(states)):
        if cost[s] >= DIVERGED_COST:
            continue
        mujoco.mj_setState(model, data, states[s], spec)
        out[s] = window_cost(features(model, data, prob.ee_ids, prob.foot_ids), ref, weights,
                             prob.hinge_w)  # fmt: skip
    return out
