"""Synthetic clips: what they are (physical share, speeds, skating, contacts) and how fast they come.

Usage::

    python benchmarks/bench_synth.py --data ../shared/cmu [--n 16] [--workers 1] [--no-speed]
    python benchmarks/bench_synth.py --data ../shared/cmu --samples 64 [--n 60] [--kinds track fall]
    python benchmarks/bench_synth.py --data ../shared/cmu --controller plain [--audit]

Quality (deterministic for a seed, unaffected by machine load): ``synthesize`` writes ``--n``
clips of the default mix with synth's default controller (the sampler at its default count, no
assistance) into a temporary folder (or ``--synth DIR`` reads a folder written by
``sidql synth``); per kind the tracking error, falls, root height after a fall, self- and floor
penetration and the share of *physical* clips (mean root assistance, force and torque, within
``PHYSICAL_BUDGET``); point and hinge speed percentiles of the real trials (on the shared
humanoid, 30 fps) and of the synthetic clips, all, per kind, not fallen and physical only, with
their p95 ratio to the real trials'; foot skating in contact, the same estimator
(``sim.physics``: ground and contact labels from the points) on real and synthetic clips; the
targets among the clips that do not fall (p95 point speed >= 1.5x the real trials', skating no
worse); and how many clips' episodes replay bit for bit (``sim.simulate.episode.replay``).
Written to ``docs/results/synth.md`` (and with ``--plot`` the speed distributions).

Speed (ratios against baselines measured in the same run): the control loop alone (a 4 s real
reference, torque limits and self-collision on, its inverse dynamics included) in simulated
seconds per wall second on one core, against the 20x target; end to end (AMC parsing, floor
estimate, simulation, kinematics) one worker vs two on the same tasks, against the 1.7x target.
Written to ``docs/results/synth_speed.md`` with the machine's load: timings on a shared machine
are noisy, re-run them on a quiet one.

``--audit``: the physics room's residual force against the recorded help per kind
(``sim.simulate.audit``), written to ``docs/results/synth_audit.md``.

``--samples N`` (another count) or ``--controller C`` (another controller): the same figures
for that controller, written to ``docs/results/synth_sampled.md`` or ``synth_<C>.md``.
``--gain-choice SHARE``: the sampler's share of candidates on the stiff gains (another than
synth's default writes ``synth_gains.md``); ``--against SHARE [...]``: the same tasks made in
the same run with those shares too (0: the body's gains alone), and a table of each beside
the run's (clips up, the targets' figures, tracking error global and root-relative, the
ticks on the stiff gains, CPU seconds per simulated second of this process). The
speed timings always time the plain tracker (``--no-speed`` skips them); the audit compares
against recorded help, which only the plain tracker asked for help gives.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from results import write_results  # noqa: E402

from sim.model.humanoid import canonical_skeleton  # noqa: E402
from sim.motion.clip import load_extra, load_npz  # noqa: E402
from sim.motion.dataset import find_trials  # noqa: E402
from sim.motion.ingest import load_motion  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402
from sim.physics.contacts import trial_contacts  # noqa: E402
from sim.physics.ground import estimate_ground  # noqa: E402
from sim.simulate.controller import track  # noqa: E402
from sim.simulate.dataset import synthesize  # noqa: E402
from sim.simulate.episode import array_text, replay  # noqa: E402
from sim.simulate.generate import (  # noqa: E402
    ALL_KINDS,
    CLIP_SECONDS,
    KINDS,
    PHYSICAL_BUDGET,
    SYNTH_CONTACT_REFERENCE,
    SYNTH_CONTROLLERS,
    SYNTH_DEFAULT_CONTROLLER,
    SYNTH_DRIFT,
    SYNTH_FOOT_LOCK,
    SYNTH_GAIN_CHOICE,
    SYNTH_LEAN,
    SYNTH_TERRAIN,
    synth_controller,
)
from sim.simulate.model import G, sim_model  # noqa: E402
from sim.simulate.reference import on_floor, trial_qpos  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
Q = (50, 95, 99)
SPEED_TARGET = 20.0  # simulated seconds per wall second on one core
SCALING_TARGET = 1.7  # 2 workers over 1
SPEED_RATIO_TARGET = 1.5  # p95 point speed of the clips that do not fall over the real trials'
#: the targets' figures as the pages last measured them before this version (their rows stay
#: beside the new ones), per page: (what ran, date, command, clips, not fallen, p95 ratio,
#: skating, real's)
EARLIER = {
    "synth": [
        ("the default then: plain tracker, no assistance", "2026-11-26",
         "`python benchmarks/bench_synth.py --data /work/shared/cmu --n 40 --workers 1 "
         "--no-speed`", 39, 0, float("nan"), float("nan"), 235),
        ("sampler, 64 samples, track only", "2026-11-26",
         "`python benchmarks/bench_synth.py --data /work/shared/cmu --samples 64 --n 14 --kinds "
         "track --workers 2`", 13, 9, 1.15, 413, 235),
        ("sampler, 32 samples (the new default), 4 s clips, the windows and warps of then",
         "2026-11-26", "`python benchmarks/bench_synth.py --data /work/shared/cmu --n 16 "
         "--workers 1 --no-speed --keep /tmp/synthx/base`", 15, 1, 0.88, 669, 235),
        ("sampler, 32 samples, 2 s clips, 1-1.6x, the fastest windows, 0-2 pushes per track "
         "clip", "2026-11-26", "`python benchmarks/bench_synth.py --data /work/shared/cmu --n 20 "
         "--workers 1 --no-speed --keep /tmp/synthx/new`", 20, 9, 1.25, 430, 235),
        ("sampler, 32 samples, no balance feedback, 2 s clips, 0-1 pushes per track clip",
         "2026-11-26", "`python benchmarks/bench_synth.py --data /work/shared/cmu --n 20 "
         "--workers 1 --no-speed --keep /tmp/synthx/push2`", 20, 9, 1.19, 409, 235),
    ],
    "synth_sampled": [
        ("sampler, 64 samples", "2026-11-25", "`python benchmarks/bench_synth.py --data "
         "../shared/cmu --samples 64 --n 60 --kinds track fall --workers 2`", 58, 26, 1.17, 291,
         235),
    ],
}  # fmt: skip


def speeds(clips) -> tuple[np.ndarray, np.ndarray]:
    """Point speeds [m/s] (root excluded) and hinge angular speeds [rad/s], pooled."""
    if not clips:
        return np.zeros(0), np.zeros(0)
    p = np.concatenate([np.linalg.norm(c.velocities[:, 1:], axis=-1).ravel() for c in clips])
    w = np.concatenate([np.abs(c.qvel[:, 6:]).ravel() for c in clips])
    return p, w


def skating(clips) -> tuple[float, int]:
    """Mean horizontal speed [mm/s] of each foot's lowest sole point while it is labelled in
    contact, and the sample count: ``sim.physics``'s ground and contact labels from each clip's
    own points."""
    v = []
    for c in clips:
        ground = estimate_ground(c.positions, c.names, c.fps)
        contacts = trial_contacts(c.positions, c.names, c.fps, ground, c.velocities)
        v.append(contacts.foot_speed[contacts.contact])
    v = np.concatenate(v) if v else np.zeros(0)
    return (1e3 * float(v.mean()) if v.size else float("nan")), int(v.size)


def _until(clip, frames: int):
    """``clip``'s first ``frames`` frames (at least 3: the skating estimator's differences)."""
    return clip.slice(0, max(3, min(frames, clip.n_frames)))


def replays(folder: Path, rows: list[dict]) -> str:
    """One line: how many clips' episodes replay bit for bit (``sim.simulate.episode.replay``
    of their stored actions, gains and wrenches from their first state), and how many episodes end
    in a fall (their last step is a termination)."""
    ok, falls = replay_counts(folder, rows)
    return (
        f"Episodes (actions at the control rate, 120 Hz, frame_skip 4): {ok} of {len(rows)} "
        f"replay every stored state bit for bit from their first state; {falls} end in a fall "
        "(terminated), the others at the time limit (truncated)."
    )


def replay_counts(folder: Path, rows: list[dict]) -> tuple[int, int]:
    """How many of ``rows``' episodes replay every stored state bit for bit, and how many end
    in a fall."""
    ok = falls = 0
    for r in rows:
        lab = load_extra(folder / r["file"], "sim_")
        q, v = replay(array_text(lab["sim_mjcf"]), lab["sim_initial_state"], lab["sim_actions"],
                      lab["sim_xfrc_applied"], lab["sim_qfrc_applied"],
                      int(lab["sim_frame_skip"]), lab.get("sim_actuator_gains"))  # fmt: skip
        ok += bool(
            np.array_equal(q, lab["sim_tick_qpos"]) and np.array_equal(v, lab["sim_tick_qvel"])
        )
        falls += int(lab["sim_fall_tick"]) > 0
    return ok, falls


def make(args, folder: Path, options: list, share: float) -> tuple[str, float]:
    """Synthesize ``args.n`` clips into ``folder`` with the sampler's gain choice ``share``;
    returns the cost line and the CPU seconds per simulated second (this process, one
    worker; NaN with more)."""
    controller, samples = synth_controller(args.samples, args.controller)
    t0, c0 = time.perf_counter(), time.process_time()
    s = synthesize(args.cmu, folder, args.n, seed=args.seed, workers=args.workers,
                   kinds=tuple(args.kinds), samples=samples, controller=controller,
                   seconds=args.seconds, progress=False, drift=options[0],
                   contact_reference=options[1], lean=options[2], foot_lock=options[3],
                   terrain=options[4],
                   gain_choice=share if controller == "sampling" else None)  # fmt: skip
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    simulated = sum(r["frames"] for r in s.written) / 30.0
    per_s = cpu / simulated if args.workers == 1 else float("nan")
    stepped = [r for r in s.written if r["generation"].get("scene", {}).get("boxes")]
    cost = (
        f"Generation: {len(s.written)} clips, {simulated:.0f} simulated s in {wall:.0f} s "
        f"on {args.workers} worker(s): {simulated / wall / args.workers:.2f} simulated s "
        "per wall s per worker"
        + (f"; {per_s:.1f} CPU s per simulated s (this process)" if args.workers == 1 else "")
        + f"; {len(stepped)} clips in a scene with inferred steps"
        + (f" ({', '.join(sorted({Path(r['amc']).stem for r in stepped}))})." if stepped else ".")
    )  # fmt: skip
    return cost, per_s


def stiff_share(folder: Path, rows: list[dict]) -> float:
    """The share of the control ticks whose gains are not the MJCF's (the stiff set)."""
    on = total = 0
    for r in rows:
        lab = load_extra(folder / r["file"], "sim_")
        g = lab.get("sim_actuator_gains")
        if g is None:
            total += len(lab["sim_actions"])
            continue
        body = mujoco.MjModel.from_xml_string(array_text(lab["sim_mjcf"]))
        on += int(np.sum(np.any(g[:, 0] != body.actuator_gainprm[:, 0], axis=1)))
        total += len(g)
    return on / max(total, 1)


