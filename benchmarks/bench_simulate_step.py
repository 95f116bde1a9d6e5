"""Where a rollout tick of the sampling tracker spends its time, and what ``sim_model(lean=True)``
saves.

Usage::

    python benchmarks/bench_simulate_step.py --data ../shared/cmu [--clips 07_01@0 05_06@240]
        [--samples 28] [--reps 3] [--no-write]

Per clip (2 s of a CMU trial at 120 Hz on the canonical humanoid, body and reference as ``eval
--simulate`` builds them: ``validate.validation_model``, ``ForwardValidation.reference``), the
sampler as ``eval`` runs it (:data:`SEARCH`, ``--samples``) tracks it once; the states of that
run (every control tick, just before its physics steps) are then

* stepped ``SUBSTEPS`` times by the default body and by the lean one in turn, ``--reps`` times
  each, the least CPU time per state kept (robust to a shared machine's load): microseconds per
  physics step, with MuJoCo's own timers per stage, contacts, constraint rows and solver
  iterations;
* handed to the tick's Python parts (balance feedback, fall check, control writes, the check
  for a diverged simulation) at their tick: microseconds per call, likewise.

Then the whole tracking (search and replay) runs on both bodies in turn, ``--reps`` times: CPU
seconds per simulated second, and whether the two give the same motion bit for bit. Written to
``docs/results/simulate_step.md``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from results import machine, write_results  # noqa: E402

from sim.errors import SidqlError  # noqa: E402
from sim.model.humanoid import canonical_skeleton  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402
from sim.simulate.balance import balance_plan, balance_torques  # noqa: E402
from sim.simulate.controller import set_controls  # noqa: E402
from sim.simulate.falls import fall_reference, has_fallen  # noqa: E402
from sim.simulate.feedforward import reference_feedforward  # noqa: E402
from sim.simulate.model import CONTROL_HZ, SUBSTEPS  # noqa: E402
from sim.simulate.reference import trial_qpos  # noqa: E402
from sim.simulate.sampling import sample_track  # noqa: E402
from sim.simulate.tracking import divergences  # noqa: E402
from sim.simulate.validate import (  # noqa: E402
    DEFAULT_BALANCE,
    DEFAULT_NOISE_DEFLECTION,
    ForwardValidation,
    validation_model,
)

BODIES = ("default", "lean")
#: the sampler's search keywords as ``ForwardValidation.run`` passes them
SEARCH = {"balance": DEFAULT_BALANCE, "noise_deflection": DEFAULT_NOISE_DEFLECTION}
STAGES = (  # MuJoCo's timers shown, per physics step
    ("position", "mjTIMER_POSITION"), ("  kinematics", "mjTIMER_POS_KINEMATICS"),
    ("  inertia", "mjTIMER_POS_INERTIA"), ("  collision", "mjTIMER_POS_COLLISION"),
    ("    broad phase", "mjTIMER_COL_BROAD"), ("    narrow phase", "mjTIMER_COL_NARROW"),
    ("  constraint rows", "mjTIMER_POS_MAKE"), ("velocity", "mjTIMER_VELOCITY"),
    ("actuation", "mjTIMER_ACTUATION"), ("constraint solver", "mjTIMER_CONSTRAINT"),
    ("integration", "mjTIMER_ADVANCE"), ("whole step", "mjTIMER_STEP"),
)  # fmt: skip


def clip_reference(data_dir: str, clip: str, model) -> np.ndarray:
    """(240, nq) 2 s of trial ``clip`` (``"07_01@0"``: trial and first frame) at the control
    rate, as ``eval --simulate`` tracks it."""
    trial, start = clip.split("@")
    subject = trial.split("_")[0]
    folder = Path(data_dir) / subject
    qpos = trial_qpos(folder / f"{subject}.asf", folder / f"{trial}.amc")
    n = int(2 * CONTROL_HZ)
    return ForwardValidation(model, ["root"]).reference(qpos[int(start) : int(start) + n], 120.0)


def tick_states(model, ref: np.ndarray, samples: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The sampler's run on ``ref``: (K, state size) its integration states at each tick before
    the physics steps, (K,) their ticks, and its CPU seconds."""
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    states, ticks = [], []

    def rec(k: int, data, _model=None) -> None:
        if k < len(ref):
            states.append(np.empty(mujoco.mj_stateSize(model, spec)))
            mujoco.mj_getState(model, data, states[-1], spec)
            ticks.append(k)

    t0 = time.process_time()
    sample_track(model, ref, samples=samples, record_every=1, recorder=rec, **SEARCH)
    return np.array(states), np.array(ticks), time.process_time() - t0


