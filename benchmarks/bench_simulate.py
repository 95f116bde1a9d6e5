"""Validation by forward simulation, per keyframe method: could a body perform the motion?

Usage::

    python benchmarks/bench_simulate.py --data ../shared/cmu [--keyframes 10] [--workers 2]
        [--samples 64] [--every 5] [--max-clips N]

Every 60-frame clip (30 fps) of the trials under ``--data`` is rebuilt by each method; the
subject's humanoid is fitted to the original and to every reconstruction (``sim.physics``) and
the subject's torque-limited body tracks each fit in ``mj_step`` with no assistance
(``sim.simulate.validate``), exactly as ``sidql eval --physics --simulate`` does. Per method:
the tracking error against the motion tracked and against the original, the share of clips in
which the body fell and when, and the joint torque it used; the original's own row is the
baseline. Written to ``docs/results/simulate.md`` (with ``--samples N``, the sampling tracker
of ``sim.simulate.sampling``: ``docs/results/simulate_sampled.md``). Quality figures: the machine's load does not
change them.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from results import write_results  # noqa: E402

from sidql.evaluation.cases import load_cases  # noqa: E402
from sidql.evaluation.evaluate import evaluate  # noqa: E402
from sidql.evaluation.tables import simulate_markdown  # noqa: E402
from sidql.evaluation.trial_physics import _protocol_names, physics_setup  # noqa: E402
from sim.model.humanoid import subject_model  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402
from sim.simulate.balance import Balance  # noqa: E402
from sim.simulate.model import MIN_DEFLECTION, Gains  # noqa: E402
from sim.simulate.sampling import CostWeights, search_offsets  # noqa: E402
from sim.simulate.validate import DEFAULT_BALANCE, ForwardValidation, validation_model  # noqa: E402

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
    CONTROLLERS[f"default{_n}"] = (  # the sampler as eval runs it now (validate's defaults)
        f"sampler, {_n} samples, eval's defaults now: falls in its cost, balance feedback with "
        f"the drift lead, foot holding {CostWeights().hold:g}, "
        f"{search_offsets.__kwdefaults__['elite']} elite",
        {"controller": "sampling", "samples": _n},
        "position",
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


def _clip_rows(c, setup, names, bodies: dict, threads: int) -> dict[str, dict]:
    """Per controller name, the figures of ``ForwardValidation.run`` on case ``c``'s original
    motion (its IK fit from ``setup``, :func:`physics_setup`); ``bodies`` caches each subject's
    body per controller."""
    qpos = setup[c.clip.source].analyse(c.clip)["per_frame"]["qpos"]
    out = {}
    for n in names:
        _, kw, actuators = CONTROLLERS[n][:3]
        model_kw = CONTROLLERS[n][3] if len(CONTROLLERS[n]) > 3 else {}
        if (c.asf, n) not in bodies:
            skeleton = subject_model(c.asf)[0]
            model = validation_model(skeleton, actuators=actuators, **model_kw)
            bodies[c.asf, n] = ForwardValidation(
                model, _protocol_names(c.clip), threads=threads, **kw
            )
        t0 = time.process_time()
        w0 = time.perf_counter()
        row = bodies[c.asf, n].run(qpos, c.clip.fps)  # the fits above are not timed
        seconds = c.clip.n_frames / c.clip.fps
        cpu = (time.process_time() - t0) / seconds
        wall = (time.perf_counter() - w0) / seconds
        out[n] = {"clip": f"{c.clip.source}@{c.clip.start_frame}", **row,
                  "sim_unstable": int(bodies[c.asf, n].last_unstable),
                  "sim_cpu_s_per_s": cpu, "sim_wall_s_per_s": wall}  # fmt: skip
    return out


_WORKER: dict = {"setup": {}, "bodies": {}}  # a pool worker's fits per trial, bodies per subject


def _clip_task(item) -> dict[str, dict]:
    """One clip in a pool worker: ``item`` = (case, every case of its trial, names, threads);
    the trial's physics set up once per worker from all its clips, as one process would."""
    c, trial_cases, names, threads = item
    if c.clip.source not in _WORKER["setup"]:
        _WORKER["setup"].update(physics_setup(trial_cases))
    return _clip_rows(c, _WORKER["setup"], names, _WORKER["bodies"], threads)


