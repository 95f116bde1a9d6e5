"""Synthetic clips: per-kind tracking, speed distributions vs real, simulation speed, 1->2 workers.

Usage: ``python benchmarks/bench_synth.py --cmu ../shared/cmu --synth DIR [--plot docs/synth_speeds.png]``
where DIR was written by ``sidql synth``. Prints: per kind, tracking MPJPE, falls and mean
assistance; point-speed and joint-angular-speed p50/p95/p99 of synthetic vs real clips (and their
ratio); the lowest body point; simulated frames per second per core (ratio to real time); and the
1 -> 2 worker speed-up of ``synthesize`` measured in this run. Also the floor contacts (deepest
per clip and the steady stance figure) and the physics room's audit of every clip
(``sim.simulate.audit``): residual force where no help was recorded vs where it was.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from sim.model.humanoid import canonical_skeleton
from sim.motion.clip import load_npz
from sim.motion.dataset import find_trials
from sim.motion.ingest import load_motion
from sim.simulate.audit import assistance_audit
from sim.simulate.controller import track
from sim.simulate.dataset import synthesize
from sim.simulate.generate import simulated_clip
from sim.simulate.model import sim_model
from sim.simulate.reference import on_floor, trial_qpos


def speeds(clips):
    """Point speeds [m/s] and hinge angular speeds [rad/s], pooled over frames and points."""
    p = np.concatenate([np.linalg.norm(c.velocities[:, 1:], axis=-1).ravel() for c in clips])
    w = np.concatenate([np.abs(c.qvel[:, 6:]).ravel() for c in clips])
    return p, w


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cmu", required=True)
    ap.add_argument("--synth", required=True)
    ap.add_argument("--plot", default=None)
    ap.add_argument("--speed-n", type=int, default=8, help="clips per worker-count timing")
    args = ap.parse_args()

    index = json.loads((Path(args.synth) / "index.json").read_text())
    rows = index["trials"]
    print("| kind | clips | tracking MPJPE [mm] | falls | mean assistance [body weight] |")
    print("|---|---|---|---|---|")
    for kind in dict.fromkeys(r["subject"] for r in rows):
        rs = [r for r in rows if r["subject"] == kind]
        print(
            f"| {kind} | {len(rs)} | {np.mean([r['tracking_mpjpe_mm'] for r in rs]):.0f} | "
            f"{sum(r['fell'] for r in rs)} | {np.mean([r['mean_assistance'] for r in rs]):.2f} |"
        )

    synth = {k: [load_npz(Path(args.synth) / r["file"]) for r in rows if r["subject"] == k]
             for k in dict.fromkeys(r["subject"] for r in rows)}  # fmt: skip
    real = [load_motion(t.asf, t.amc, skeleton="humanoid") for t in find_trials(args.cmu)]
    rp, rw = speeds(real)
    allc = [c for v in synth.values() for c in v]
    print("\n| clips | point speed p50/p95/p99 [m/s] | joint speed p50/p95/p99 [rad/s] |")
    print("|---|---|---|")
    q = (50, 95, 99)
    for name, clips in [("real (CMU, shared humanoid)", real), ("synthetic, all", allc)] + [
        (f"synthetic, {k}", v) for k, v in synth.items()
    ]:
        p, w = speeds(clips)
        print(
            f"| {name} | {'/'.join(f'{x:.2f}' for x in np.percentile(p, q))} | "
            f"{'/'.join(f'{x:.2f}' for x in np.percentile(w, q))} |"
        )
    sp, sw = speeds(allc)
    print(
        f"\np95 point speed synthetic / real = {np.percentile(sp, 95) / np.percentile(rp, 95):.2f}"
        f"; joint speed {np.percentile(sw, 95) / np.percentile(rw, 95):.2f}"
    )
    bone = max(float(np.ptp(np.linalg.norm(c.bone_vectors(), axis=-1), axis=0).max())
               for c in allc)  # fmt: skip
    print(f"max bone-length spread over synthetic clips: {bone:.1e} m")
    print(
        "floor penetration [mm] (MuJoCo contact distance): deepest per clip p50/p90/max; "
        "per frame in contact (30 fps) p50/p90/p99"
    )
    for kind in dict.fromkeys(r["subject"] for r in rows):
        rs = [r for r in rows if r["subject"] == kind]
        pen = np.array([r["penetration_mm"] for r in rs])
        per = np.concatenate([np.asarray(r.get("contact_penetration_mm", [])) for r in rs])
        per = per[per > 0]
        steady = "/".join(f"{x:.1f}" for x in np.percentile(per, (50, 90, 99))) if per.size else "-"
        print(
            f"  {kind}: deepest {'/'.join(f'{x:.0f}' for x in np.percentile(pen, (50, 90, 100)))}"
            f"; per frame {steady}"
        )

    # the physics room's residual against the recorded help (assistance + pushes), per frame
    print(
        "\n| clips | n | corr (median) | residual, no help [BW] (frames) | residual / help, "
        "helped [BW] | residual - help p95 [BW] (median) | residual lying [BW] (frames) |"
    )
    print("|---|---|---|---|---|---|---|")
    audits = {}
    for r in rows:
        audits[r["file"]] = assistance_audit(load_npz(Path(args.synth) / r["file"]), r)
    groups = [(k, [r for r in rows if r["subject"] == k]) for k in dict.fromkeys(
        r["subject"] for r in rows)]  # fmt: skip
    groups.insert(1, ("track, MPJPE < 50 mm", [r for r in rows if r["subject"] == "track"
                                              and r["tracking_mpjpe_mm"] < 50]))  # fmt: skip
    for name, rs in groups:
        if not rs:
            continue
        a = [audits[r["file"]] for r in rs]
        res = np.concatenate([x["residual"] for x in a])
        hlp = np.concatenate([x["help"] for x in a])
        quiet = np.concatenate([x["quiet"] for x in a])
        up = np.concatenate([~x["lying"] for x in a]) & ~quiet
        inner = np.concatenate([np.arange(len(x["residual"])) for x in a])
        n = np.concatenate([np.full(len(x["residual"]), len(x["residual"])) for x in a])
        inner = (inner >= 4) & (inner < n - 4)
        helped, lying = up & inner, np.concatenate([x["lying"] for x in a]) & inner
        corr = (
            np.nanmedian([x["corr"] for x in a])
            if any(np.isfinite(x["corr"]) for x in a)
            else np.nan
        )
        qtxt = f"{res[quiet].mean():.3f} ({quiet.sum()})" if quiet.any() else "- (0)"
        htxt = f"{res[helped].mean():.3f} / {hlp[helped].mean():.3f}" if helped.any() else "-"
        ltxt = f"{res[lying].mean():.2f} ({lying.sum()})" if lying.any() else "- (0)"
        exc = np.median([x["excess_bw_p95"] for x in a])
        print(f"| {name} | {len(rs)} | {corr:.2f} | {qtxt} | {htxt} | {exc:.2f} | {ltxt} |")

    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
        for name, (p, w) in [("real", (rp, rw))] + [(k, speeds(v)) for k, v in synth.items()]:
            for a, x in zip(ax, (p, w), strict=True):
                xs = np.sort(x)
                a.plot(xs, 1 - np.arange(len(xs)) / len(xs), label=name)
        for a, t in zip(ax, ("point speed [m/s]", "hinge angular speed [rad/s]"), strict=True):
            a.set_xlabel(t)
            a.set_yscale("log")
            a.set_ylim(1e-3, 1)
            a.grid(alpha=0.3)
        ax[0].set_ylabel("fraction above")
        ax[0].legend()
        fig.tight_layout()
        Path(args.plot).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.plot, dpi=110)
        print(f"wrote {args.plot}")

    # no help at all: every trial's first 1.5 s tracked with the assistance off (frames while the
    # root stays within 10 cm of its reference height), audited the same way
    model = sim_model(canonical_skeleton())
    skeleton = canonical_skeleton()
    quiet, worst = [], []
    for t in find_trials(args.cmu):
        ref = on_floor(model, trial_qpos(t.asf, t.amc))[:180]
        if len(ref) < 60:
            continue
        r = track(model, ref, assist_limit=0.0)
        clip = simulated_clip(model, skeleton, r.qpos, r.qvel, 30.0, t.name)
        a = assistance_audit(clip, {"generation": {"scale": 1.0}, "assistance": r.assistance})
        upright = np.abs(r.qpos[:, 2] - ref[::4, 2]) < 0.1
        res = a["residual"][a["quiet"] & upright]
        quiet.append(res)
        worst.append((float(res.mean()) if res.size else np.nan, t.name))
    pooled = np.concatenate(quiet)
    worst = sorted(w for w in worst if np.isfinite(w[0]))[-3:]
    print(
        f"\nno help (assistance off, first 1.5 s of {len(quiet)} trials, upright frames): "
        f"residual {pooled.mean():.3f} BW mean, p50/p90/p99 "
        f"{'/'.join(f'{x:.3f}' for x in np.percentile(pooled, (50, 90, 99)))} ({pooled.size} "
        f"frames); worst trials (mean): {', '.join(f'{n} {m:.2f}' for m, n in worst)}"
    )

    # the control loop alone (mj_step + controller), one core: a 4 s walk reference, best of 3
    model = sim_model(canonical_skeleton())
    trial = next(t for t in find_trials(args.cmu) if t.name == "02_01")
    ref = on_floor(model, trial_qpos(trial.asf, trial.amc))[:480]
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        track(model, ref, assist_limit=0.5)
        best = min(best, time.perf_counter() - t0)
    print(
        f"\ncontrol loop alone (02_01, {len(ref) / 120:.1f} s, incl. its inverse dynamics): "
        f"{best:.3f} s wall = {len(ref) / 120 / best:.1f}x real time on one core, "
        f"{len(ref) * 4 / best:.0f} physics steps/s"
    )

    # simulation speed: one worker (this process) vs two processes, same tasks
    times = {}
    with tempfile.TemporaryDirectory() as tmp:
        for w in (1, 2):
            t0 = time.perf_counter()
            s = synthesize(args.cmu, Path(tmp) / str(w), args.speed_n, seed=99, workers=w,
                           kinds=("track",), progress=False)  # fmt: skip
            times[w] = time.perf_counter() - t0
            frames = sum(r["frames"] for r in s.written)
        ticks = frames * 4  # 120 Hz control ticks (4 physics steps each) per 30 fps frame
    sim_s = ticks / 120.0
    print(
        f"\n1 worker: {len(s.written)} clips, {sim_s:.1f} simulated s in {times[1]:.1f} s wall "
        f"(incl. ingest and inverse dynamics): {sim_s / times[1]:.1f}x real time, "
        f"{frames / times[1]:.0f} clip frames/s per core; "
        f"2 workers: {times[1] / times[2]:.2f}x speed-up"
    )


if __name__ == "__main__":
    main()