def step_costs(models: dict, states: np.ndarray, reps: int) -> dict[str, dict]:
    """Per body: microseconds per physics step (least CPU time per state over ``reps``, the
    bodies in turn), MuJoCo's stage timers [us per step, wall clock, of each state's least CPU
    time rep], contacts, constraint rows and solver iterations per step."""
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    datas = {n: mujoco.MjData(m) for n, m in models.items()}
    best = {n: np.full(len(states), np.inf) for n in models}
    stages = {n: np.zeros(len(STAGES)) for n in models}
    counts = {n: np.zeros(3) for n in models}
    ids = [int(getattr(mujoco.mjtTimer, t)) for _, t in STAGES]
    for i, s in enumerate(states):
        kept = {n: np.zeros(len(STAGES)) for n in models}
        for r in range(reps):
            for n, m in models.items():
                d = datas[n]
                mujoco.mj_setState(m, d, s, spec)
                before = np.array([d.timer[j].duration for j in ids])
                t0 = time.process_time()
                for _ in range(SUBSTEPS):
                    mujoco.mj_step(m, d)
                    if r == 0:
                        counts[n] += d.ncon, d.nefc, d.solver_niter[0]
                dt = time.process_time() - t0
                if dt < best[n][i]:
                    best[n][i] = dt
                    kept[n] = np.array([d.timer[j].duration for j in ids]) - before
        for n in models:
            stages[n] += kept[n]
    out = {}
    for n in datas:
        steps = SUBSTEPS * len(states)
        timers = {label: 1e6 * v / steps for (label, _), v in zip(STAGES, stages[n], strict=True)}
        per = counts[n] / (SUBSTEPS * len(states))
        out[n] = {"us_per_step": 1e6 * best[n].sum() / (SUBSTEPS * len(states)),
                  "timers": timers, "contacts": per[0], "rows": per[1], "iterations": per[2]}  # fmt: skip
    return out


def python_costs(model, ref: np.ndarray, states: np.ndarray, ticks: np.ndarray, reps: int) -> dict:
    """Microseconds per call of the tick's Python parts on the recorded states (least of
    ``reps`` per state): the balance feedback (at its own ticks only), the fall check, the
    control writes, the divergence check."""
    data = mujoco.MjData(model)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    ref_qvel, _ = reference_feedforward(model, ref, data)
    plan = balance_plan(model, ref, ref_qvel, DEFAULT_BALANCE)
    falls = fall_reference(model, ref)
    fb = np.zeros(model.nu)
    target = ref[0, 7:].copy()
    parts = {
        "balance feedback (per call, every 2nd tick)": lambda k: balance_torques(
            model, data, plan, k, fb
        ),
        "fall check": lambda k: has_fallen(model, data, falls, k),
        "control writes": lambda k: set_controls(model, data, target, 1.0),
        "divergence check": lambda k: divergences(data),
    }
    out = {}
    for name, f in parts.items():
        total, n = 0.0, 0
        for s, k in zip(states, ticks, strict=True):
            if name.startswith("balance") and k % plan.every:
                continue
            mujoco.mj_setState(model, data, s, spec)
            mujoco.mj_forward(model, data)  # the contacts and kinematics a tick leaves behind
            best = np.inf
            for _ in range(reps):
                t0 = time.process_time()
                f(int(k))
                best = min(best, time.process_time() - t0)
            total, n = total + best, n + 1
        out[name] = 1e6 * total / max(1, n)
    return out