def controller_rows(
    cases, names: list[str], log=None, threads: int = 1, workers: int = 1
) -> dict[str, list[dict]]:
    """Per controller name (:data:`CONTROLLERS`), the figures of
    ``ForwardValidation.run`` for the original motion (its IK fit) of every case, in case
    order: in one process (the sampler's rollouts on ``threads`` threads; its CPU time counts
    every thread's), or one clip per task on ``workers`` processes (the same figures: every
    controller is deterministic and each trial's physics is set up from all its clips)."""
    out: dict[str, list[dict]] = {n: [] for n in names}
    if workers <= 1:
        setup, bodies = physics_setup(cases), {}
        per_clip = (_clip_rows(c, setup, names, bodies, threads) for c in cases)
        done = enumerate(per_clip)
    else:
        by_trial: dict[str, list] = {}
        for c in cases:
            by_trial.setdefault(c.clip.source, []).append(c)
        items = [(c, by_trial[c.clip.source], names, threads) for c in cases]
        done = _pool_rows(items, workers)
    got: dict[int, dict] = {}
    for i, rows in done:
        got[i] = rows
        if log:
            for n in names:
                log(f"{i + 1}/{len(cases)} {n} {rows[n]}", rows[n] | {"controller": n})
    for i in sorted(got):
        for n in names:
            out[n].append(got[i][n])
    return out


def _pool_rows(items: list, workers: int):
    """(position, rows) of :func:`_clip_task` per item as the clips finish; a clip whose
    simulation failed is reported and left out."""
    from sim.batch import iter_batch

    for i, outcome in iter_batch(_clip_task, items, workers=workers, progress=False):
        if outcome.ok:
            yield i, outcome.result
        else:
            print(f"clip {i} failed: {outcome.error}", flush=True)


def jsonl_log(path: str | None):
    """A log function printing each row, and appending it as a JSON line to ``path`` (a new
    file, not followed through a link) where given: a long run's rows survive its end."""
    import json

    fd = None
    if path:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)

    def log(message: str, row: dict | None = None) -> None:
        print(message, flush=True)
        if fd is not None and row is not None:
            os.write(fd, (json.dumps(row) + "\n").encode())

    return log


