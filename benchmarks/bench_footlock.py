"""The foot-locked reference against the contact-consistent one it is made from, clip by clip,
without simulating: how much its stance feet slide and sink, how much of the stance is held,
how fast its knees move and what the lock costs.

Usage::

    python benchmarks/bench_footlock.py --data ../shared/cmu --every 5 [--offset 2]

Per clip (the IK fit of the original, as ``bench_simulate.py`` tracks it): eval's tracked
reference (``ForwardValidation.reference`` with the contact-consistent floor) and the same
locked (``sim.simulate.footlock.foot_locked``), each at the control rate: the skating of
its soles in contact (``ForwardValidation.skating``: the mean horizontal speed of each sole
box's bottom where its lowest corner is within 5 mm), the median horizontal speed of the
stance soles (lowest corner within 3 cm), the lowest sole corner over the clip, the share of
stance frames held (flat within 1 deg, within 2 mm of z = 0), the largest knee change per
tick, and the lock's CPU seconds per second of motion. Prints the medians; writes no page.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sidql.evaluation.cases import load_cases  # noqa: E402
from sidql.evaluation.trial_physics import _protocol_names, physics_setup  # noqa: E402
from sim.model.humanoid import subject_model  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402
from sim.simulate.footlock import foot_locked  # noqa: E402
from sim.simulate.model import CONTROL_HZ  # noqa: E402
from sim.simulate.reference import STANCE_GAP  # noqa: E402
from sim.simulate.validate import forward_validation  # noqa: E402

SIGNS = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)


def sole_state(model, qpos: np.ndarray) -> np.ndarray:
    """(T, 2, 4) per sole box (left, right): its bottom's centre (x, y) [m], lowest corner
    height [m] and tilt from flat [rad]."""
    data = mujoco.MjData(model)
    out = np.empty((len(qpos), 2, 4))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for s, side in enumerate("lr"):
            g = model.geom(f"{side}sole").id
            R = data.geom_xmat[g].reshape(3, 3)
            low = (data.geom_xpos[g] + (SIGNS * model.geom_size[g]) @ R.T)[:, 2].min()
            bottom = data.geom_xpos[g] - R[:, 2] * model.geom_size[g, 2]
            out[t, s] = bottom[0], bottom[1], low, np.arccos(min(1.0, R[2, 2]))
    return out


def reference_figures(fv, ref: np.ndarray, stance: np.ndarray) -> dict:
    """The figures of one reference ``ref`` (T, nq, control rate) on ``stance`` (T, 2) bool."""
    model = fv.model
    st = sole_state(model, ref)
    speed = np.linalg.norm(np.gradient(st[..., :2], 1.0 / CONTROL_HZ, axis=0), axis=-1)
    held = stance & (np.abs(st[..., 2]) < 0.002) & (st[..., 3] < np.radians(1.0))
    knees = [model.jnt_qposadr[model.joint(f"{s}tibia_rx").id] for s in "lr"]
    return {
        "skate_mm_s": fv.skating(ref, CONTROL_HZ),
        "stance_speed_mm_s": 1e3 * float(np.median(speed[stance])) if stance.any() else None,
        "min_sole_mm": 1e3 * float(st[..., 2].min()),
        "held": float(held.sum() / max(1, stance.sum())),
        "knee_rad_tick": float(np.abs(np.diff(ref[:, knees], axis=0)).max()),
    }


def clip_row(fv, qpos: np.ndarray, fps: float) -> dict:
    """Both references of ``qpos`` (F, nq at ``fps``) and the lock's CPU s per s."""
    ref = fv.reference(qpos, fps, contact=True)
    stance = sole_state(fv.model, ref)[..., 2] <= STANCE_GAP
    t0 = time.process_time()
    locked = foot_locked(fv.model, ref, CONTROL_HZ)
    cpu = (time.process_time() - t0) / (len(ref) / CONTROL_HZ)
    return {"before": reference_figures(fv, ref, stance),
            "locked": reference_figures(fv, locked, stance), "cpu_s_per_s": cpu}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=default_data_dir())
    ap.add_argument("--every", type=int, default=5)
    ap.add_argument("--offset", type=int, default=0)
    ap.add_argument("--max-clips", type=int, default=None)
    args = ap.parse_args()
    cases, _ = load_cases(args.data, progress=False, workers=1)
    cases = cases[args.offset :: args.every][: args.max_clips]
    setup = physics_setup(cases)
    bodies, rows = {}, []
    for c in cases:
        if c.asf not in bodies:
            bodies[c.asf] = forward_validation(subject_model(c.asf)[0], _protocol_names(c.clip))
        qpos = setup[c.clip.source].analyse(c.clip)["per_frame"]["qpos"]
        rows.append(clip_row(bodies[c.asf], qpos, c.clip.fps))
        r = rows[-1]
        print(f"{Path(c.clip.source).stem}@{c.clip.start_frame} before {r['before']} "
              f"locked {r['locked']} cpu {r['cpu_s_per_s']:.3f}", flush=True)  # fmt: skip
    print(f"\n{len(rows)} clips, medians (the worst for the lowest sole and the knee):")
    print("| reference | skating [mm/s] | stance sole speed [mm/s] | lowest sole [mm] | "
          "stance held | knee change per tick [rad] |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for key in ("before", "locked"):

        def med(k, rs=rows, key=key):
            return float(np.median([r[key][k] for r in rs if r[key][k] is not None]))

        lows = [r[key]["min_sole_mm"] for r in rows]
        knees = [r[key]["knee_rad_tick"] for r in rows]
        print(f"| {key} | {med('skate_mm_s'):.0f} | {med('stance_speed_mm_s'):.0f} | "
              f"{med('min_sole_mm'):.1f} (worst {min(lows):.1f}) | {med('held'):.2f} | "
              f"{med('knee_rad_tick'):.3f} (worst {max(knees):.3f}) |")  # fmt: skip
    print(f"lock CPU s per s of motion: median {np.median([r['cpu_s_per_s'] for r in rows]):.3f}")


if __name__ == "__main__":
    main()