def comparison(runs: list[tuple[str, Path, dict, float]]) -> str:
    """The table of runs of the same tasks: (name, folder, quality figures, CPU per s)."""
    lines = [
        "| gain choice (share on the stiff gains) | clips | not fallen | p95 point speed / "
        "real's, not fallen | skating in contact, not fallen [mm/s] | tracking error median, "
        "global / root-relative [mm] (not fallen) | ticks on the stiff gains | CPU s per "
        "simulated s | replay bit for bit |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, folder, fig, per_s in runs:
        rows = json.loads((folder / "index.json").read_text())["trials"]
        up = [r for r in rows if not r["fell"]]
        med = lambda key, rs: np.median([r[key] for r in rs]) if rs else float("nan")  # noqa: E731
        f = fig["synthetic, not fallen"]
        lines.append(
            f"| {name} | {len(rows)} | {len(up)} | {f['p95_ratio']:.2f} | {f['skate_mm_s']:.0f} "
            f"| {med('tracking_mpjpe_mm', rows):.0f} / {med('tracking_local_mm', rows):.0f} "
            f"({med('tracking_mpjpe_mm', up):.0f} / {med('tracking_local_mm', up):.0f}) "
            f"| {stiff_share(folder, rows):.2f} | {per_s:.2f} "
            f"| {replay_counts(folder, rows)[0]} of {len(rows)} |"
        )
    return "\n".join(lines)


def pct(x: np.ndarray) -> str:
    return "/".join(f"{v:.2f}" for v in np.percentile(x, Q)) if x.size else "-"


def quality(
    cmu: str,
    folder: Path,
    plot: str | None,
    label: str = "`synthesize`",
    earlier=None,
    run: str = "",
) -> tuple[str, dict]:
    index = json.loads((folder / "index.json").read_text())
    rows = index["trials"]
    clips = {r["file"]: load_npz(folder / r["file"]) for r in rows}
    kinds = list(dict.fromkeys(r["subject"] for r in rows))
    lines = [
        f"{len(rows)} clips of {index['synthetic']['seconds']:g} s ({label}, seed "
        f"{index['synthetic']['seed']}); physical: mean root assistance force <= "
        f"{PHYSICAL_BUDGET} body weight and torque <= {PHYSICAL_BUDGET} body weight x 1 m.",
        "",
        "| kind | clips | physical | fell | physical, not fallen | tracking MPJPE [mm] median "
        "| mean assistance force [BW] / torque [BW m] | root height 0.5 s after a fall, max [m] "
        "| self-penetration, deepest per clip p50/max [mm] | floor penetration in contact "
        "p50/p99 [mm] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for kind in [*kinds, "all"]:
        rs = [r for r in rows if kind in ("all", r["subject"])]
        after = [
            float(clips[r["file"]].qpos[r["fall_frame"] + 15 :, 2].max())
            for r in rs
            if r["fell"] and r["fall_frame"] + 15 < r["frames"]
        ]
        pen = np.concatenate(
            [load_extra(folder / r["file"], "sim_")["sim_contact_penetration"] for r in rs]
        )
        pen = 1e3 * pen[pen > 0]
        sp = [r["self_penetration_mm"] for r in rs]
        lines.append(
            f"| {kind} | {len(rs)} | {sum(r['physical'] for r in rs)} "
            f"| {sum(r['fell'] for r in rs)} | {sum(r['physical'] and not r['fell'] for r in rs)} "
            f"| {np.median([r['tracking_mpjpe_mm'] for r in rs]):.0f} "
            f"| {np.mean([r['mean_assistance'] for r in rs]):.3f} / "
            f"{np.mean([r['mean_assist_torque'] for r in rs]):.3f} "
            f"| {max(after) if after else float('nan'):.2f} "
            f"| {np.median(sp):.1f}/{max(sp):.1f} "
            f"| {np.percentile(pen, 50):.1f}/{np.percentile(pen, 99):.1f} |"
        )
    warped = [r for r in rows if r["subject"] in ("track", "fall")]
    if warped:  # does the body keep up with faster motion?
        up = [r["generation"]["speed"] for r in warped if not r["fell"]]
        down = [r["generation"]["speed"] for r in warped if r["fell"]]
        mean = lambda x: f"{np.mean(x):.2f}x ({len(x)})" if x else "- (0)"  # noqa: E731
        lines += [
            "",
            f"Time warp of the track and fall clips, mean: {mean(up)} among those that stayed "
            f"up, {mean(down)} among those that fell.",
        ]
    real = [load_motion(t.asf, t.amc, skeleton="humanoid") for t in find_trials(cmu)]
    rp, rw = speeds(real)
    groups = [("real: CMU trials, shared humanoid, 30 fps", real)]
    groups.append(("synthetic, all", list(clips.values())))
    groups += [(f"synthetic, {k}", [clips[r["file"]] for r in rows if r["subject"] == k])
               for k in kinds]  # fmt: skip
    groups.append(("synthetic, not fallen", [clips[r["file"]] for r in rows if not r["fell"]]))
    phys = [r for r in rows if r["physical"]]
    groups.append(("synthetic, physical", [clips[r["file"]] for r in phys]))
    groups.append(
        ("synthetic, physical and not fallen", [clips[r["file"]] for r in phys if not r["fell"]])
    )
    lines += [
        "",
        "| clips | n | point speed p50/p95/p99 [m/s] | p95 / real | hinge speed p50/p95/p99 "
        "[rad/s] | skating in contact [mm/s] (samples) |",
        "|---|---|---|---|---|---|",
    ]
    figures = {}
    for name, cs in groups:
        p, w = speeds(cs)
        sk, n_sk = skating(cs)
        ratio = np.percentile(p, 95) / np.percentile(rp, 95) if p.size else float("nan")
        figures[name] = {"p95_ratio": float(ratio), "skate_mm_s": sk}
        lines.append(
            f"| {name} | {len(cs)} | {pct(p)} | {ratio:.2f} | {pct(w)} | {sk:.0f} ({n_sk}) |"
        )
    before = [clips[r["file"]] for r in rows]
    before = [_until(c, r["fall_frame"] if r["fell"] else c.n_frames) for c, r in
              zip(before, rows, strict=True)]  # fmt: skip
    p, w = speeds(before)
    sk, n_sk = skating(before)
    ratio = np.percentile(p, 95) / np.percentile(rp, 95) if p.size else float("nan")
    lines.append(f"| synthetic, every clip up to its fall (an episode's steps) | {len(before)} "
                 f"| {pct(p)} | {ratio:.2f} | {pct(w)} | {sk:.0f} ({n_sk}) |")  # fmt: skip
    up, real_fig = figures["synthetic, not fallen"], figures[groups[0][0]]
    verdict = lambda ok: "met" if ok else "**not met**"  # noqa: E731
    n_up = sum(not r["fell"] for r in rows)
    lines += [
        "",
        "| run | clips | not fallen | p95 point speed / real's, not fallen | skating in contact, "
        "not fallen [mm/s] | real trials' [mm/s] |",
        "|---|---|---|---|---|---|",
    ]
    for what, date, command, n, n_up0, ratio0, skate0, real0 in earlier or ():
        lines.append(f"| earlier, {what} ({date}: {command}) | {n} | {n_up0} | {ratio0:.2f} "
                     f"| {skate0:.0f} | {real0:.0f} |")  # fmt: skip
    lines += [
        f"| this run ({run}) | {len(rows)} | {n_up} | {up['p95_ratio']:.2f} "
        f"| {up['skate_mm_s']:.0f} "
        f"| {real_fig['skate_mm_s']:.0f} |",
        f"| target | | | >= {SPEED_RATIO_TARGET:g} | <= the real trials' | |",
        "",
        f"Targets, among the clips that do not fall: p95 point speed {up['p95_ratio']:.2f}x the "
        f"real trials' (target >= {SPEED_RATIO_TARGET:g}x: "
        f"{verdict(up['p95_ratio'] >= SPEED_RATIO_TARGET)}); foot skating in contact "
        f"{up['skate_mm_s']:.0f} mm/s against the real trials' {real_fig['skate_mm_s']:.0f} "
        f"(target <= real: {verdict(up['skate_mm_s'] <= real_fig['skate_mm_s'])}).",
        "",
        replays(folder, rows),
    ]
    if plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
        for name, cs in groups:
            if not cs:
                continue
            for a, x in zip(ax, speeds(cs), strict=True):
                xs = np.sort(x)
                a.plot(xs, 1 - np.arange(len(xs)) / len(xs), label=name.split(":")[0])
        for a, t in zip(ax, ("point speed [m/s]", "hinge angular speed [rad/s]"), strict=True):
            a.set_xlabel(t)
            a.set_yscale("log")
            a.set_ylim(1e-3, 1)
            a.grid(alpha=0.3)
        ax[0].set_ylabel("fraction above")
        ax[0].legend(fontsize=7)
        fig.tight_layout()
        Path(plot).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(plot, dpi=110)
        lines += ["", f"![speed distributions]({Path('..') / Path(plot).name})"]
    return "\n".join(lines), figures


def audit(folder: Path) -> str:
    from sim.simulate.audit import assistance_audit

    index = json.loads((folder / "index.json").read_text())
    rows = index["trials"]
    out = [
        "| clips | n | corr. (median) | residual, no help [BW] (frames) | residual / help, "
        "helped [BW] | residual - help p95 [BW] (median) | residual lying [BW] (frames) |",
        "|---|---|---|---|---|---|---|",
    ]
    audits = {}
    for r in rows:
        clip = load_npz(folder / r["file"])
        wrench = load_extra(folder / r["file"], "sim_")["sim_assist_wrench"]
        weight = 75.0 * r["generation"]["scale"] ** 3 * G
        record = {**r, "assistance": np.linalg.norm(wrench[:, :3], axis=1) / weight}
        audits[r["file"]] = assistance_audit(clip, record)
    groups = [(k, [r for r in rows if r["subject"] == k])
              for k in dict.fromkeys(r["subject"] for r in rows)]  # fmt: skip
    groups.insert(1, ("track, MPJPE < 50 mm", [r for r in rows if r["subject"] == "track"
                                              and r["tracking_mpjpe_mm"] < 50]))  # fmt: skip
    for name, rs in groups:
        if not rs:
            continue
        a = [audits[r["file"]] for r in rs]
        res = np.concatenate([x["residual"] for x in a])
        hlp = np.concatenate([x["help"] for x in a])
        quiet = np.concatenate([x["quiet"] for x in a])
        lying = np.concatenate([x["lying"] for x in a])
        inner = np.concatenate([(np.arange(len(x["residual"])) >= 4)
                                & (np.arange(len(x["residual"])) < len(x["residual"]) - 4)
                                for x in a])  # fmt: skip
        helped, lying = ~lying & ~quiet & inner, lying & inner
        corr = np.nanmedian([x["corr"] for x in a]) if any(
            np.isfinite(x["corr"]) for x in a) else np.nan  # fmt: skip
        q = f"{res[quiet].mean():.3f} ({quiet.sum()})" if quiet.any() else "- (0)"
        h = f"{res[helped].mean():.3f} / {hlp[helped].mean():.3f}" if helped.any() else "-"
        ly = f"{res[lying].mean():.2f} ({lying.sum()})" if lying.any() else "- (0)"
        exc = np.median([x["excess_bw_p95"] for x in a])
        out.append(f"| {name} | {len(rs)} | {corr:.2f} | {q} | {h} | {exc:.2f} | {ly} |")
    return "\n".join(out)


def speed(cmu: str, clips: int, seed: int) -> tuple[str, dict]:
    model = sim_model(canonical_skeleton())
    trials = find_trials(cmu)
    trial = next((t for t in trials if t.name == "02_01"), trials[0])
    ref = on_floor(model, trial_qpos(trial.asf, trial.amc))[:480]
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        track(model, ref, assist_limit=0.5)
        best = min(best, time.perf_counter() - t0)
    loop = len(ref) / 120.0 / best
    times, frames = {}, 0
    with tempfile.TemporaryDirectory() as tmp:
        for w in (1, 2, 1, 2):  # interleaved, best of two each: load changes between runs
            t0 = time.perf_counter()
            s = synthesize(cmu, Path(tmp) / f"{w}_{len(times)}", clips, seed=seed, workers=w,
                           kinds=("track",), controller="plain", progress=False)  # fmt: skip
            times[w] = min(times.get(w, np.inf), time.perf_counter() - t0)
            frames = sum(r["frames"] for r in s.written)
    sim_s = frames / 30.0
    end_to_end = sim_s / times[1]
    scaling = times[1] / times[2]
    text = "\n".join([
        "| measure | value | target |",
        "|---|---|---|",
        f"| control loop alone ({trial.name}, {len(ref) / 120:.1f} s, torque limits, "
        f"self-collision, inverse dynamics incl.): simulated s per wall s, one core "
        f"| **{loop:.1f}x** | >= {SPEED_TARGET:g}x |",
        f"| end to end, 1 worker ({len(s.written)} track clips, plain tracker, {sim_s:.0f} simulated s, parsing "
        f"and kinematics incl.): simulated s per wall s | {end_to_end:.1f}x | - |",
        f"| 2 workers over 1 (same tasks, best of two runs each) | **{scaling:.2f}x** "
        f"| >= {SCALING_TARGET:g}x |",
    ])  # fmt: skip
    return text, {"loop_x": loop, "end_to_end_x": end_to_end, "scaling": scaling}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--data", "--cmu", dest="cmu", default=default_data_dir(),
        help="folder of CMU trials (default: $SIDQL_DATA or ../shared/cmu)",
    )  # fmt: skip
    ap.add_argument("--synth", default=None, help="a folder written by sidql synth (else made)")
    ap.add_argument("--keep", default=None, metavar="DIR",
                    help="make the clips in DIR (kept) instead of a temporary folder")  # fmt: skip
    ap.add_argument("--n", type=int, default=90, help="clips to synthesize for the figures")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2, help="workers for the figures' clips")
    ap.add_argument("--speed-clips", type=int, default=16, help="clips per worker-count timing")
    ap.add_argument("--plot", default=str(REPO / "docs" / "synth_speeds.png"))
    ap.add_argument("--audit", action="store_true", help="also the physics room's audit")
    ap.add_argument(
        "--samples", type=int, default=0,
        help="the sampler's rollouts per window (default: its default count); another count "
        "writes synth_sampled.md, without speed timings",
    )  # fmt: skip
    ap.add_argument("--kinds", nargs="+", default=list(KINDS), choices=ALL_KINDS)
    ap.add_argument("--controller", default=None, choices=SYNTH_CONTROLLERS,
                    help="controller of the real-motion kinds (default: synth's, "
                    f"{SYNTH_DEFAULT_CONTROLLER}); another writes synth_<controller>.md")  # fmt: skip
    for flag, default, what in (
        ("drift", SYNTH_DRIFT, "the sampler's balance feedback with eval's drift lead"),
        ("contact-reference", SYNTH_CONTACT_REFERENCE, "the sampler tracks the "
         "contact-consistent reference (else lifted 1 cm)"),
        ("lean", SYNTH_LEAN, "the body stepped lean (the same motion, cheaper steps)"),
        ("foot-lock", SYNTH_FOOT_LOCK, "the contact-consistent reference foot-locked (its "
         "stance soles held still on the floor by the legs)"),
        ("terrain", SYNTH_TERRAIN, "the real-motion kinds in the scene inferred from their "
         "trials (--flat-floor: --no-terrain)"),
    ):  # fmt: skip
        ap.add_argument(f"--{flag}", action=argparse.BooleanOptionalAction, default=None,
                        help=f"{what} (default: synth's, {default}); another than synth's "
                        "default writes synth_variant.md")  # fmt: skip
    ap.add_argument("--flat-floor", dest="terrain", action="store_false",
                    help="as synth --flat-floor: --no-terrain")  # fmt: skip
    ap.add_argument("--gain-choice", type=float, default=SYNTH_GAIN_CHOICE, metavar="SHARE",
                    help="the sampler's share of candidates on the stiff gains (default: "
                    f"synth's, {SYNTH_GAIN_CHOICE:g}); another writes synth_gains.md")  # fmt: skip
    ap.add_argument("--against", type=float, nargs="+", default=[], metavar="SHARE",
                    help="also make the same tasks with these gain-choice shares in this run "
                    "(0: the body's gains alone) and compare (one worker: CPU per simulated s)")  # fmt: skip
    ap.add_argument("--seconds", type=float, default=CLIP_SECONDS, help="clip length [s]")
    ap.add_argument("--no-speed", action="store_true",
                    help="skip the speed timings (synth_speed.md stays as it is)")  # fmt: skip
    ap.add_argument("--no-write", action="store_true", help="print only")
    args = ap.parse_args()
    command = "python benchmarks/bench_synth.py " + " ".join(sys.argv[1:])

    controller, samples = synth_controller(args.samples, args.controller)
    chosen = (args.drift, args.contact_reference, args.lean, args.foot_lock, args.terrain)
    defaults = (SYNTH_DRIFT, SYNTH_CONTACT_REFERENCE, SYNTH_LEAN, SYNTH_FOOT_LOCK, SYNTH_TERRAIN)
    options = [d if v is None else v for v, d in zip(chosen, defaults, strict=True)]
    page = ("synth_variant" if options != list(defaults)
            else "synth_gains" if args.gain_choice != SYNTH_GAIN_CHOICE
            else "synth" if (controller, samples) == synth_controller()
            else "synth_sampled" if controller == "sampling" else f"synth_{controller}")  # fmt: skip
    run = controller + (f", {samples} samples" if samples else "")
    if controller == "sampling":
        run += ", " + ", ".join(w if on else f"no {w}" for w, on in zip(
            ("drift lead", "contact-consistent reference", "lean body", "foot lock",
             "inferred scene"), options, strict=True))  # fmt: skip
        run += (f", gain choice {args.gain_choice:g} on the stiff gains" if args.gain_choice
                else ", the body's gains alone")  # fmt: skip
    label = f"`synthesize`: {run}"
    plot = args.plot if page == "synth" else args.plot.replace(".png", f"_{page[6:]}.png")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.synth or args.keep or Path(tmp) / "synth")
        others = []
        if not args.synth:
            for share in args.against:  # the same tasks with other shares first, then this run's
                other = Path(tmp) / f"against_{share:g}"
                _, per_s = make(args, other, options, share)
                others.append((share, other, per_s))
            cost, per_s = make(args, folder, options, args.gain_choice)
            print(cost)
        table, figures = quality(args.cmu, folder, None if args.no_write else plot, label,
                                 EARLIER.get(page), run)  # fmt: skip
        if not args.synth:
            table = cost + "\n\n" + table
        if others:
            runs = [(f"{args.gain_choice:g} (this run)", folder, figures, per_s)]
            for share, other, cpu_s in others:
                runs.append((f"{share:g}", other, quality(args.cmu, other, None)[1], cpu_s))
            table += ("\n\nThe same tasks with other gain choices, made in this run (load "
                      f"{os.getloadavg()[0]:.1f} at the end):\n\n" + comparison(runs))  # fmt: skip
        print(table)
        audit_table = audit(folder) if args.audit else None
        if audit_table:
            print(audit_table)
    if not args.no_write:
        title = ("Synthetic clips: physical share, speeds, skating, contacts" if page == "synth"
                 else f"Synthetic clips tracked by the {run} controller")  # fmt: skip
        if page in ("synth_variant", "synth_gains"):
            args.no_speed = True  # the speed timings time the default's plain tracker
        write_results(page, title, table, command)
    if args.no_speed:
        return
    speed_table, timing = speed(args.cmu, args.speed_clips, args.seed + 99)
    print(speed_table)
    if args.no_write:
        return
    write_results(
        "synth_speed", "Synthetic clips: simulation speed and 1 -> 2 worker scaling",
        speed_table, command,
        notes="Timings depend on the machine and its load (above): ratios are measured in one "
        "run; re-run on a quiet machine for figures to quote.",
    )  # fmt: skip
    if audit_table:
        write_results(
            "synth_audit", "Synthetic clips: the physics room's residual against recorded help",
            audit_table, command,
        )  # fmt: skip


if __name__ == "__main__":
    main()
