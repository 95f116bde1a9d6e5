"""Why the simulated body falls and strays, clip by clip: eval's forward simulation of the
original motion with each clip's fall, its cause and the reference's own state then.

Usage::

    python benchmarks/bench_simulate_falls.py --data ../shared/cmu --every 2 --workers 2 \
        [--offset 1] [--log rows.jsonl] [--page simulate_falls] [--no-write]

Per clip (eval's default, ``sim.simulate.validate.forward_validation``, on the IK fit of the
original, as ``bench_simulate.py`` runs it): whether and when it fell and why (the part that
touched the floor, ``sim.simulate.falls.fall_cause``, or the head), how high that part and the
head are in the reference then, and the reference's own state over the clip: its lowest
non-foot part (a body part on the floor), its lowest sole (feet through the floor), its flight
frames, its stance feet's sliding, the contact-consistent shift (how far the stance soles sat
off the floor estimate), the root's vertical speed (a jump). Then the root's horizontal drift
over time and the points that stray most. Each fall is put in a category
(:func:`fall_category`), written to ``docs/results/<page>.md`` with the command.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_simulate import jsonl_log  # noqa: E402
from results import keep_rows, write_results  # noqa: E402

from sidql.evaluation.cases import load_cases  # noqa: E402
from sidql.evaluation.trial_physics import _protocol_names, physics_setup  # noqa: E402
from sim.model.humanoid import subject_model  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402
from sim.physics.support import capture_unsupported  # noqa: E402
from sim.simulate.falls import (  # noqa: E402
    HEAD_GEOM,
    fall_cause,
    fall_reference,
    geom_bottoms,
)
from sim.simulate.model import CONTROL_HZ  # noqa: E402
from sim.simulate.reference import STANCE_GAP, lowest_foot_point, time_warp  # noqa: E402
from sim.simulate.validate import forward_validation  # noqa: E402

#: [s] the reference is read this long around the fall for a part near the floor
NEAR_S = 0.25
#: [m] a reference part this low near the fall lies (almost) on the floor
LOW_PART = 0.10
#: [m/s] the reference root's upward speed beyond which the motion jumps
JUMP_SPEED = 1.0
#: [s] a reference with both soles off the floor this long around the fall is held up by
#: something the empty scene lacks (a climb), or its floor is wrong: a jump's flight is shorter
LONG_FLIGHT = 0.4


def longest_run(mask: np.ndarray) -> int:
    """The length of the longest run of True in ``mask`` (T,)."""
    best = run = 0
    for m in mask:
        run = run + 1 if m else 0
        best = max(best, run)
    return best


def _foot_mask(model) -> np.ndarray:
    from sim.simulate.falls import _foot_mask as mask

    return mask(model)


def reference_state(model, ref: np.ndarray) -> dict:
    """The reference's own figures over ``ref`` (T, nq at the control rate, as tracked):
    per tick the lowest non-foot part (name, bottom [m]), the head and root height."""
    data = mujoco.MjData(model)
    feet = _foot_mask(model)
    head = model.geom(HEAD_GEOM).id
    floor = model.geom("floor").id
    low_part = np.empty(len(ref))
    low_name = np.empty(len(ref), int)
    bottoms = np.empty((len(ref), model.ngeom))
    head_z = np.empty(len(ref))
    for t, q in enumerate(ref):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        b = geom_bottoms(model, data)
        bottoms[t] = b
        head_z[t] = data.geom_xpos[head, 2]
        b = np.where(feet, np.inf, b)
        b[floor] = np.inf
        low_name[t] = int(np.argmin(b))
        low_part[t] = b[low_name[t]]
    return {"low_part": low_part, "low_name": low_name, "bottoms": bottoms, "head_z": head_z}


def fall_category(row: dict, capture: bool = True) -> str:
    """One word for why a clip fell (None: it did not), from its row's figures, in this order:
    ``capture-unsupported`` (the original capture itself needs support found nowhere on the
    floor, ``sim.physics.support.capture_unsupported`` of its inverse dynamics: no body performs
    it as captured), ``reference-unsupported`` (the reference's soles are off the floor for
    :data:`LONG_FLIGHT` around the fall), ``reference-part`` (the touching part is within :data:`LOW_PART` of the floor in the
    reference near the fall: the reference nearly puts it there), ``head-reference-low`` (the
    reference's own head is low then: a crouch, a roll), ``jump`` (the reference's root rises
    faster than :data:`JUMP_SPEED` within 0.5 s before), ``drift`` (the root is more than 0.3 m
    off the reference's path at the fall), ``balance`` (none of these: the body lost its balance
    on a motion that looks possible). ``capture`` False: the category the rest gives."""
    if not row["fell"]:
        return ""
    if capture and capture_unsupported(row.get("orig_support_missing_share")):
        return "capture-unsupported"
    if row["ref_flight_near_s"] >= LONG_FLIGHT:
        return "reference-unsupported"
    if row["ref_part_near_m"] is not None and row["ref_part_near_m"] <= LOW_PART:
        return "reference-part"
    if row["cause"] == "head" and row["ref_head_at_fall_m"] < 1.0:
        return "head-reference-low"
    if row["ref_jump_before_fall"]:
        return "jump"
    if row["drift_at_fall_m"] > 0.3:
        return "drift"
    return "balance"


def clip_row(fv, qpos: np.ndarray, fps: float, clip: str, original: dict | None = None) -> dict:
    """Eval's forward simulation of ``qpos`` (F, nq at ``fps``) on ``fv`` and the diagnosis;
    ``original``: the original's physics figures (``PhysicsJob.analyse``), whose support the
    row carries (``orig_support_missing_share``, ``orig_residual_force_bw``)."""
    t0 = time.process_time()
    figures = fv.run(qpos, fps)
    cpu = time.process_time() - t0
    model, every = fv.model, int(round(CONTROL_HZ / fps))
    sim = fv.last_qpos
    ref = fv.last_tracked
    n = len(sim)
    ref_f = ref[::every][:n]
    st = reference_state(model, ref)
    # the root's horizontal drift and heading error per frame
    drift = np.linalg.norm(sim[:, :2] - ref_f[:, :2], axis=1)
    # per-point root-relative error
    p_sim, p_ref = fv.points(sim), fv.points(ref_f)
    local = np.linalg.norm((p_sim - p_sim[:, :1]) - (p_ref - p_ref[:, :1]), axis=-1)
    glob = np.linalg.norm(p_sim - p_ref, axis=-1)
    upto = n if fv.last_fall_tick < 0 else max(1, -(-fv.last_fall_tick // every))
    per_point = local[:upto].mean(axis=0)
    worst = np.argsort(per_point)[::-1][:3]
    # the reference: its stance soles, flight, jump, the floor shift
    sole_low = lowest_foot_point(model, ref)
    raw = time_warp(model, qpos, fps, 1.0, CONTROL_HZ)
    vz = np.gradient(ref[:, 2], 1.0 / CONTROL_HZ)
    row = {
        "clip": clip,
        **{k: figures[k] for k in ("sim_fell", "sim_fall_s", "sim_error_mm",
                                   "sim_error_local_mm", "sim_skate_mm_s", "sim_skate_ref_mm_s")},
        "fell": bool(figures["sim_fell"]),
        "cpu_s": cpu,
        "ref_min_part_m": float(st["low_part"].min()),
        "ref_min_part": model.geom(int(st["low_name"][np.argmin(st["low_part"])])).name,
        "ref_min_sole_m": float(sole_low.min()),
        "ref_flight_share": float(np.mean(sole_low > STANCE_GAP)),
        "ref_longest_flight_s": longest_run(sole_low > STANCE_GAP) / CONTROL_HZ,
        "ref_root_vz_max": float(vz.max()),
        "ref_root_z_range_m": float(np.ptp(ref[:, 2])),
        "ref_raw_root_z_range_m": float(np.ptp(raw[:, 2])),
        "drift_mid_m": float(drift[: n // 2].max()) if n > 1 else 0.0,
        "drift_end_m": float(drift[upto - 1]),
        "drift_max_m": float(drift[:upto].max()),
        "global_upto_mm": 1e3 * float(glob[:upto].mean()),
        "worst_points": [(fv.names[i], round(1e3 * float(per_point[i]))) for i in worst],
        "cause": None, "part": None, "ref_part_at_fall_m": None, "ref_part_near_m": None,
        "ref_head_at_fall_m": None, "sim_head_at_fall_m": None, "ref_jump_before_fall": False,
        "drift_at_fall_m": None, "ref_flight_near_s": 0.0, "ref_low_part_at_fall": None, "ref_low_part_at_fall_m": None,
    }  # fmt: skip
    if fv.last_fall_tick >= 0:
        row.update(_fall_details(fv, sim, ref, st, vz, drift, every))
        k = fv.last_fall_tick
        around = sole_low[max(0, k - int(0.5 * CONTROL_HZ)) : k + int(0.5 * CONTROL_HZ) + 1]
        row["ref_flight_near_s"] = longest_run(around > STANCE_GAP) / CONTROL_HZ
    original = original or {}
    row["orig_support_missing_share"] = original.get("support_missing_share")
    row["orig_residual_force_bw"] = original.get("residual_force_bw")
    row["category"] = fall_category(row)
    return row


def _fall_details(fv, sim, ref, st, vz, drift, every) -> dict:
    """The fall's cause at its first recorded frame and the reference's state around it."""
    model = fv.model
    k = fv.last_fall_tick
    f = min(len(sim) - 1, -(-k // every))
    fref = fall_reference(model, ref)
    data = mujoco.MjData(model)
    cause = None
    for g in (f, min(f + 1, len(sim) - 1), max(f - 1, 0)):  # contacts at the frames' poses
        data.qpos[:] = sim[g]
        mujoco.mj_forward(model, data)
        cause = fall_cause(model, data, fref, min(g * every, len(ref) - 1))
        if cause:
            break
    head = model.geom(HEAD_GEOM).id
    data.qpos[:] = sim[f]
    mujoco.mj_kinematics(model, data)
    out = {"cause": cause or "?", "sim_head_at_fall_m": float(data.geom_xpos[head, 2]),
           "ref_head_at_fall_m": float(st["head_z"][k]), "drift_at_fall_m": float(drift[f]),
           "ref_low_part_at_fall": model.geom(int(st["low_name"][k])).name,
           "ref_low_part_at_fall_m": float(st["low_part"][k])}  # fmt: skip
    near = slice(max(0, k - int(NEAR_S * CONTROL_HZ)), k + int(NEAR_S * CONTROL_HZ) + 1)
    if cause and cause.startswith("contact:"):
        g = model.geom(cause.split(":", 1)[1]).id
        out["part"] = cause.split(":", 1)[1]
        out["ref_part_at_fall_m"] = float(st["bottoms"][k, g])
        out["ref_part_near_m"] = float(st["bottoms"][near, g].min())
    before = slice(max(0, k - int(0.5 * CONTROL_HZ)), k + 1)
    out["ref_jump_before_fall"] = bool(vz[before].max() > JUMP_SPEED)
    return out


TITLE = "Forward simulation: why the body falls, clip by clip"
_WORKER: dict = {"setup": {}, "bodies": {}}


def _task(item) -> dict:
    c, trial_cases = item
    if c.clip.source not in _WORKER["setup"]:
        _WORKER["setup"].update(physics_setup(trial_cases))
    if c.asf not in _WORKER["bodies"]:
        _WORKER["bodies"][c.asf] = forward_validation(subject_model(c.asf)[0],
                                                      _protocol_names(c.clip))  # fmt: skip
    original = _WORKER["setup"][c.clip.source].analyse(c.clip)
    return clip_row(_WORKER["bodies"][c.asf], original["per_frame"]["qpos"], c.clip.fps,
                    f"{Path(c.clip.source).stem}@{c.clip.start_frame}", original)  # fmt: skip


def table_markdown(rows: list[dict]) -> str:
    """The per-clip table and the fall categories' counts."""
    head = (
        "| clip | fell [s] | cause | reference's part then / nearest [m] | head sim / ref [m] | "
        "category | original: support missing [share], residual force [BW] | reference: lowest "
        "part [m], lowest sole [m], longest flight, root up [m/s] | drift mid / end [m] | "
        "root-relative / global [mm] | worst points [mm] |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|\n"
    )

    def m(v, fmt=".2f"):
        return "-" if v is None else f"{v:{fmt}}"

    lines = []
    for r in rows:
        fell = m(r["sim_fall_s"]) if r["fell"] else "no"
        lines.append(
            f"| {r['clip']} | {fell} | {r['cause'] or ''} | {m(r['ref_part_at_fall_m'])} / "
            f"{m(r['ref_part_near_m'])} | {m(r['sim_head_at_fall_m'])} / "
            f"{m(r['ref_head_at_fall_m'])} | {r['category']} | "
            f"{m(r.get('orig_support_missing_share'))}, {m(r.get('orig_residual_force_bw'))} | "
            f"{r['ref_min_part']} "
            f"{r['ref_min_part_m']:.2f}, {r['ref_min_sole_m']:+.3f}, "
            f"{r['ref_longest_flight_s']:.2f} s, {r['ref_root_vz_max']:.2f} | {r['drift_mid_m']:.2f} / "
            f"{r['drift_end_m']:.2f} | {r['sim_error_local_mm']:.0f} / {r['sim_error_mm']:.0f} | "
            + ", ".join(f"{n} {e}" for n, e in r["worst_points"])
            + " |"
        )
    cats: dict[str, list[str]] = {}
    for r in rows:
        if r["fell"]:
            rest = fall_category(r, capture=False)  # what else explains it, shown beside
            name = r["clip"] if rest == r["category"] else f"{r['clip']} ({rest})"
            cats.setdefault(r["category"], []).append(name)
    summary = "\n".join(f"- **{k}**: {len(v)} ({', '.join(v)})" for k, v in sorted(cats.items()))
    fell = np.mean([r["fell"] for r in rows])
    med = np.median
    return (
        f"{len(rows)} clips; falls {fell:.2f}; median root-relative "
        f"{med([r['sim_error_local_mm'] for r in rows]):.0f} mm, global "
        f"{med([r['sim_error_mm'] for r in rows]):.0f} mm; median root drift at the end "
        f"{med([r['drift_end_m'] for r in rows]):.2f} m.\n\nFalls by category "
        "(`bench_simulate_falls.fall_category`; in brackets, the category the rest of the rule "
        "gives a capture-unsupported fall):\n\n" + summary + "\n\n" + head + "\n".join(lines)
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=default_data_dir())
    ap.add_argument("--every", type=int, default=2)
    ap.add_argument("--offset", type=int, default=0)
    ap.add_argument("--max-clips", type=int, default=None)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--log", default=None, help="append every clip's row to this new file")
    ap.add_argument("--page", default="simulate_falls")
    ap.add_argument(
        "--from-log", default=None, metavar="LOG",
        help="write the page from a finished run's --log instead of simulating",
    )  # fmt: skip
    ap.add_argument(
        "--note", default="", help="with --from-log: a line for the page (the log's own run)"
    )
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    if not args.page.replace("_", "").isalnum():
        ap.error(f"--page must be a plain name; got {args.page!r}")
    command = "python benchmarks/bench_simulate_falls.py " + " ".join(sys.argv[1:])
    t0 = time.perf_counter()
    if args.from_log:
        with open(args.from_log, encoding="utf-8") as f:
            rows = sorted((json.loads(line) for line in f if line.strip()),
                          key=lambda r: (r["clip"].split("@")[0], int(r["clip"].split("@")[1])))  # fmt: skip
        for r in rows:  # by this script's rule (a log's own category may be older)
            r["category"] = fall_category(r)
        text = table_markdown(rows) + f"\n\nRows read from {Path(args.from_log).name}.\n"
        print(text)
        if not args.no_write:
            write_results(args.page, TITLE, text, command,
                          notes=(args.note + "\n\n" + _kept_rows_note(args, rows)).strip())  # fmt: skip
        return
    cases, _ = load_cases(args.data, progress=False, workers=1)
    cases = cases[args.offset :: args.every][: args.max_clips]
    by_trial: dict[str, list] = {}
    for c in cases:
        by_trial.setdefault(c.clip.source, []).append(c)
    log = jsonl_log(args.log)
    from sim.batch import iter_batch

    items = [(c, by_trial[c.clip.source]) for c in cases]
    got = {}
    for i, outcome in iter_batch(_task, items, workers=args.workers, progress=False,
                                 in_flight=args.workers):  # fmt: skip
        if outcome.ok:
            got[i] = outcome.result
            log(json.dumps(outcome.result), outcome.result)
        else:
            print(f"clip {i} failed: {outcome.error}", flush=True)
    rows = [got[i] for i in sorted(got)]
    text = (
        table_markdown(rows)
        + f"\n\nWall time {time.perf_counter() - t0:.0f} s on {args.workers} workers, "
        f"load {os.getloadavg()[0]:.1f} at the end.\n"
    )
    print(text)
    if not args.no_write:
        write_results(args.page, TITLE, text, command, notes=_kept_rows_note(args, rows))


def _kept_rows_note(args, rows: list[dict]) -> str:
    """Keep the page's rows in ``docs/results/rows/`` and say how to write it again from them."""
    path = keep_rows(args.page, rows)
    return (f"The rows are kept in {path}; the page again from them: `python "
            f"benchmarks/bench_simulate_falls.py --from-log {path} --page {args.page}`.")  # fmt: skip


if __name__ == "__main__":
    main()
