"""The physics figures: ground truth of the derivatives, what the evaluation finds on CMU, and speed.

Usage: .venv/bin/python benchmarks/bench_physics.py [--data ../shared/cmu] [--truth] [--figures]
       [--repeats 5] [--eval] [--write]

``--truth``: the ground-truth cases of ``tests/test_physics_truth.py`` (``mj_step`` at 1200 Hz,
limbs at 1.5-3 Hz, pushes on the thorax and a hand in flight, a push while standing, a kick on a
foot, a landing), analysed at 30 fps three ways: the original's path (its 120 Hz samples), the
exact point derivatives (a reconstruction's curve), and the 9-frame Savitzky-Golay filter of the
30 fps frames alone (the baseline). Targets: unpushed flight <= 3 % body weight mean, a push's
impulse within 5 % and peak within 15 %, no impact leaking > 10 % BW beyond 2 frames.

``--figures``: ``sidql eval --physics`` (five methods, W = 5 10 15) on ``--data``, in process:
the original's residual force per trial (target <= 0.03 BW mean) and torque, where its support
was found (the floor's fit; trials whose support is off the floor, and why; body points other
than the feet on the floor), the means over all trials and over those whose floor fits and
whose support is found on it, the noise floors,
Spearman's rho of Q against the residual force across method/W rows and clip by clip, and how
often optimal beats uniform on residual force (with the paired bootstrap interval).

``--write``: writes ``docs/results/physics.md`` (the parts run).

Part 1 (one core: the process is pinned to CPU 0 and BLAS to one thread): a real CMU clip (02_01,
clip 0, 30 fps, 23 protocol points), its uniform W=10 spherical Hermite reconstruction, and three
ways to get that reconstruction's physics, each followed by the same inverse dynamics
(``sim.physics.dynamics``):

* ours: ``sim.physics.ik.HumanoidIK`` (damped least squares on MuJoCo Jacobians, warm-started frame
  to frame) - also timed as the whole ``PhysicsJob.analyse`` (contacts and capsule replay too);
* naive: the same fit started cold every frame (rigid Kabsch placement of the zero pose);
* mink: ``mink.solve_ik`` with one position ``FrameTask`` per point (daqp QP), warm-started,
  iterated per frame until the step is below 1e-6 or 20 iterations.

Best of ``--repeats``; the aim: at most 0.5 s for ours (fit + dynamics).

Part 2 (``--eval``): wall time of ``sidql eval`` on ``--data`` at W = 5 10 15 for the five default
methods, without and with ``--physics`` (the baseline is the first). Target: ~10 minutes on 2
cores with ``--physics``. The load average is printed: other jobs on the machine slow both.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core: before numpy loads BLAS
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from sidql.evaluation.cases import make_case  # noqa: E402
from sidql.evaluation.validation import physics_job, trial_ground  # noqa: E402
from sidql.keyframes.methods import select  # noqa: E402
from sidql.keyframes.reconstructions import reconstruct_series  # noqa: E402
from sidql.keyframes.spherical import POINTS  # noqa: E402
from sim.analysis.job import MAX_DERIVATIVE_NOISE
from sim.model.humanoid import subject_model  # noqa: E402
from sim.motion.ingest import load_clips  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402
from sim.physics.dynamics import InverseDynamics  # noqa: E402
from sim.physics.ik import Fit, HumanoidIK  # noqa: E402
from sim.physics.support import HELD_BW, HELD_S, RESIDUAL_CAUSES

REPO = Path(__file__).resolve().parents[1]


def best(fn, repeats):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def naive_fit(ik: HumanoidIK, pts: np.ndarray) -> Fit:
    """Every frame from a cold start (no warm start)."""
    T = len(pts)
    q, e, it = np.empty((T, ik.model.nq)), np.empty(T), np.empty(T, dtype=int)
    for t in range(T):
        q[t], e[t], it[t] = ik.fit_frame(pts[t], ik.initial_pose(pts[t]), max_iter=100, tol=1e-6)
    return Fit(q, e, it)


def mink_fit(model, names, pts: np.ndarray, q_init: np.ndarray) -> Fit:
    """mink: one position FrameTask per point, daqp, warm-started."""
    import mink  # the baseline only

    cfg = mink.Configuration(model)
    tasks = [
        mink.FrameTask(
            "root" if n == "root" else f"{n}_end",
            "body" if n == "root" else "site",
            position_cost=1.0,
            orientation_cost=0.0,
            lm_damping=1e-4,
        )
        for n in names
    ]
    cfg.update(q_init)
    T = len(pts)
    q, e, it = np.empty((T, model.nq)), np.empty(T), np.zeros(T, dtype=int)
    for t in range(T):
        for k, task in enumerate(tasks):
            task.set_target(mink.SE3.from_translation(pts[t, k]))
        for i in range(20):
            v = mink.solve_ik(cfg, tasks, 1.0, "daqp", damping=1e-4)
            cfg.integrate_inplace(v, 1.0)
            it[t] = i + 1
            if np.abs(v).max() < 1e-6:
                break
        q[t] = cfg.q
        x = np.array(
            [cfg.data.xpos[1] if n == "root" else cfg.data.site(f"{n}_end").xpos for n in names]
        )
        e[t] = np.sqrt(np.mean(np.sum((x - pts[t]) ** 2, axis=1)))
    return Fit(q, e, it)


def part1(data: Path, repeats: int) -> str:
    asf = data / "02" / "02.asf"
    clips = load_clips(asf, data / "02" / "02_01.amc")
    clip = clips[0]
    model = subject_model(asf)[1]
    case = make_case(clip)
    rec = reconstruct_series(case.series, select("uniform", clip, 10), "hermite")
    pts = rec.positions
    job = physics_job(model, clip)
    ground = trial_ground(clips)
    job.analyse(clip, None, ground)  # the original: computed once per clip, cached
    ik = HumanoidIK(model, POINTS)
    inv = InverseDynamics(model)
    orig = job.original(clip, ground)
    contacts = job.force_points(orig.contacts, ground)  # same dynamics work for every fit
    q0 = clip.qpos[0]

    def dyn(fit):
        return inv.run(fit.qpos, clip.fps, contacts)

    rows = []
    for name, fit_fn in (
        ("ours (warm-started DLS)", lambda: ik.fit(pts, q_init=q0)),
        ("naive (cold start per frame)", lambda: naive_fit(ik, pts)),
        ("mink (daqp, warm-started)", lambda: mink_fit(model, POINTS, pts, q0)),
    ):
        t_fit, fit = best(fit_fn, repeats)
        t_dyn, _ = best(lambda fit=fit: dyn(fit), repeats)
        rows.append((name, t_fit, t_dyn, fit))
    t_all, _ = best(
        lambda: job.analyse(
            clip, pts, ground, velocities=rec.velocities, accelerations=rec.accelerations
        ),
        repeats,
    )
    lines = [
        f"clip 02_01 #0: {len(pts)} frames, {len(POINTS)} points, nv = {model.nv}; one core",
        "",
        "| IK | fit (s) | dynamics (s) | fit + dynamics (s) | vs ours | mean iterations "
        "| max point error (mm) |",
        "|---|---|---|---|---|---|---|",
    ]  # fmt: skip
    ours = rows[0][1] + rows[0][2]
    for name, tf, td, fit in rows:
        lines.append(
            f"| {name} | {tf:.3f} | {td:.3f} | {tf + td:.3f} | {(tf + td) / ours:.1f}x "
            f"| {fit.iterations.mean():.1f} | {1e3 * fit.error.max():.2f} |"
        )
    lines.append("")
    lines.append(
        f"whole PhysicsJob.analyse of the reconstruction (IK, curve derivatives through the "
        f"Jacobians, contacts, capsule replay, dynamics): {t_all:.3f} s ({t_all / ours:.1f}x ours)"
    )
    text = "\n".join(lines)
    print(text)
    return text


def part2(data: Path) -> str:
    base = [sys.executable, "-m", "sidql.commands.main", "eval", "--data", str(data),
            "--keyframes", "5", "10", "15", "--quiet"]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env.pop(k, None)
    lines, took = [], []
    with tempfile.TemporaryDirectory() as d:
        for extra in ([], ["--physics"]):
            t0 = time.perf_counter()
            subprocess.run(base + ["--out", f"{d}/r.json"] + extra, check=True, env=env,
                           stdout=subprocess.DEVNULL, cwd=REPO)  # fmt: skip
            took.append(time.perf_counter() - t0)
            label = "sidql eval --physics" if extra else "sidql eval (baseline)"
            lines.append(f"{label}: {took[-1]:.0f} s ({took[-1] / 60:.1f} min)")
    lines.append(f"ratio: {took[1] / took[0]:.1f}x; load average {os.getloadavg()[0]:.1f}")
    text = "\n".join(lines)
    print(text)
    return text


# ---------------------------------------------------------------- ground truth (--truth)


def truth() -> str:
    """The ground-truth cases of tests/test_physics_truth.py, measured three ways."""
    sys.path.insert(0, str(REPO / "tests"))
    import test_physics_truth as gt  # the simulations the tests check, not copied

    from sim.physics.ground import Ground

    humanoid = gt.humanoid_model()
    model = humanoid[1]
    push = np.array([200.0, -120.0, 120.0])
    rows = []

    def analyse(sim, way, ground=None):
        if way == "filter":  # the 30 fps frames alone, 9-frame Savitzky-Golay
            job, clip, idx = gt._job_and_clip(humanoid, sim)
            mp = job.motion_physics(clip.positions[:, idx], None, ground or Ground(-5.0), clip.qpos)
            return mp, np.arange(0, len(sim["qpos"]), gt.DENSE_HZ // gt.FPS)
        return gt._analyse(humanoid, sim, exact=way == "exact", ground=ground)

    def near_of(on):
        near = np.zeros(len(on), bool)
        i = np.flatnonzero(on)
        near[max(i[0] - 2, 0) : i[-1] + 3] = True
        return near

    for body in ("thorax", "lhand"):
        sim = gt._simulate(model, seconds=1.0, z0=3.0, v0=(0.5, 0, 2.0),
                           pushes=[(body, push, 0.4, 0.6, "sine")])  # fmt: skip
        for way in ("source", "exact", "filter"):
            mp, centre = analyse(sim, way)
            rf, W = mp.dynamics.residual_force, mp.dynamics.weight
            on = np.linalg.norm(sim["push"][centre], axis=1) > 0
            near = near_of(on)
            true = sim["push"].sum(0) / gt.DENSE_HZ
            imp = np.linalg.norm(rf[near].sum(0) / gt.FPS - true) / np.linalg.norm(true)
            peak = abs(np.linalg.norm(rf[on], axis=1).max() - np.linalg.norm(push))
            quiet = np.linalg.norm(rf[~near], axis=1) / W
            rows.append((f"push on the {body}, in flight", way, quiet.mean(), quiet.max(),
                         imp, peak / np.linalg.norm(push), None))  # fmt: skip
    kick = np.array([0.0, 1500.0, 3700.0])
    sim = gt._simulate(model, seconds=0.8, z0=3.0, pushes=[("rfoot", kick, 0.395, 0.405, "box")])
    for way in ("source", "exact", "filter"):
        mp, centre = analyse(sim, way)
        rf = np.linalg.norm(mp.dynamics.residual_force, axis=1) / mp.dynamics.weight
        far = np.abs(np.arange(len(centre)) - int(round(0.4 * gt.FPS))) > 2
        rows.append(("kick on a foot, in flight", way, rf[far].mean(), None, None, None,
                     rf[far].max()))  # fmt: skip
    stand = np.array([150.0, -150.0, 150.0])
    sim = gt._simulate(model, seconds=1.0, z0=None, floor=True, kp=600.0, kd=20.0,
                       driven=gt.ARMS, pushes=[("thorax", stand, 0.4, 0.6, "sine")])  # fmt: skip
    for way in ("source", "exact", "filter"):
        mp, centre = analyse(sim, way, Ground(0.0))
        floor = np.array([sim["floor"][max(c - 2, 0) : c + 2].mean(axis=0) for c in centre])
        extra = mp.dynamics.force - floor
        on = np.linalg.norm(sim["push"][centre], axis=1) > 0
        near = near_of(on)
        quiet = ~near
        quiet[:3] = quiet[-3:] = False
        true = sim["push"].sum(0) / gt.DENSE_HZ
        imp = np.linalg.norm(extra[near].sum(0) / gt.FPS - true) / np.linalg.norm(true)
        peak = abs(np.linalg.norm(extra[on], axis=1).max() - np.linalg.norm(stand))
        q = np.linalg.norm(extra[quiet], axis=1) / mp.dynamics.weight
        rows.append(("push on the thorax, standing (required - floor force)", way, q.mean(),
                     q.max(), imp, peak / np.linalg.norm(stand), None))  # fmt: skip
    sim = gt._simulate(model, seconds=0.9, z0=1.05, floor=True, kp=300.0, kd=10.0)
    for way in ("source", "exact", "filter"):
        mp, centre = analyse(sim, way, Ground(0.0))
        rf = np.linalg.norm(mp.dynamics.residual_force, axis=1) / mp.dynamics.weight
        first = int(np.argmax(np.linalg.norm(sim["floor"][centre], axis=1) > 0))
        rows.append(("landing: free fall > 2 frames before touch-down", way,
                     rf[: first - 2].mean(), rf[: first - 2].max(), None, None, None))  # fmt: skip
    names = {"source": "source frames (original)", "exact": "curve (exact)",
             "filter": "30 fps filter only (baseline)"}  # fmt: skip

    def f(x, pct=False):
        return "-" if x is None else (f"{100 * x:.1f} %" if pct else f"{x:.3f}")

    lines = [
        "| case | derivatives | unpushed mean (BW) | unpushed max (BW) | impulse error "
        "| peak error | leak > 2 frames away, max (BW) |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for case, way, qm, qx, imp, pk, leak in rows:
        lines.append(
            f"| {case} | {names[way]} | {f(qm)} | {f(qx)} | {f(imp, True)} | {f(pk, True)} "
            f"| {f(leak)} |"
        )
    lines.append(
        "\nTargets: unpushed frames <= 0.03 BW mean; impulse within 5 %, peak within 15 %; "
        "nothing > 0.10 BW beyond 2 frames of an impact."
    )
    text = "\n".join(lines)
    print(text)
    return text


# ---------------------------------------------------------------- CMU figures (--figures)


def figures(data: Path) -> str:
    """``sidql eval --physics`` in process and the figures drawn from it."""
    from scipy.stats import spearmanr

    from sidql.evaluation.cases import load_cases
    from sidql.evaluation.evaluate import evaluate
    from sidql.evaluation.scoring import NOISE_FLOOR
    from sidql.evaluation.significance import bootstrap_mean_ci
    from sidql.evaluation.tables import physics_markdown

    t0 = time.perf_counter()
    cases, _ = load_cases(data, progress=False)
    methods = ["random", "uniform", "greedy", "optimal", "pitch"]
    out = evaluate(cases, methods, [5, 10, 15], physics=True, progress=False)
    took = time.perf_counter() - t0
    per = out["per_clip"]
    lines = [f"{len(cases)} clips of {data}; {took:.0f} s in one process.", ""]
    # the original, per trial
    orig = [r for r in per if r["method"] == "original"]
    floors = {f["source"]: f for f in out["floors"]}
    by_trial: dict[str, list[dict]] = {}
    for r in orig:
        by_trial.setdefault(r["source"], []).append(r)
    lines += ["### The original's residual, per trial (means over its clips)", "",
              "Means over the measured frames; *unmeasured*: frames whose source window is "
              "shifted against the take's ends or a pose jump (more than "
              f"{MAX_DERIVATIVE_NOISE:g}x the centred window's noise), reported, not scored. "
              "*Held*: measured frames needing a horizontal force over "
              f"{HELD_BW:g} BW for {HELD_S:g} s or longer that no floor contact supplies.", "",
              "| trial | clips | residual force (BW) | residual torque (N m/kg) | unmeasured "
              "frames | no support found | held | floor fits | support | body on the floor |",
              "|---|---:|---:|---:|---:|---:|---:|---|---|---|"]  # fmt: skip
    for src, rs in sorted(by_trial.items(), key=lambda kv: Path(kv[0]).stem):
        f = floors[src]
        parts = ", ".join(f"{p} {100 * x:.1f} %" for p, x in f.get("ground_parts", {}).items())
        lines.append(
            f"| {Path(src).stem} | {len(rs)} | {np.mean([r['residual_force_bw'] for r in rs]):.3f} "
            f"| {np.mean([r['residual_torque_nm_kg'] for r in rs]):.2f} "
            f"| {f['dynamics_unmeasured_n']} "
            f"| {100 * f['support_missing_share']:.1f} % | {100 * f['support_held_share']:.1f} % "
            f"| {'yes' if f['floor_fits'] else 'no'} "
            f"| {'off the floor: ' + f['support_why'] if f['support_off_floor'] else 'found'} "
            f"| {parts or '-'} |"
        )
    rf = np.array([r["residual_force_bw"] for r in orig])
    fits = np.array([r["floor_fits"] for r in orig])
    found = np.array([not floors[r["source"]]["support_off_floor"] for r in orig])
    both = fits & found
    flagged = sorted(Path(s).stem for s, f in floors.items() if f["support_off_floor"])
    lines += ["", f"The original's mean residual force over all {len(orig)} clips: "
              f"**{rf.mean():.3f} BW** (median {np.median(rf):.3f}); over the {fits.sum()} clips "
              f"of trials whose floor fits: {rf[fits].mean():.3f} BW; over the {both.sum()} clips "
              f"of trials whose floor fits and whose support is found on it: "
              f"**{rf[both].mean() if both.any() else float('nan'):.3f} BW** (median "
              f"{np.median(rf[both]) if both.any() else float('nan'):.3f}). Support off the "
              f"floor ({len(flagged)} trials: {', '.join(flagged)}): "
              f"{rf[~found].mean() if (~found).any() else float('nan'):.3f} BW. Target 0.03 BW.",
              ""]  # fmt: skip
    lines += residual_breakdown([r for r, b in zip(orig, both, strict=True) if b])
    lines += ["### Means over clips (noise floor: how far 1.5 mm of marker noise moves each "
              "figure)", "", physics_markdown(out["results"]), ""]  # fmt: skip
    # Q against the residual force
    rows = [r for r in out["results"] if r["method"] not in ("original", NOISE_FLOOR)]
    q = [r["mean_q"] for r in rows]
    rho_mean = spearmanr(q, [r["residual_force_bw"] for r in rows]).statistic
    rho_median = spearmanr(q, [r["residual_force_bw_median"] for r in rows]).statistic
    clips = {}
    for r in per:
        if r["method"] in methods:
            clips.setdefault((r["source"], r["start_frame"]), []).append(r)
    per_clip_rho = []
    for rs in clips.values():
        a = [r["q"] for r in rs]
        b = [r["residual_force_bw"] for r in rs]
        if np.ptp(a) > 0 and np.ptp(b) > 0:
            per_clip_rho.append(spearmanr(a, b).statistic)
    per_clip_rho = np.array(per_clip_rho)
    lines += [
        "### Does lower Q mean less residual force?", "",
        f"Spearman's rho of Q against the residual force across the {len(rows)} method/W rows: "
        f"{rho_mean:.2f} (means), {rho_median:.2f} (medians). Clip by clip (the 15 "
        f"reconstructions of a clip): median rho {np.median(per_clip_rho):.2f}, positive in "
        f"{100 * (per_clip_rho > 0).mean():.0f} % of {len(per_clip_rho)} clips.", "",
    ]  # fmt: skip
    # optimal against uniform
    lines += [
        "| W | clips where optimal's residual force is lower / equal (to 1 mBW) / higher than "
        "uniform's | mean(optimal - uniform) [95 % CI] (BW) | decided |",
        "|---|---|---|---|",
    ]
    for W in (5, 10, 15):
        o = {(r["source"], r["start_frame"]): r for r in per if r["method"] == "optimal"
             and r["keyframes"] == W}  # fmt: skip
        u = {(r["source"], r["start_frame"]): r for r in per if r["method"] == "uniform"
             and r["keyframes"] == W}  # fmt: skip
        d = np.array([o[k]["residual_force_bw"] - u[k]["residual_force_bw"] for k in o if k in u])
        mean, lo, hi = bootstrap_mean_ci(d)
        decided = "optimal" if hi < 0 else ("uniform" if lo > 0 else "not told apart")
        eq = np.abs(d) < 1e-3  # both explained by the ground to the mBW
        shares = f"{100 * (d < 0)[~eq].sum() / len(d):.0f} / {100 * eq.mean():.0f} / " + (
            f"{100 * (d > 0)[~eq].sum() / len(d):.0f} %"
        )
        lines.append(f"| {W} | {shares} | {mean:+.3f} [{lo:+.3f}, {hi:+.3f}] | {decided} |")
    text = "\n".join(lines)
    print(text)
    return text


def residual_breakdown(rows: list[dict]) -> list[str]:
    """Where the original's residual force comes from over ``rows`` (its clips): per cause
    (:func:`sim.physics.support.residual_causes`), its share of the mean over the measured
    frames, and the frames left unmeasured with what they would have added."""
    n = np.array([r["dynamics_n"] for r in rows], dtype=float)
    un = np.array([r["dynamics_unmeasured_n"] for r in rows], dtype=float)
    if not len(rows) or n.sum() == 0:
        return []
    lines = [f"Where it comes from, over those {len(rows)} clips ({int(n.sum())} measured frames; "
             "per cause, the residual force summed over its frames / all measured frames):", "",
             "| cause | BW |", "|---|---:|"]  # fmt: skip
    total = 0.0
    for c in RESIDUAL_CAUSES:
        v = float(sum(r["residual_force_bw_by_cause"][c] * k for r, k in zip(rows, n, strict=True)))
        total += v
        lines.append(f"| {c} | {v / n.sum():.4f} |")
    lines.append(f"| all (frame-weighted mean) | {total / n.sum():.4f} |")
    lost = sum(
        (r["residual_force_bw_unmeasured"] or 0.0) * k for r, k in zip(rows, un, strict=True)
    )
    lines += ["", f"Unmeasured there: {int(un.sum())} frames (take edges and pose jumps), "
              f"{lost / max(un.sum(), 1):.3f} BW on average; scored, the frame-weighted mean "
              f"over all {int(n.sum() + un.sum())} frames would be "
              f"{(total + lost) / (n.sum() + un.sum()):.4f} BW.", ""]  # fmt: skip
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--truth", action="store_true", help="the ground-truth cases, measured")
    ap.add_argument("--figures", action="store_true", help="eval --physics figures on --data")
    ap.add_argument("--speed", action="store_true", help="time one clip's physics (one core)")
    ap.add_argument("--eval", action="store_true", help="also time sidql eval with/without physics")
    ap.add_argument("--write", action="store_true", help="write docs/results/physics.md")
    args = ap.parse_args()
    parts = []
    print(f"mujoco {mujoco.__version__}; load average {os.getloadavg()}")
    if args.truth:
        parts.append(("Derivatives against an mj_step ground truth at 30 fps", truth()))
    if args.figures:
        parts.append(("What the evaluation finds on CMU", figures(args.data)))
    if args.speed or args.eval:
        if hasattr(os, "sched_setaffinity"):
            os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
        if args.speed:
            parts.append(("Speed of one clip's physics (one core)", part1(args.data, args.repeats)))
        if args.eval:
            parts.append(("Wall time of sidql eval", part2(args.data)))
    if args.write and parts:
        sys.path.insert(0, str(REPO / "benchmarks"))
        from results import write_results

        flags = " ".join(
            f for f, on in (("--truth", args.truth), ("--figures", args.figures),
                            ("--speed", args.speed), ("--eval", args.eval)) if on
        )  # fmt: skip
        body = "\n\n".join(f"## {title}\n\n{text}" for title, text in parts)
        print(write_results("physics", "Physics figures", body,
                            f"python benchmarks/bench_physics.py {flags} --write"))  # fmt: skip


if __name__ == "__main__":
    main()
