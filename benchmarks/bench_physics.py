"""Physics of one 60-frame clip for one method (IK fit + inverse dynamics) on one core, and the
wall time of ``sidql eval --physics``.

Usage: .venv/bin/python benchmarks/bench_physics.py [--data ../shared/cmu] [--repeats 5] [--eval]

Part 1 (one core: the process is pinned to CPU 0 and BLAS to one thread): a real CMU clip (02_01,
clip 0, 30 fps, 23 protocol points), its uniform W=10 spherical Hermite reconstruction, and three
ways to get that reconstruction's physics, each followed by the same inverse dynamics
(``sim.physics.dynamics``):

* ours: ``sim.physics.ik.HumanoidIK`` (damped least squares on MuJoCo Jacobians, warm-started frame
  to frame) - also timed as the whole ``PhysicsJob.analyse`` (contacts and capsule replay too);
* naive: the same fit started cold every frame (rigid Kabsch placement of the zero pose);
* mink: ``mink.solve_ik`` with one position ``FrameTask`` per point (daqp QP), warm-started,
  iterated per frame until the step is below 1e-6 or 20 iterations.

Best of ``--repeats``; target (issue 10): <= 0.5 s for ours (fit + dynamics).

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

from sidql.evaluation.evaluate import make_case  # noqa: E402
from sidql.evaluation.report import physics_job, trial_ground  # noqa: E402
from sidql.keyframes.methods import select  # noqa: E402
from sidql.keyframes.reconstructions import reconstruct_series  # noqa: E402
from sidql.keyframes.spherical import POINTS  # noqa: E402
from sim.model.humanoid import subject_model  # noqa: E402
from sim.motion.ingest import load_clips  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402
from sim.physics.dynamics import InverseDynamics  # noqa: E402
from sim.physics.ik import Fit, HumanoidIK  # noqa: E402

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


def part1(data: Path, repeats: int) -> None:
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
    contacts = job.ground_contacts(pts, ground)[3]  # same dynamics work for every fit
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
    t_all, _ = best(lambda: job.analyse(clip, pts, ground), repeats)
    print(f"clip 02_01 #0: {len(pts)} frames, {len(POINTS)} points, nv = {model.nv}; one core")
    print("| IK | fit (s) | dynamics (s) | fit + dynamics (s) | vs ours | mean iterations "
          "| max point error (mm) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    ours = rows[0][1] + rows[0][2]
    for name, tf, td, fit in rows:
        print(
            f"| {name} | {tf:.3f} | {td:.3f} | {tf + td:.3f} | {(tf + td) / ours:.1f}x "
            f"| {fit.iterations.mean():.1f} | {1e3 * fit.error.max():.2f} |"
        )
    print(f"whole PhysicsJob.analyse (IK, contacts, capsule replay, dynamics): {t_all:.3f} s")
    print(
        f"target <= 0.5 s for fit + dynamics: {'met' if ours <= 0.5 else 'NOT met'} ({ours:.3f} s)"
    )


def part2(data: Path) -> None:
    base = [sys.executable, "-m", "sidql.commands.main", "eval", "--data", str(data),
            "--keyframes", "5", "10", "15", "--quiet"]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env.pop(k, None)
    with tempfile.TemporaryDirectory() as d:
        for extra in ([], ["--physics"]):
            t0 = time.perf_counter()
            subprocess.run(base + ["--out", f"{d}/r.json"] + extra, check=True, env=env,
                           stdout=subprocess.DEVNULL, cwd=REPO)  # fmt: skip
            dt = time.perf_counter() - t0
            label = "sidql eval --physics" if extra else "sidql eval (baseline)"
            print(f"{label}: {dt:.0f} s ({dt / 60:.1f} min); load average {os.getloadavg()}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--eval", action="store_true", help="also time sidql eval with/without physics")
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    print(f"mujoco {mujoco.__version__}; load average {os.getloadavg()}")
    part1(args.data, args.repeats)
    if args.eval:
        part2(args.data)


if __name__ == "__main__":
    main()