def tracking_costs(models: dict, ref: np.ndarray, samples: int, reps: int) -> dict:
    """Per body: the whole sampler's CPU seconds per simulated second (each of ``reps`` runs,
    the bodies in turn, their order reversed every other round), and whether every body's
    motion equals the first's bit for bit."""
    cpu = {n: [] for n in models}
    motion = {}
    for r in range(reps):
        for n in list(models)[:: 1 if r % 2 == 0 else -1]:
            m = models[n]
            t0 = time.process_time()
            r = sample_track(m, ref, samples=samples, record_every=1, **SEARCH)
            cpu[n].append((time.process_time() - t0) / (len(ref) / CONTROL_HZ))
            motion[n] = r.qpos
    first = next(iter(motion.values()))
    return {n: (cpu[n], bool(np.array_equal(motion[n], first))) for n in models}


def clip_markdown(clip: str, steps: dict, python: dict, tracking: dict, samples: int) -> str:
    """One clip's tables."""
    d, lean = steps["default"], steps["lean"]
    lines = [
        f"### {clip}\n",
        "| per physics step | default body | lean body |",
        "|---|---|---|",
        f"| CPU time, least of the reps [us] | {d['us_per_step']:.1f} | {lean['us_per_step']:.1f} "
        f"(x{lean['us_per_step'] / d['us_per_step']:.3f}) |",
    ]
    for label, _ in STAGES:
        name = label.replace(" ", "&nbsp;", label.count(" ") - label.lstrip().count(" "))
        lines.append(f"| MuJoCo timer: {name} [us] | {d['timers'][label]:.1f} "
                     f"| {lean['timers'][label]:.1f} |")  # fmt: skip
    for key in ("contacts", "rows", "iterations"):
        lines.append(f"| {key.replace('rows', 'constraint rows').replace('iterations', 'solver iterations')} "
                     f"| {d[key]:.2f} | {lean[key]:.2f} |")  # fmt: skip
    lines += ["", "| a tick's Python part | us per call |", "|---|---|"]
    lines += [f"| {k} | {v:.1f} |" for k, v in python.items()]
    lines += [
        "",
        f"| whole tracking, {samples} samples | CPU s per simulated s (each run) | same motion "
        "as the default body |",
        "|---|---|---|",
    ]
    for n, (cpu, same) in tracking.items():
        lines.append(f"| {n} | {' '.join(f'{c:.2f}' for c in cpu)} | {'yes' if same else 'NO'} |")
    ratio = np.array(tracking["lean"][0]) / np.array(tracking["default"][0])
    lines.append(f"\nLean over default, run by run: {' '.join(f'{x:.3f}' for x in ratio)} "
                 f"(median {np.median(ratio):.3f}).")  # fmt: skip
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=default_data_dir(), help="folder of CMU trials")
    ap.add_argument("--clips", nargs="+", default=["07_01@0", "05_06@240"])
    ap.add_argument("--samples", type=int, default=28)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--no-write", action="store_true", help="print only")
    args = ap.parse_args()
    command = "python benchmarks/bench_simulate_step.py " + " ".join(sys.argv[1:])
    skeleton = canonical_skeleton()
    models = {n: validation_model(skeleton, lean=n == "lean") for n in BODIES}
    parts = []
    for clip in args.clips:
        try:
            ref = clip_reference(args.data, clip, models["default"])
        except (SidqlError, ValueError) as e:
            print(f"bench_simulate_step: clip {clip!r}: {e}", file=sys.stderr)
            sys.exit(2)
        states, ticks, _ = tick_states(models["default"], ref, args.samples)
        steps = step_costs(models, states, args.reps)
        python = python_costs(models["default"], ref, states, ticks, args.reps)
        tracking = tracking_costs(models, ref, args.samples, args.reps)
        parts.append(clip_markdown(clip, steps, python, tracking, args.samples))
        print(parts[-1], flush=True)
    text = (
        "The sampling tracker's rollouts are physics steps and a little Python per control tick "
        f"({SUBSTEPS} steps of 1/480 s). Per clip: 2 s of the trial on the canonical humanoid "
        f"({len(ticks)} control ticks of its sampler's replay, each stepped by both bodies in "
        f"turn, {args.reps} times, the least CPU time kept; MuJoCo's timers, wall clock, "
        f"of those least runs); then the whole tracking on both bodies in turn. {machine()}.\n\n"
        + "\n".join(parts)
    )
    if not args.no_write:
        write_results("simulate_step", "Forward simulation: the cost of a rollout tick", text,
                      command)  # fmt: skip


if __name__ == "__main__":
    main()
