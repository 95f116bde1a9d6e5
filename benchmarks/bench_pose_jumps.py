"""Euler flips and pose jumps in CMU takes, and what they do to the "true" velocities.

Usage: .venv/bin/python benchmarks/bench_pose_jumps.py [--data ../shared/cmu] [--write]

Per trial, on the subject's own skeleton at 120 Hz: how many (bone, frame) Euler triples
:func:`sim.model.rotations.continuous_euler` re-chose (the file switched to the rotation's twin or
by whole turns), how many source steps hold a pose jump (:func:`sim.motion.velocities.pose_jumps`:
a bone turning faster than 50 rad/s and 3x its neighbouring steps, with its chain - the capture solver's flips)
and which bones, and the largest point speed ``|J q-dot|`` of the 30 fps clip computed three ways
in the same run: the file's angles differenced straight across everything (the plain pipeline),
after the Euler fix only, and as ingest now does (also one-sided beside pose jumps); beside it,
the largest speed of the points' own 120 Hz central differences away from any jump (what the
motion itself reaches). ``--write`` writes ``docs/results/ingest_jumps.md``.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from sim.acclaim.amc import parse_amc  # noqa: E402
from sim.errors import MotionDataError  # noqa: E402
from sim.model.humanoid import subject_model  # noqa: E402
from sim.model.kinematics import point_names  # noqa: E402
from sim.motion.dataset import find_trials  # noqa: E402
from sim.motion.retarget import joint_qpos_addresses, motion_to_qpos  # noqa: E402
from sim.motion.velocities import (  # noqa: E402
    body_rotation_steps,
    kin_related,
    point_kinematics,
    pose_jumps,
    qvel_from_qpos,
)
from sim.paths import default_data_dir  # noqa: E402

SOURCE_FPS, FPS = 120.0, 30.0


def file_qpos(skeleton, motion, model, qpos):
    """``qpos`` with every hinge set to the file's own angle (no continuity fix)."""
    raw = qpos.copy()
    adr = joint_qpos_addresses(model)
    for b in skeleton.bones:
        for k, dof in enumerate(b.dofs):
            a = adr.get(f"{b.name}_{dof}")
            if a is not None:
                raw[:, a] = np.deg2rad(motion.angles[b.name][:, k])
    return raw


def trial_figures(asf, amc) -> dict:
    skeleton, model = subject_model(asf)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a truncated final frame is noted by the reader
        motion = parse_amc(amc, skeleton)
    qpos = motion_to_qpos(skeleton, motion, model)
    raw = file_qpos(skeleton, motion, model, qpos)
    names = point_names(skeleton)
    body = [model.body(n).id for n in names]
    site = [-1 if n == "root" else model.site(f"{n}_end").id for n in names]
    data = mujoco.MjData(model)
    step = int(round(SOURCE_FPS / FPS))
    frames = np.arange(0, len(qpos), step)

    def top_speed(q, across):
        qvel = qvel_from_qpos(model, q, SOURCE_FPS, frames, across_jumps=across)
        v = point_kinematics(model, data, q[frames], qvel, body, site)[1]
        return float(np.linalg.norm(v, axis=-1).max())

    jumps = pose_jumps(body_rotation_steps(model, qpos), SOURCE_FPS, kin_related(model))
    events = jumps.any(axis=1)
    # the motion's own speed: 120 Hz central differences of the points, away from any jump
    pos = point_kinematics(model, data, qpos, np.zeros((len(qpos), model.nv)), body, site)[0]
    fd = np.linalg.norm(pos[2:] - pos[:-2], axis=-1) * SOURCE_FPS / 2
    near = np.zeros(len(qpos), dtype=bool)
    for s in np.flatnonzero(events):
        near[max(s - 1, 0) : s + 3] = True
    return {
        "frames": len(qpos),
        "euler": int((qpos != raw).any(axis=1).sum()),
        "jumps": int(events.sum()),
        "bones": sorted({model.body(b).name for b in np.flatnonzero(jumps.any(axis=0))}),
        "plain": top_speed(raw, True),
        "euler_only": top_speed(qpos, True),
        "now": top_speed(qpos, False),
        "motion": float(fd[~near[1:-1]].max()) if (~near[1:-1]).any() else float("nan"),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--write", action="store_true", help="write docs/results/ingest_jumps.md")
    args = ap.parse_args()
    if args.data is None or not args.data.is_dir():
        sys.exit(f"no CMU folder at {args.data} (pass --data)")
    head = (
        "| trial | source frames | Euler frames re-chosen | pose-jump steps | bones that jump "
        "| max speed, plain (m/s) | Euler fix only | now | motion away from jumps |\n"
        "|---|---:|---:|---:|---|---:|---:|---:|---:|"
    )
    print(head)
    lines, rows = [], []
    for t in find_trials(args.data):
        try:
            r = trial_figures(t.asf, t.amc)
        except MotionDataError as e:
            print(f"{t.amc}: skipped: {e}", file=sys.stderr)
            continue
        rows.append(r)
        bones = ", ".join(r["bones"][:6]) + (" ..." if len(r["bones"]) > 6 else "")
        line = (
            f"| {t.name} | {r['frames']} | {r['euler']} | {r['jumps']} | {bones or '-'} "
            f"| {r['plain']:.1f} | {r['euler_only']:.1f} | {r['now']:.1f} | {r['motion']:.1f} |"
        )
        print(line, flush=True)
        lines.append(line)
    n = len(rows)
    summary = (
        f"\n{n} trials: Euler triples re-chosen in {sum(r['euler'] > 0 for r in rows)}, pose jumps "
        f"in {sum(r['jumps'] > 0 for r in rows)} ({sum(r['jumps'] for r in rows)} source steps of "
        f"{sum(r['frames'] for r in rows)}). Largest point speed over all trials: plain "
        f"{max(r['plain'] for r in rows):.1f} m/s, Euler fix only "
        f"{max(r['euler_only'] for r in rows):.1f}, now {max(r['now'] for r in rows):.1f}; the "
        f"points' own differences away from jumps reach {max(r['motion'] for r in rows):.1f} m/s."
    )
    print(summary)
    if args.write:
        from results import write_results

        notes = (
            "A pose jump is in the rotations (and the points), not in their Euler angles: the "
            "positions keep it; only the velocities beside it are one-sided differences away "
            "from it. 'motion away from jumps' is the fastest any point moves by its own 120 Hz "
            "central difference outside +-2 frames of a jump."
        )
        write_results(
            "ingest_jumps",
            "Euler flips and pose jumps in CMU takes",
            head + "\n" + "\n".join(lines) + "\n" + summary,
            command="python benchmarks/bench_pose_jumps.py --write",
            notes=notes,
        )


if __name__ == "__main__":
    main()