def paired_markdown(rows: dict[str, list[dict]]) -> str:
    """Each controller against the first, paired over the clips both ran
    (``sidql.evaluation.significance.paired_bootstrap``: the mean difference, its 95 %
    interval over 10,000 resamples of the clips): falls, root-relative and global error, and
    the median per-clip change of each error."""
    from sidql.evaluation.significance import paired_bootstrap

    names = list(rows)
    base = {r["clip"]: r for r in rows[names[0]]}
    head = (
        f"Against the first row ({CONTROLLERS[names[0]][0]}), paired over the clips both ran: "
        "mean difference [95 % interval]; the median per-clip change.\n\n"
        "| controller | clips | falls | root-relative [mm] | median change | global [mm] | "
        "median change |\n|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for n in names[1:]:
        both = [(r, base[r["clip"]]) for r in rows[n] if r["clip"] in base]
        cells = [CONTROLLERS[n][0], str(len(both))]
        for key in ("sim_fell", "sim_error_local_mm", "sim_error_mm"):
            a = np.array([r[key] for r, _ in both], dtype=float)
            b = np.array([q[key] for _, q in both], dtype=float)
            t = paired_bootstrap(a, b)
            fmt = "+.2f" if key == "sim_fell" else "+.0f"
            cells.append(f"{t['mean_diff']:{fmt}} [{t['ci_low']:{fmt}}, {t['ci_high']:{fmt}}]")
            if key != "sim_fell":
                cells.append(f"{np.median(a - b) if a.size else float('nan'):+.0f}")
        lines.append("| " + " | ".join(cells) + " |")
    return head + "\n".join(lines) + "\n"


def controllers_markdown(rows: dict[str, list[dict]]) -> str:
    """The controllers' table: falls, root-relative and global tracking error
    (mean over the protocol points, median over clips), foot skating in contact against the
    tracked motion's (medians over clips, the same estimator), CPU s per simulated s (mean)."""
    head = (
        "| controller | clips | falls | root-relative error, median [mm] | global error, "
        "median [mm] | skating in contact, median [mm/s] | the reference's [mm/s] | CPU s per "
        "simulated s |\n|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for n, rs in rows.items():

        def med(k, rs=rs):
            v = np.array([np.nan if r[k] is None else r[k] for r in rs], dtype=float)
            v = v[np.isfinite(v)]
            return float(np.median(v)) if v.size else float("nan")

        fell = float(np.mean([r["sim_fell"] for r in rs]))
        cpu = float(np.mean([r["sim_cpu_s_per_s"] for r in rs]))
        lines.append(
            f"| {CONTROLLERS[n][0]} | {len(rs)} | {fell:.2f} | {med('sim_error_local_mm'):.0f} "
            f"| {med('sim_error_mm'):.0f} | {med('sim_skate_mm_s'):.0f} "
            f"| {med('sim_skate_ref_mm_s'):.0f} | {cpu:.2f} |"
        )
    unstable = {n: sum(r.get("sim_unstable", 0) for r in rs) for n, rs in rows.items()}
    note = "".join(f"\n{CONTROLLERS[n][0]}: MuJoCo flagged a diverging acceleration in {k} "
                   "clips.\n" for n, k in unstable.items() if k)  # fmt: skip
    return head + "\n".join(lines) + "\n" + note


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--data", "--cmu", dest="cmu", default=default_data_dir(),
        help="folder of CMU trials (default: $SIDQL_DATA or ../shared/cmu)",
    )  # fmt: skip
    ap.add_argument("--keyframes", type=int, nargs="+", default=[10])
    ap.add_argument("--methods", nargs="+",
                    default=["random", "uniform", "greedy", "optimal", "pitch"])  # fmt: skip
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--max-clips", type=int, default=None)
    ap.add_argument(
        "--every",
        type=int,
        default=1,
        help="keep every N-th clip (a subset spread over the trials)",
    )
    ap.add_argument(
        "--samples",
        type=int,
        default=0,
        help="sampling tracker's rollouts per window (0: the plain tracker)",
    )
    ap.add_argument(
        "--controllers", nargs="+", choices=sorted(CONTROLLERS), default=None,
        help="compare these controllers on the original motion only (one clip per process on "
        "--workers; writes docs/results/simulate_controllers.md or --page)",
    )  # fmt: skip
    ap.add_argument(
        "--threads", type=int, default=1,
        help="with --controllers: the sampler's rollouts on this many threads",
    )  # fmt: skip
    ap.add_argument(
        "--page", default="simulate_controllers",
        help="with --controllers: the docs/results page written (default simulate_controllers)",
    )  # fmt: skip
    ap.add_argument(
        "--log", default=None,
        help="with --controllers: also append every clip's row as a JSON line to this new file",
    )  # fmt: skip
    ap.add_argument("--no-write", action="store_true", help="print only")
    args = ap.parse_args()
    if not args.page.replace("_", "").isalnum():
        ap.error(f"--page must be a plain name (letters, digits, _); got {args.page!r}")
    command = "python benchmarks/bench_simulate.py " + " ".join(sys.argv[1:])
    t0 = time.perf_counter()
    cases, skipped = load_cases(args.cmu, progress=False, workers=args.workers)
    cases = cases[:: args.every][: args.max_clips]
    if args.controllers:
        rows = controller_rows(cases, args.controllers, log=jsonl_log(args.log),
                               threads=args.threads, workers=args.workers)  # fmt: skip
        limited = f", one clip in {args.every} only (--every)" if args.every > 1 else ""
        text = (
            f"{len(cases)} clips of 60 frames (30 fps, 2 s) from "
            f"{len({c.clip.source for c in cases})} trials{limited}: the original motion (its "
            "IK fit on the subject's skeleton) tracked by each controller with no assistance; a "
            "fall as `sim.simulate.falls` defines it; CPU time of every thread "
            f"(--threads {args.threads}; one clip per process on --workers {args.workers}).\n\n"
            + controllers_markdown(rows)
            + ("\n" + paired_markdown(rows) if len(rows) > 1 else "")
            + f"\nWall time {time.perf_counter() - t0:.0f} s (loading and fits included).\n"
        )
        print(text)
        if not args.no_write:
            write_results(args.page, "Forward simulation: the controllers on the "
                          "original motion", text, command)  # fmt: skip
        return
    out = evaluate(cases, args.methods, args.keyframes, physics=True, simulate=True,
                   simulate_samples=args.samples, workers=args.workers,
                   progress=False)  # fmt: skip
    trials = len({c.clip.source for c in cases})
    sampled = f" --samples {args.samples}" if args.samples else ""
    note = " (the sampling tracker, `sim.simulate.sampling`)" if args.samples else ""
    limited = f", one clip in {args.every} only (--every)" if args.every > 1 else ""
    if args.max_clips:
        limited += f", the first {args.max_clips} clips only (--max-clips)"
    text = (
        f"{len(cases)} clips of 60 frames from {trials} trials ({len(skipped)} skipped); the "
        f"equivalent command: `sidql eval --data {args.cmu} --keyframes "
        f"{' '.join(map(str, args.keyframes))} --methods {' '.join(args.methods)} --physics "
        f"--simulate{sampled}`{note}{limited}. Means over clips (fall time: over the clips that "
        "fell).\n\n" + simulate_markdown(out["results"])
    )
    if args.samples:  # what the sampling costs (the machine's load changes this one)
        text += (
            f"\nWall time {time.perf_counter() - t0:.0f} s for the whole run (loading, fits and "
            f"{len(cases) * (1 + len(args.methods) * len(args.keyframes))} simulations) on "
            f"{args.workers} workers.\n"
        )
    print(text)
    print(f"({time.perf_counter() - t0:.0f} s)")
    if not args.no_write:
        name, title = (
            "simulate",
            "Forward simulation per method: the human-strength body, no assistance",
        )
        if args.samples:
            name, title = "simulate_sampled", title + ", the sampling tracker"
        write_results(name, title, text, command)


if __name__ == "__main__":
    main()
