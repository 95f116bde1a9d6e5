"""The controllers ``benchmarks/bench_simulate.py --controllers`` compares, by name: eval's
default (``mix0.5``: the gains chosen per window), its default before (``default28``: the
default gains only) and every candidate tried against them (docs/synthetic.md, "The
controllers, measured", says what each gave).

``CONTROLLERS[name]`` = (label, ``ForwardValidation`` keywords, actuators[, the body's
``sim_model`` keywords]).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sim.simulate.balance import Balance  # noqa: E402
from sim.simulate.friction import Friction  # noqa: E402
from sim.simulate.gainchoice import GainChoice  # noqa: E402
from sim.simulate.lqr import LQRWeights  # noqa: E402
from sim.simulate.model import MIN_DEFLECTION, PAD_SOLE, Gains, SoftSole  # noqa: E402
from sim.simulate.noisescale import NoiseScale  # noqa: E402
from sim.simulate.sampling import CostWeights, search_offsets  # noqa: E402
from sim.simulate.searchplan import SearchPlan  # noqa: E402
from sim.simulate.validate import DEFAULT_BALANCE, STIFF_GAINS  # noqa: E402
from sim.simulate.wholebody import WholeBodyGains  # noqa: E402

#: the sampler as first built: no fall in its cost, rollouts judged 0.4 s past their window, no
#: balance feedback
FIRST_SAMPLER = {"weights": CostWeights(fall=0.0), "lookahead": 48, "balance": None}
#: ``--controllers`` names: (label, ForwardValidation keywords, actuators[, the body's
#: ``sim_model`` keywords: ``validate.validation_model``'s, eval's gains unless they name some])
CONTROLLERS = {
    "plain": ("plain tracker", {"controller": "plain"}, "position"),
    "sampling64": (
        "sampler, 64 samples (as first built)",
        {"controller": "sampling", "samples": 64, "search": FIRST_SAMPLER},
        "position",
    ),
    "wholebody": ("whole-body QP", {"controller": "wholebody"}, "motor"),
}
#: the sampler before foot holding, elite reuse and the drift lead (``CostWeights.hold`` 0, no
#: elite, the balance feedback ``Balance()`` without ``k_drift``)
BEFORE_HOLD = {"weights": CostWeights(hold=0.0), "elite": 0, "balance": Balance()}
for _n in (16, 24, 28, 32, 48, 64):
    CONTROLLERS[f"falls{_n}"] = (  # falls in the cost, no balance feedback
        f"sampler, {_n} samples, falls in its cost",
        {"controller": "sampling", "samples": _n, "search": {**BEFORE_HOLD, "balance": None}},
        "position",
    )
    CONTROLLERS[f"balance{_n}"] = (  # and the balance feedback (eval's default before hold)
        f"sampler, {_n} samples, falls in its cost, balance feedback",
        {"controller": "sampling", "samples": _n, "search": BEFORE_HOLD},
        "position",
    )
    CONTROLLERS[f"default{_n}"] = (  # eval's sampler on the default gains only
        f"sampler, {_n} samples, eval's defaults on the default gains only: falls in its cost, "
        f"balance feedback with the drift lead, foot holding {CostWeights().hold:g}, "
        f"{search_offsets.__kwdefaults__['elite']} elite",
        {"controller": "sampling", "samples": _n},
        "position",
    )
#: eval's sampler on the lean body (``sim_model(lean=True)``: the same motion bit for bit,
#: cheaper steps): ``fast28`` at eval's 28 samples, ``fast<n>`` more samples for about the
#: old cost (``benchmarks/bench_simulate_step.py``)
for _n in (28, 32, 36, 40):
    CONTROLLERS[f"fast{_n}"] = (
        f"sampler, {_n} samples, eval's defaults now, lean body",
        {"controller": "sampling", "samples": _n},
        "position",
        {"lean": True},
    )
for _w in (0, 2, 5, 10, 20, 50):  # candidates: foot holding (sim.simulate.footholding) ...
    for _e in (0, 1, 4, 8):  # ... and elite reuse (search_offsets(elite=...))
        _name = (f"hold{_w}" if _w else "") + (f"elite{_e}" if _e else "")
        if _name:
            CONTROLLERS[_name] = (
                f"sampler, 28 samples, falls in its cost, balance feedback, foot holding {_w}, "
                f"{_e} elite",
                {"controller": "sampling", "samples": 28,
                 "search": {"weights": CostWeights(hold=_w), "elite": _e, "balance": Balance()}},
                "position",
            )  # fmt: skip

#: candidates against the root's drift, each on the default (28 samples, balance feedback):
#: ``bdrift<k>`` the balance feedback's velocity target leads by k [1/s] times the root's
#: horizontal position error (``Balance.k_drift``); ``xy<w>`` the cost's root position weight
#: (``CostWeights.root_xy``, 20 by default); ``vdrift<w>`` the cost's root velocity weight w
#: with its target leading by 1/s times the position error (``CostWeights.drift_rate``)
DRIFT = {
    **{f"bdrift{_k:g}": ({"balance": Balance(k_drift=_k)}, f"balance drift {_k:g}/s")
       for _k in (0.5, 1, 2, 4)},
    **{f"xy{_w}": ({"weights": CostWeights(root_xy=_w)}, f"root position weight {_w}")
       for _w in (50, 100, 200)},
    **{f"vdrift{_w}": ({"weights": CostWeights(root_vel=_w, drift_rate=1.0)},
                       f"root velocity weight {_w}, leading by 1/s times the drift")
       for _w in (2, 5, 10)},
    "bdrift2x5": ({"balance": Balance(k_drift=2.0, drift_max=0.5)},
                  "balance drift 2/s up to 0.5 m"),
    **{f"bdrift{_k}dead{_d:g}": ({"balance": Balance(k_drift=_k, drift_max=0.3 + _d,
                                                      drift_dead=_d)},
                                 f"balance drift {_k}/s beyond {_d:g} m")
       for _k in (2, 4) for _d in (0.05, 0.1)},
    "bdrift2v2": ({"balance": Balance(k_drift=2.0),
                   "weights": CostWeights(root_vel=2.0, drift_rate=1.0)},
                  "balance drift 2/s, root velocity weight 2 leading by 1/s times the drift"),
}  # fmt: skip
for _name, (_search, _label) in DRIFT.items():
    CONTROLLERS[_name] = (
        f"sampler, 28 samples, falls in its cost, balance feedback, {_label}",
        {"controller": "sampling", "samples": 28, "search": {"balance": Balance(), **_search}},
        "position",
    )


#: stiffer controllers on eval's default (``default28``), the torque limits the human ones in
#: all: ``stiff<d>`` caps each hinge's stiffness at its peak torque over d [rad]
#: (``Gains.min_deflection``, 0.25 by default), ``w12`` at 12 Hz bandwidth instead of 8, ``rad``
#: with the sampler's noise in the default body's angles (``noise_deflection`` 0.25: the
#: offsets' spread stays what it was in radians, not shrunk by the stiffer joints)
_RAD = {"noise_deflection": MIN_DEFLECTION}
STIFF = {
    "stiff0.1": (Gains(min_deflection=0.1), {}, "stiffness cap 0.1 rad"),
    "stiff0.05": (Gains(min_deflection=0.05), {}, "stiffness cap 0.05 rad"),
    "stiff0.1w12": (Gains(min_deflection=0.1, omega=2 * np.pi * 12.0), {},
                    "stiffness cap 0.1 rad, 12 Hz bandwidth"),
    "stiff0.1rad": (Gains(min_deflection=0.1), _RAD,
                    "stiffness cap 0.1 rad, sampler noise in the 0.25 rad body's angles"),
}  # fmt: skip
for _name, (_gains, _search, _label) in STIFF.items():
    CONTROLLERS[_name] = (
        f"sampler, 28 samples, eval's defaults, {_label}",
        {"controller": "sampling", "samples": 28, "search": _search},
        "position",
        {"gains": _gains},
    )

#: swing-foot placement (``sim.simulate.balance.Balance(c_d, c_v)``: the capture point's error)
STEP = Balance(c_d=1.0, c_v=0.3)
STEP_HALF = Balance(c_d=0.5, c_v=0.15)
#: foot holding 5 given up where the body's capture point leaves its support and the reference's
#: does not
CAPTURE_REF = CostWeights(hold=5.0, hold_capture=True, hold_capture_ref=True)
for _name, _label, _search in (
    ("step", "swing-foot placement", {"balance": STEP}),
    (
        "holdcap5",
        "foot holding 5 off while the capture point leaves the support",
        {"weights": CostWeights(hold=5.0, hold_capture=True)},
    ),
    (
        "stepholdcap5",
        "swing-foot placement, foot holding 5 off while the capture point leaves the support",
        {"balance": STEP, "weights": CostWeights(hold=5.0, hold_capture=True)},
    ),
    ("stephalf", "swing-foot placement at half the gains", {"balance": STEP_HALF}),
    (
        "holdcapref5",
        "foot holding 5 off while the capture point leaves the support where the reference's "
        "does not",
        {"weights": CAPTURE_REF},
    ),
    (
        "stepholdcapref5",
        "swing-foot placement, foot holding 5 off while the capture point leaves the support "
        "where the reference's does not",
        {"balance": STEP, "weights": CAPTURE_REF},
    ),
):
    CONTROLLERS[_name] = (
        f"sampler, 28 samples, falls in its cost, balance feedback, {_label}",
        {"controller": "sampling", "samples": 28, "search": {**BEFORE_HOLD, **_search}},
        "position",
    )  # fmt: skip


#: candidates on eval's default (``default28``: 28 samples, the balance feedback with the drift
#: lead, ``sim.simulate.validate.DEFAULT_BALANCE``): ``cc28`` tracks the contact-consistent
#: reference (no floor lift, stance soles on z = 0; ``ForwardValidation(contact_reference=
#: True)``; measured against the same lifted points as the default); ``feetdrift28`` reads the
#: drift lead's position error at the stance feet instead of the root (``Balance.drift_feet``);
#: ``ccfeetdrift28`` both
FEET_DRIFT = {"balance": dataclasses.replace(DEFAULT_BALANCE, drift_feet=True)}
for _name, _label, _kw in (
    ("cc28", "the contact-consistent reference", {"contact_reference": True}),
    (
        "lifted28",
        "the lifted reference (eval's default before the contact-consistent one)",
        {"contact_reference": False},
    ),
    ("feetdrift28", "the drift lead read at the stance feet", {"search": FEET_DRIFT}),
    (
        "ccfeetdrift28",
        "the contact-consistent reference, the drift lead read at the stance feet",
        {"contact_reference": True, "search": FEET_DRIFT},
    ),
):
    CONTROLLERS[_name] = (
        f"sampler, 28 samples, eval's defaults with {_label}",
        {"controller": "sampling", "samples": 28, **_kw},
        "position",
    )

#: the stiffer controllers further (a 2-clip smoke run: 12 Hz lowered the root-relative error
#: most) and with the drift lead at the stance feet
for _name, _gains, _search, _label in (
    (
        "stiff0.05w16",
        Gains(min_deflection=0.05, omega=2 * np.pi * 16.0),
        {},
        "stiffness cap 0.05 rad, 16 Hz bandwidth",
    ),
    (
        "stiff0.1w12feet",
        Gains(min_deflection=0.1, omega=2 * np.pi * 12.0),
        FEET_DRIFT,
        "stiffness cap 0.1 rad, 12 Hz bandwidth, the drift lead read at the stance feet",
    ),
    (
        "stiff0.1feet",
        Gains(min_deflection=0.1),
        FEET_DRIFT,
        "stiffness cap 0.1 rad, the drift lead read at the stance feet",
    ),
):
    CONTROLLERS[_name] = (
        f"sampler, 28 samples, eval's defaults, {_label}",
        {"controller": "sampling", "samples": 28, "search": _search},
        "position",
        {"gains": _gains},
    )  # fmt: skip

#: stiffness where the pose is and not where the balance is, on eval's default (the
#: contact-consistent reference): ``upper<d>[w<f>]`` the trunk, neck and arms capped at peak
#: torque over d [rad] (at f Hz), the legs with the default gains (``Gains.legs``);
#: ``ccstiff<d>w<f>`` the whole body so, beside them in the same run
_W12 = 2 * np.pi * 12.0
for _name, _gains, _label in (
    ("upper0.1", Gains(min_deflection=0.1, legs=Gains()), "upper body capped at 0.1 rad"),
    (
        "upper0.1w12",
        Gains(min_deflection=0.1, omega=_W12, legs=Gains()),
        "upper body capped at 0.1 rad, 12 Hz",
    ),
    ("ccstiff0.1w12", Gains(min_deflection=0.1, omega=_W12), "stiffness cap 0.1 rad, 12 Hz"),
):
    CONTROLLERS[_name] = (
        f"sampler, 28 samples, eval's defaults, {_label}",
        {"controller": "sampling", "samples": 28, "contact_reference": True},
        "position",
        {"gains": _gains},
    )  # fmt: skip
#: ``ccstiff0.1w12rad``: the stiff controller with the sampler's noise in the default body's
#: angles (``noise_deflection`` 0.25: the stiff body's offsets explore as widely in radians)
CONTROLLERS["ccstiff0.1w12rad"] = (
    "sampler, 28 samples, eval's defaults, stiffness cap 0.1 rad, 12 Hz, sampler noise in the "
    "0.25 rad body's angles",
    {"controller": "sampling", "samples": 28, "contact_reference": True, "search": _RAD},
    "position",
    {"gains": Gains(min_deflection=0.1, omega=_W12)},
)

#: the gains chosen per window (``sim.simulate.gainchoice``) between the default and the stiff
#: controller (cap 0.1 rad, 12 Hz), eval's default otherwise (``mix0.5`` was eval's default at 28:
#: ``sim.simulate.validate.DEFAULT_GAIN_CHOICE``): ``mix<share>`` that share of each
#: window's 28 candidates on the stiff gains; ``stifffb`` all on the stiff gains, a window whose
#: candidates all fall tried again on the default ones; ``mix<share>fb`` both
_STIFF = STIFF_GAINS  # eval's second gain set
for _name, _choice in (
    ("mix0.5", GainChoice(share=0.5)),
    ("mix0.25", GainChoice(share=0.25)),
    ("mix0.75", GainChoice(share=0.75)),
    ("stifffb", GainChoice(share=1.0, fallback=True)),
    ("mix0.5fb", GainChoice(share=0.5, fallback=True)),
):
    CONTROLLERS[_name] = (
        f"sampler, 28 samples, eval's defaults, {_choice.share:.0%} of the candidates on the "
        f"stiff gains (0.1 rad, 12 Hz){', default gains where all fall' if _choice.fallback else ''}",
        {"controller": "sampling", "samples": 28, "contact_reference": True,
         "search": {"choice": _choice}},
        "position",
        {"alternate_gains": (_STIFF,)},
    )  # fmt: skip

#: ``mix0.5s<n>``: ``mix0.5`` with ``n`` rollouts per window instead of 28; ``mix0.5s40`` is
#: eval's rollouts (``validate.DEFAULT_SAMPLES``; docs/results/simulate_samples.md) on the empty floor
for _n in (36, 40, 48):
    CONTROLLERS[f"mix0.5s{_n}"] = (
        f"sampler, {_n} samples, eval's defaults (gains chosen per window)",
        {"controller": "sampling", "samples": _n, "contact_reference": True,
         "search": {"choice": GainChoice(share=0.5)}},
        "position",
        {"alternate_gains": (_STIFF,)},
    )  # fmt: skip

#: ``mix0.5s40terrain``: eval's default, ``mix0.5s40`` with each clip tracked in the scene inferred
#: from its original motion (``ForwardValidation(terrain=True)``, ``sim.simulate.terrain``: boxes
#: under the feet that stand on steps, the ground from the ground-level stances;
#: ``validate.DEFAULT_TERRAIN``, docs/results/simulate_terrain.md)
CONTROLLERS["mix0.5s40terrain"] = (
    "sampler, 40 samples, eval's defaults (gains chosen per window), the scene inferred from the "
    "motion",
    {"controller": "sampling", "samples": 40, "contact_reference": True, "terrain": True,
     "search": {"choice": GainChoice(share=0.5)}},
    "position",
    {"alternate_gains": (_STIFF,)},
)  # fmt: skip

#: ``fp<w>``: eval's default (``mix0.5s40terrain``) with footprints (``sim.simulate.footprints``,
#: ``CostWeights(footprint=w)``: a sole down where the reference stands on it pays w times its
#: squared distance from the reference's, averaged over the window); ``fpland<w>`` only at
#: touch-down (``footprint_landing``); ``fplook<w>`` over the window and its lookahead
#: (``footprint_lookahead``)
for _w in (10, 30, 100, 300):
    for _how, _kw, _said in (
        ("", {}, ""),
        ("land", {"footprint_landing": True}, " at touch-down"),
        ("look", {"footprint_lookahead": True}, " over the lookahead too"),
    ):
        _base = CONTROLLERS["mix0.5s40terrain"]
        CONTROLLERS[f"fp{_how}{_w}"] = (
            _base[0] + f", footprints {_w}{_said}",
            {**_base[1], "search": {**_base[1]["search"],
                                    "weights": CostWeights(footprint=float(_w), **_kw)}},
            *_base[2:],
        )  # fmt: skip

#: ``sig<s>``: eval's default (``mix0.5s40terrain``) with the sampler's offset noise at s of each
#: joint's peak torque instead of 0.3 (``search_offsets(torque_sigma=s)``); ``trunk<s>``: the
#: offset noise of the trunk's hinges (``lowerback``, ``upperback``, ``thorax``) s times the
#: legs' (``sim.simulate.noisescale``); ``feet<s>``: the ankles' and toes' s times the rest's
#: (their low stiffness gives them the widest noise in radians); ``pers0.5``: a child's offset
#: starts from half its parent's instead of 0.8 (``persistence``); ``sig0.15rec1``: noise 0.15
#: with ``rec1``'s recovery (``SearchPlan(recover=1)``, below); ``narrow<f>of<h>``: a share h of
#: each window's candidates, drawn at random, with their noise times f (``SearchPlan(narrow=f,
#: narrow_share=h)``); ``...seed1``: its noise seeded 1, a second draw (docs/synthetic.md, "What
#: the root-relative error is made of")
_NOISE = {
    **{f"sig{_s:g}": ({"torque_sigma": _s}, f"offset noise {_s:g} of peak torque")
       for _s in (0.1, 0.15, 0.2)},
    **{f"trunk{_s:g}": ({"noise_scale": NoiseScale(scale=_s)},
                        f"the trunk's offset noise {_s:g} times the legs'")
       for _s in (0.5,)},
    "pers0.5": ({"persistence": 0.5}, "offsets persisting 0.5 instead of 0.8 per window"),
    "sig0.15rec1": ({"torque_sigma": 0.15, "plan": SearchPlan(recover=1)},
                    "offset noise 0.15 of peak torque, recovery: back 1 window, 2x samples"),
    **{f"feet{_s:g}": ({"noise_scale": NoiseScale(scale=_s, bones=("foot", "toes"))},
                       f"the ankles' and toes' offset noise {_s:g} times the rest's")
       for _s in (0.25, 0.5)},
    **{f"narrow{_f:g}of{_h:g}": ({"plan": SearchPlan(narrow=_f, narrow_share=_h)},
                                 f"{_h:g} of the candidates with the offset noise times {_f:g}")
       for _f, _h in ((0.5, 0.5), (0.5, 0.75), (0.33, 0.5))},
}  # fmt: skip
for _name, (_search, _label) in _NOISE.items():
    _base = CONTROLLERS["mix0.5s40terrain"]
    for _seed in (0, 1):
        CONTROLLERS[_name + ("seed1" if _seed else "")] = (
            _base[0] + f", {_label}" + (", its noise seeded 1" if _seed else ""),
            {**_base[1], "search": {**_base[1]["search"], **_search, "seed": _seed}},
            *_base[2:],
        )

#: ``nf<f>s<n>f<h>``: eval's default with ``n`` samples a window, the first ``h`` of them rolled
#: out with their noise times ``f`` and the rest at full noise only where one of those fell
#: (``SearchPlan(first=h, narrow=f, narrow_first=True)``: small corrections of the posture
#: where the body is safe, the full search where a fall threatens)
for _f, _n, _h in ((0.5, 40, 0.5), (0.5, 60, 0.67), (0.7, 60, 0.67), (0.5, 80, 0.5)):
    _base = CONTROLLERS["mix0.5s40terrain"]
    CONTROLLERS[f"nf{_f:g}s{_n}f{_h:g}"] = (
        _base[0] + f", {_n} samples instead: the first {_h:g} with the offset noise times {_f:g}, "
        "the rest at full noise where one of those fell",
        {**_base[1], "samples": _n, "search": {
            **_base[1]["search"], "plan": SearchPlan(first=_h, narrow=_f, narrow_first=True)}},
        *_base[2:],
    )  # fmt: skip

#: ``clear<w>``, ``pivot<w>``, ``clear<w>pivot<v>``: eval's default (``mix0.5s40terrain``) with
#: swing clearance and stance pivot (``sim.simulate.swingstance``, ``CostWeights(clearance=w,
#: pivot=v)``: a sole lower than the reference's swing sole, capped at 3 cm, pays w times the
#: squared shortfall [m^2]; a sole on its support where the reference stands on it pays v times
#: its yaw rate's squared difference from the reference's [rad^2/s^2]; means over the window)
for _name, _kw in (
    *((f"clear{_w:g}", {"clearance": _w}) for _w in (100.0, 300.0, 1000.0, 3000.0)),
    *((f"pivot{_w:g}", {"pivot": _w}) for _w in (0.003, 0.01, 0.03, 0.1, 0.3, 1.0)),
    *((f"clear{_c:g}pivot{_p:g}", {"clearance": _c, "pivot": _p})
      for _c, _p in ((300.0, 0.03), (1000.0, 0.03), (1000.0, 0.1))),
):  # fmt: skip
    _base = CONTROLLERS["mix0.5s40terrain"]
    _said = ", ".join(f"{k} {v:g}" for k, v in _kw.items())
    CONTROLLERS[_name] = (
        _base[0] + f", {_said}",
        {**_base[1], "search": {**_base[1]["search"], "weights": CostWeights(**_kw)}},
        *_base[2:],
    )
#: ``pivot0.03seed1``: ``pivot0.03`` with its noise seeded 1 (its own chance yardstick)
CONTROLLERS["pivot0.03seed1"] = (
    CONTROLLERS["pivot0.03"][0] + ", its noise seeded 1",
    {**CONTROLLERS["pivot0.03"][1],
     "search": {**CONTROLLERS["pivot0.03"][1]["search"], "seed": 1}},
    *CONTROLLERS["pivot0.03"][2:],
)  # fmt: skip

#: ``mix0.5s40hands``: ``mix0.5s40terrain`` with boxes under the hands that hold the body up too
#: (``ForwardValidation(hand_supports=True)``, ``sim.simulate.handholds``: a hand still above the
#: ground while the centre of mass is outside the soles' footprint; docs/synthetic.md)
CONTROLLERS["mix0.5s40hands"] = (
    "sampler, 40 samples, eval's defaults (gains chosen per window), the scene inferred from the "
    "motion with supports under the hands",
    {"controller": "sampling", "samples": 40, "contact_reference": True, "terrain": True,
     "hand_supports": True, "search": {"choice": GainChoice(share=0.5)}},
    "position",
    {"alternate_gains": (_STIFF,)},
)  # fmt: skip

#: ``mix0.5lock``: eval's default (``mix0.5``) tracking the foot-locked reference (its stance
#: soles held still, flat on the floor, by the legs: ``ForwardValidation(foot_lock=True)``)
CONTROLLERS["mix0.5lock"] = (
    "sampler, 28 samples, eval's defaults (gains chosen per window), the foot-locked reference",
    {"controller": "sampling", "samples": 28, "contact_reference": True, "foot_lock": True,
     "search": {"choice": GainChoice(share=0.5)}},
    "position",
    {"alternate_gains": (_STIFF,)},
)  # fmt: skip

#: every candidate but eval's own defaults (``default<n>``) keeps the reference it was measured
#: with: the lifted one, eval's default before the contact-consistent one
for _name, _entry in CONTROLLERS.items():
    if not _name.startswith("default") and "contact_reference" not in _entry[1]:
        _entry[1]["contact_reference"] = False

#: how eval's sampler (``mix0.5``) spends its rollouts (``sim.simulate.searchplan.SearchPlan``):
#: ``rec<r>`` where every candidate of a window falls, back up r windows and search them again
#: with twice the samples (the recoveries adding at most ``extra`` of the clip's rollouts);
#: ``end<w>`` each candidate's tracking cost at its window's end weighted w beside its
#: lookahead's; ``stage<n>`` n samples, half rolled out first and the rest only where one of
#: those fell; ``adapt<r>`` each hinge's noise scale following its kept candidates' spread
PLANS = {
    "rec1": (28, SearchPlan(recover=1), "recovery: back 1 window, 2x samples"),
    "rec2": (28, SearchPlan(recover=2, extra=0.5), "recovery: back 2 windows, 2x samples"),
    "end1": (28, SearchPlan(end_cost=1.0), "window-end cost 1"),
    "stage40": (40, SearchPlan(first=0.5), "40 samples, 20 first, the rest where one fell"),
    "adapt0.3": (28, SearchPlan(adapt=0.3), "noise scale per hinge adapted at rate 0.3"),
    "stage48f20": (48, SearchPlan(first=20 / 48), "48 samples, 20 first, the rest where one fell"),
    "stage40f28": (40, SearchPlan(first=0.7), "40 samples, 28 first, the rest where one fell"),
    "stage40end1": (
        40,
        SearchPlan(first=0.5, end_cost=1.0),
        "40 samples, 20 first, the rest where one fell, window-end cost 1",
    ),
    "stage40adapt0.3": (
        40,
        SearchPlan(first=0.5, adapt=0.3),
        "40 samples, 20 first, the rest where one fell, noise adapted at 0.3",
    ),
}
for _name, (_n, _plan, _label) in PLANS.items():
    CONTROLLERS[_name] = (
        f"sampler, {_n} samples, eval's defaults (gains chosen per window), {_label}",
        {"controller": "sampling", "samples": _n, "contact_reference": True,
         "search": {"choice": GainChoice(share=0.5), "plan": _plan}},
        "position",
        {"alternate_gains": (_STIFF,)},
    )  # fmt: skip

#: the time-varying LQR tracker (``sim.simulate.lqr``, no sampler): ``lqr`` linearised at the
#: simulated state every tick (``mjd_transitionFD``, one Riccati step a
#: tick from the last value matrix) on the servo body, its feedback offsetting the plain
#: tracker's targets; ``lqrref`` the gains of one Riccati pass along the reference (linearised
#: there, the stance soles sunk 0.5 mm into the floor)
_LQR = LQRWeights()
for _name, _w, _act, _label in (
    ("lqr", _LQR, "position", "linearised at the simulated state, servo body"),
    (
        "lqrref",
        dataclasses.replace(_LQR, online=False),
        "position",
        "one Riccati pass along the reference, servo body",
    ),
):
    CONTROLLERS[_name] = (
        f"time-varying LQR, {_label}",
        {"controller": "lqr", "contact_reference": True, "search": {"weights": _w}},
        _act,
    )  # fmt: skip

#: the LQR as the sampler's base policy (``sim.simulate.sampling_lqr``) on eval's default
#: (``mix0.5``): one gain per window, linearised at its cheapest kept start state, shared by all
#: its rollouts and the replay; ``mix0.5lqr<s>`` s times the gain, ``mix0.5lqr`` half of it (on
#: 8 clips the full gain fell 0.75 against half's 0.62 and mix0.5's 0.38: docs/synthetic.md)
for _name, _scale in (("mix0.5lqr", 0.5), ("mix0.5lqr1", 1.0), ("mix0.5lqr0.25", 0.25)):
    CONTROLLERS[_name] = (
        f"sampler, 28 samples, eval's defaults (gains chosen per window), the LQR's gain per "
        f"window times {_scale:g} in every rollout",
        {"controller": "sampling", "samples": 28, "contact_reference": True,
         "search": {"choice": GainChoice(share=0.5), "lqr_feedback": _scale}},
        "position",
        {"alternate_gains": (_STIFF,)},
    )  # fmt: skip
#: ``mix0.5lqrnobal``: half the LQR's gain in place of the balance feedback (none)
CONTROLLERS["mix0.5lqrnobal"] = (
    "sampler, 28 samples, eval's defaults (gains chosen per window), the LQR's gain per window "
    "times 0.5 in every rollout, no balance feedback",
    {"controller": "sampling", "samples": 28, "contact_reference": True,
     "search": {"choice": GainChoice(share=0.5), "lqr_feedback": 0.5, "balance": None}},
    "position",
    {"alternate_gains": (_STIFF,)},
)  # fmt: skip
#: ``mix0.5nobal``: eval's default without the balance feedback (the control for the above)
CONTROLLERS["mix0.5nobal"] = (
    "sampler, 28 samples, eval's defaults (gains chosen per window), no balance feedback",
    {"controller": "sampling", "samples": 28, "contact_reference": True,
     "search": {"choice": GainChoice(share=0.5), "balance": None}},
    "position",
    {"alternate_gains": (_STIFF,)},
)  # fmt: skip

#: compliant soles (``sim_model(soft_soles=SoftSole(timeconst))``: the sole and toe boxes'
#: floor contacts at that time constant instead of the stiff floor's 0.005 s, friction kept):
#: ``wholebodysoft`` the QP on them (0.02 s, MuJoCo's default), ``wholebodysoft0.01`` at
#: 0.01 s; ``mix0.5soft`` eval's default (``mix0.5``) on the 0.02 s soles
for _name, _tc in (("wholebodysoft", 0.02), ("wholebodysoft0.01", 0.01)):
    CONTROLLERS[_name] = (
        f"whole-body QP, compliant soles (contact time constant {_tc:g} s)",
        {"controller": "wholebody"},
        "motor",
        {"soft_soles": SoftSole(timeconst=_tc)},
    )
CONTROLLERS["mix0.5soft"] = (
    "sampler, 28 samples, eval's defaults (gains chosen per window), compliant soles (contact "
    "time constant 0.02 s)",
    {"controller": "sampling", "samples": 28, "contact_reference": True,
     "search": {"choice": GainChoice(share=0.5)}},
    "position",
    {"alternate_gains": (_STIFF,), "soft_soles": SoftSole(timeconst=0.02)},
)  # fmt: skip
#: ``wholebodyff``: the QP with its swing soles' orientation tracking the reference's angular
#: velocity and acceleration (``WholeBodyGains(swing_feedforward=True)``); ``wholebodyffsoft``
#: and on the 0.02 s compliant soles
_FF = {"gains": WholeBodyGains(swing_feedforward=True)}
CONTROLLERS["wholebodyff"] = (
    "whole-body QP, swing soles' orientation with the reference's angular velocity",
    {"controller": "wholebody", "search": _FF},
    "motor",
)
CONTROLLERS["wholebodyffsoft"] = (
    "whole-body QP, swing soles' orientation with the reference's angular velocity, compliant "
    "soles (0.02 s)",
    {"controller": "wholebody", "search": _FF},
    "motor",
    {"soft_soles": SoftSole(timeconst=0.02)},
)
#: the pad (``PAD_SOLE``: the floor's 0.005 s, a low impedance at the surface rising to the
#: floor's over 6 mm: soft for the first millimetres, as stiff as the floor deeper):
#: ``wholebodypad`` the QP, ``wholebodyffpad`` with the swing feed-forward, ``mix0.5pad``
#: eval's default on it
CONTROLLERS["wholebodypad"] = (
    "whole-body QP, padded soles",
    {"controller": "wholebody"},
    "motor",
    {"soft_soles": PAD_SOLE},
)
CONTROLLERS["wholebodyffpad"] = (
    "whole-body QP, swing soles' orientation with the reference's angular velocity, padded soles",
    {"controller": "wholebody", "search": _FF},
    "motor",
    {"soft_soles": PAD_SOLE},
)
CONTROLLERS["mix0.5pad"] = (
    "sampler, 28 samples, eval's defaults (gains chosen per window), padded soles",
    {"controller": "sampling", "samples": 28, "contact_reference": True,
     "search": {"choice": GainChoice(share=0.5)}},
    "position",
    {"alternate_gains": (_STIFF,), "soft_soles": PAD_SOLE},
)  # fmt: skip
#: the QP's feet (docs/synthetic.md "The QP's feet, one cause at a time"), each with
#: the swing feed-forward (``ff``) unless named without: ``land`` a foot the reference stands
#: on that does not touch aims ``land_depth`` below its sole; ``free`` the contact points of a
#: foot the reference has in the air not held still (``hold_swing=False``); ``pl<p>v<v>`` the
#: swing foot placed by the CoM's error (``placement`` p) and its velocity's (``placement_v`` v)
_PL, _LAND = {"placement": 1.0, "placement_v": 0.1}, {"land_depth": 0.03}
QPFEET = {
    "wholebodyffland": _LAND,
    "wholebodyffland5w30": {"land_depth": 0.05, "w_land": 30.0},
    "wholebodyfffree": {"hold_swing": False},
    "wholebodyfree": {"swing_feedforward": False, "hold_swing": False},
    "wholebodyffpl1v0.1": _PL,
    "wholebodyffpl0.5v0.1": {**_PL, "placement": 0.5},
    "wholebodyffpl1v0.2": {**_PL, "placement_v": 0.2},
    "wholebodyffpl1v0.1land": {**_PL, **_LAND},
    "wholebodyffpl1v0.2land": {**_PL, **_LAND, "placement_v": 0.2},
    "wholebodyffpl1v0.3land": {**_PL, **_LAND, "placement_v": 0.3},
    "wholebodyffpl1v0.1land5w30": {**_PL, "land_depth": 0.05, "w_land": 30.0},
    "wholebodyffpl1v0.1landfree": {**_PL, **_LAND, "hold_swing": False},
    "wholebodyffpl1v0.2landfree": {**_PL, **_LAND, "placement_v": 0.2, "hold_swing": False},
    "wholebodyffpl1v0.1landf3": {**_PL, **_LAND, "foot_omega": 2 * np.pi * 3.0},
    **{f"wholebodyffpl1v0.1landcom{_w}": {**_PL, **_LAND, "w_com": float(_w)}
       for _w in (20, 30, 50, 100)},
    "wholebodyffcom30": {"w_com": 30.0},
    **{f"wholebodyffpl1v0.1landcom30gap{_g}": {**_PL, **_LAND, "w_com": 30.0,
                                               "sole_gap": _g / 1000} for _g in (3, 5)},
}  # fmt: skip
for _name, _kw in QPFEET.items():
    _g = WholeBodyGains(**{"swing_feedforward": True, **_kw})
    CONTROLLERS[_name] = (
        "whole-body QP, "
        + ", ".join(f"{_k}={_v}" for _k, _v in _kw.items())
        + (", swing feed-forward" if _g.swing_feedforward else ""),
        {"controller": "wholebody", "search": {"gains": _g}},
        "motor",
    )

#: eval's default (``mix0.5s40terrain``) with the friction cone enforced harder
#: (``sim_model(friction=Friction(...))``, ``sim.simulate.friction``; the friction coefficient
#: kept): ``ell<r>`` the elliptic cone at impratio ``r``, ``ns<n>`` ``n`` noslip iterations,
#: ``tor`` the soles' floor contacts with torsional friction (condim 4; ``tor20`` at 0.02 m, the
#: patch of a heel or forefoot, instead of the floor's 0.005 m); docs/synthetic.md
FRICTIONS = {
    "ell5": Friction(elliptic=True, impratio=5.0),
    "ell10": Friction(elliptic=True, impratio=10.0),
    "ns3": Friction(noslip_iterations=3),
    "ell10ns3": Friction(elliptic=True, impratio=10.0, noslip_iterations=3),
    "ell10tor": Friction(elliptic=True, impratio=10.0, sole_condim=4),
    "tor20": Friction(sole_condim=4, torsion=0.02),
    "ell10tor20": Friction(elliptic=True, impratio=10.0, sole_condim=4, torsion=0.02),
}
for _name, _f in FRICTIONS.items():
    CONTROLLERS[f"mix0.5s40terrain{_name}"] = (
        CONTROLLERS["mix0.5s40terrain"][0] + f", friction {_f}",
        CONTROLLERS["mix0.5s40terrain"][1],
        "position",
        {"alternate_gains": (_STIFF,), "friction": _f},
    )
#: ``mix0.5s40terrainseed1``: eval's default with its sampler's noise seeded 1 instead of 0: another
#: draw of the same controller, the yardstick of how far a change's figures move by chance alone
CONTROLLERS["mix0.5s40terrainseed1"] = (
    CONTROLLERS["mix0.5s40terrain"][0] + ", its noise seeded 1",
    {**CONTROLLERS["mix0.5s40terrain"][1],
     "search": {**CONTROLLERS["mix0.5s40terrain"][1]["search"], "seed": 1}},
    "position",
    {"alternate_gains": (_STIFF,)},
)  # fmt: skip
