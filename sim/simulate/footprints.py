"""Footprints: what a sampled rollout pays for putting a foot down away from the reference's.

The global tracking error is mostly the root's horizontal drift (docs/synthetic.md, "Root
drift"). A walk whose feet land where the reference's land cannot drift far, and the reference
the sampler tracks is contact-consistent (its stance soles are on the floor,
``sim.simulate.reference.contact_consistent``). This term anchors the footprints: over the
ticks of a window, each sole that touches the floor in the rollout (its lowest corner at most
``footholding.CONTACT_HEIGHT`` above the support under its centre, the floor or a terrain box)
while the reference stands on it (``footholding.reference_soles``' stance) pays the squared
horizontal distance between the two soles' bottom centres::

    footprint = sum_k sum_feet counted_k |sim_k - ref_k|^2 / K

[m^2] (K ticks). With ``landing`` only the ticks where a sole starts to count (counted at k,
not at k - 1: the foot put down, or the reference putting its own down under a foot already
there) pay, summed instead of averaged: the foot's placement, not where a stance foot already
down stays. Zero on the reference itself; a sole in the air or where the reference lifts its
foot pays nothing. The sampler looks at a window's ticks, or with ``footprint_lookahead`` at
its lookahead's too (where a candidate's constant offset puts the next foot down). Units:
metres, z up, floor at z = 0.
"""

from __future__ import annotations

import numpy as np

from sim.simulate.footholding import CONTACT_HEIGHT, sole_bottoms, sole_lowest, window_hold_costs
from sim.simulate.model import CONTROL_HZ
from sim.simulate.swingstance import window_swing_stance_costs
from sim.simulate.terrain import surface_height, terrain_geoms


def footprint_cost(
    sim_xy: np.ndarray,
    ref_xy: np.ndarray,
    stance: np.ndarray,
    touch: np.ndarray,
    landing: bool = False,
    before: np.ndarray | None = None,
) -> float | np.ndarray:
    """The footprint cost [m^2] (module docstring) of soles at ``sim_xy`` (..., K, 2, 2)
    against the reference's ``ref_xy`` (K, 2, 2) over K ticks, the reference standing on each
    sole where ``stance`` (K, 2) is True and the simulated sole touching its support where
    ``touch`` (..., K, 2) is True. ``landing``: only the ticks where a sole starts to count,
    summed; ``before`` (..., 2): whether each sole counted the tick before the first (None: it
    did not).

    Returns:
        a float for one motion (``sim_xy`` (K, 2, 2)), else one cost per leading index (...).
    """
    K = sim_xy.shape[-3]
    counted = touch & stance  # (..., K, 2)
    if landing:
        prev = np.zeros_like(counted[..., :1, :]) if before is None else before[..., None, :]
        counted = counted & ~np.concatenate([prev, counted[..., :-1, :]], axis=-2)
    d2 = np.sum((sim_xy - ref_xy) ** 2, axis=-1)  # (..., K, 2)
    cost = np.sum(np.where(counted, d2, 0.0), axis=(-2, -1)) / (1 if landing else max(K, 1))
    return float(cost) if sim_xy.ndim == 3 else cost


def window_footprint_costs(
    records: tuple, size: np.ndarray, ref: tuple, terrain, landing: bool
) -> np.ndarray:
    """(S,) :func:`footprint_cost` of S rollouts' windows.

    Args:
        records: the sole boxes' positions (S, K + 1, 2, 3) [m] and orientations (S, K + 1, 2,
            9): at the window's start, then after each of its K ticks (NaN after a rollout
            stopped: no sole touches there).
        size: (2, 3) the sole boxes' half sizes [m].
        ref: the reference at the same K + 1 instants (``footholding.reference_soles``): sole
            bottom centres (K + 1, 2, 2) [m] and stance (K + 1, 2).
        terrain: ``terrain.terrain_geoms`` of the model (None: the floor alone).
        landing: only the ticks where a sole starts to count (the first instant only says
            whether it counted before).
    """
    pos, mat = records[0], records[1]
    xy = sole_bottoms(pos, mat, size[:, 2])[..., :2]
    touch = sole_lowest(pos, mat, size) - surface_height(terrain, pos[..., :2]) <= CONTACT_HEIGHT
    before = touch[:, 0] & ref[1][0]
    return footprint_cost(xy[:, 1:], ref[0][1:], ref[1][1:], touch[:, 1:], landing, before)


def sole_terms(weights) -> bool:
    """Whether ``weights`` (``sampling.CostWeights``) has a sole term (:func:`sole_costs`):
    then the rollouts record the soles."""
    return weights.hold > 0 or weights.footprint > 0 or weights.clearance > 0 or weights.pivot > 0


def sole_costs(model, prob, weights, ticks: tuple, records: tuple) -> np.ndarray:
    """(S,) the sole terms of ``sim.simulate.sampling.window_cost``'s candidates, weighted:
    ``weights.hold`` times foot holding (``footholding.window_hold_costs``) plus
    ``weights.footprint`` times :func:`window_footprint_costs` plus ``weights.clearance`` and
    ``weights.pivot`` times swing clearance and stance pivot over the window's ticks
    (``swingstance.window_swing_stance_costs``), of the window ``ticks`` = (k0,
    k1, ...) from the rollouts' records (positions (S, R, 2, 3), orientations (S, R, 2, 9),
    centre of mass (S, R, 3): the window's start, then after each tick, R - 1 >= k1 - k0:
    foot holding looks at the window's ticks, footprints at all R; NaN where a rollout
    stopped: a sole there touches nothing), against the
    reference's soles ``prob.ref_soles`` (``footholding.reference_soles`` with ``capture``) a
    tick later (a tick's record is the state at its end, less its last substep)."""
    R = records[0].shape[1]  # the window's start and its ticks (and its lookahead's)
    at = np.minimum(np.arange(ticks[0], ticks[0] + R), len(prob.base) - 1)  # (R,)
    ref = tuple(r[at] for r in prob.ref_soles)
    size = model.geom_size[prob.soles]
    cost = np.zeros(len(records[0]))
    if weights.hold > 0:  # over the window's ticks
        release = weights.hold_capture, weights.hold_capture_ref
        K = ticks[1] - ticks[0]
        ticks_only = tuple(r[:, 1 : K + 1] for r in records)
        cost += weights.hold * window_hold_costs(
            ticks_only, size, tuple(r[1 : K + 1] for r in ref), 1.0 / CONTROL_HZ,
            weights.hold_contact, release,
        )  # fmt: skip
    swing_stance = weights.clearance > 0 or weights.pivot > 0
    # the boxes under the soles, where a term reads them (foot holding does not)
    terrain = terrain_geoms(model) if weights.footprint > 0 or swing_stance else None
    if weights.footprint > 0:
        cost += weights.footprint * window_footprint_costs(
            records, size, ref, terrain, weights.footprint_landing
        )
    if swing_stance:  # the window's start and ticks
        K = ticks[1] - ticks[0]
        cost += window_swing_stance_costs(
            tuple(r[:, : K + 1] for r in records[:2]), size, tuple(r[: K + 1] for r in ref),
            terrain, 1.0 / CONTROL_HZ, (weights.clearance, weights.pivot),
        )  # fmt: skip
    return cost
