"""What a controller's root-relative tracking error (``sim_error_local_mm``) is made of.

Usage::

    python benchmarks/bench_simulate_posture.py --data /work/shared/cmu
        [--controller mix0.5s40terrain] [--clips 01_01@240 02_02@0 ...] [--json OUT]

Per clip (eval's original motion, its IK fit, tracked as ``bench_simulate.py`` tracks it by the
``--controller`` of ``simulate_controllers.CONTROLLERS``; its ``ForwardValidation.run`` wrapped to
keep its references, and the search's offsets and the replay's controls kept), all root-relative
as ``sim_error_local_mm`` is (each frame's points less its root point, mean distance, mm):

* ``error``: the figure itself, recomputed from the kept points (the same to 0.01 mm);
* ``floor``: the reference the controller tracks (contact-consistent, soles laid flat) against
  the original's IK fit as it comes: what a perfect tracker would still score;
* ``lag_ms``, ``at_lag``: the reference shifted by the best δ of -100..+100 ms (control ticks;
  negative: the body behind it) and the error there (over the frames every δ reaches);
* ``pelvis``, ``tilt``, ``heading``, ``hinges``, ``trunk``, ``legs``, ``arms``: the reference with
  that part of the simulated motion put in (its pelvis orientation, or only its tilt or its
  heading; its hinges, all or a group's);
* ``fix_pelvis``, ``fix_trunk``, ``fix_pelvis_trunk``, ``fix_pelvis_trunk_legs``: the simulated
  motion with those parts set to the reference's;
* per point (``points``) and per hinge group the angle error [deg RMS]; the sampler's offsets
  [deg RMS] and its corrected hinges' angle error where their offset is above / below its median.

Printed as a markdown table (``docs/synthetic.md``, "What the root-relative error is made of").
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_simulate as bs  # noqa: E402

import sim.simulate.gainchoice as gainchoice  # noqa: E402
import sim.simulate.validate as validate  # noqa: E402
from sidql.evaluation.cases import load_cases  # noqa: E402
from sim.files import write_atomic  # noqa: E402
from sim.simulate.footholding import sole_yaw  # noqa: E402
from sim.simulate.model import CONTROL_HZ  # noqa: E402
from sim.simulate.noisescale import hinge_bone  # noqa: E402

CLIPS = ("01_01@240", "02_02@0", "07_01@0", "18_15@0", "55_12@0", "60_01@0", "60_01@480",
         "61_01@480")  # fmt: skip
GROUPS = {
    "legs": ("femur", "tibia", "foot", "toes"),
    "trunk": ("lowerback", "upperback", "thorax"),
    "neck": ("lowerneck", "upperneck", "head"),
    "arms": ("clavicle", "humerus", "radius", "wrist", "hand", "fingers", "thumb"),
}
LAG_TICKS = 12  # 100 ms either way


class Kept:
    """What the wrapped ``ForwardValidation.run``, search and replay leave: the references
    (``reference``'s returns in order), the raw control-rate original, the search's offsets
    (T, nu) and the replay's controls (T, nu)."""

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        """Forget the last run's."""
        self.refs, self.raw, self.offsets, self.ctrl = [], None, None, []

    def install(self) -> None:
        run, reference = validate.ForwardValidation.run, validate.ForwardValidation.reference
        search, track = gainchoice.choice_search, validate.choice_track
        kept = self

        def run_(fv, qpos, fps, original_qpos=None):
            kept.raw = validate.time_warp(fv.model, qpos, fps, 1.0, CONTROL_HZ)
            return run(fv, qpos, fps, original_qpos)

        def reference_(fv, *a, **k):
            kept.refs.append(reference(fv, *a, **k))
            return kept.refs[-1]

        def search_(*a, **k):
            out = search(*a, **k)
            kept.offsets = out[0]
            return out

        def track_(model, ref, **kw):
            def rec(k, data, m):
                if k < len(ref):
                    kept.ctrl.append(data.ctrl.copy())

            return track(model, ref, recorder=rec, **kw)

        validate.ForwardValidation.run, validate.ForwardValidation.reference = run_, reference_
        gainchoice.choice_search, validate.choice_track = search_, track_


def _point_errors(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(P,) each point's root-relative error [mm], mean over frames, of points (F, P, 3)
    against (F, P, 3) (root first)."""
    return 1e3 * np.linalg.norm((a - a[:, :1]) - (b - b[:, :1]), axis=-1).mean(0)


def _err(a: np.ndarray, b: np.ndarray) -> float:
    """Root-relative error [mm] of points (F, P, 3) against (F, P, 3) (root first): as
    ``sim_error_local_mm``, the mean over frames and points."""
    return float(_point_errors(a, b).mean())


def _yaw(quats: np.ndarray) -> np.ndarray:
    """(F,) heading [rad] of (F, 4) quaternions (``footholding.sole_yaw`` of their matrices)."""
    mats = np.empty((len(quats), 9))
    for i, q in enumerate(quats):
        mujoco.mju_quat2Mat(mats[i], q)
    return sole_yaw(mats)


def _turned(quats: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(F, 4) ``quats`` turned by ``yaw`` (F,) [rad] about the vertical."""
    out = np.empty_like(quats)
    for i, (q, a) in enumerate(zip(quats, yaw, strict=True)):
        mujoco.mju_mulQuat(out[i], np.array([np.cos(a / 2), 0.0, 0.0, np.sin(a / 2)]), q)
    return out


def decompose(fv, kept: Kept, every: int = 4) -> dict:
    """The figures of the module docstring for ``fv``'s last run (``kept`` its leftovers)."""
    m, ref, tracked = fv.model, kept.refs[0], kept.refs[-1]
    sim = fv.last_qpos
    n = len(sim) if fv.last_fall_tick < 0 else min(len(sim), fv.last_fall_tick // every)
    sim, qref = sim[:n], ref[::every][:n]
    pts, p_ref_all = fv.points, fv.points(ref)
    p_sim, p_ref = pts(sim), p_ref_all[::every][:n]
    out = {
        "error": _err(p_sim, p_ref),
        "floor": _err(pts(tracked[::every][:n]), pts(kept.raw[::every][:n])),
    }
    frames = np.arange(n) * every
    ok = (frames >= LAG_TICKS) & (frames + LAG_TICKS < len(ref))
    lag = {d: _err(p_sim[ok], p_ref_all[frames[ok] + d]) for d in range(-LAG_TICKS, LAG_TICKS + 1)}
    best = min(lag, key=lag.get)
    out.update(lag_ms=1e3 * best / CONTROL_HZ, at_lag=lag[best], at_zero=lag[0])
    adr = m.jnt_qposadr[m.actuator_trnid[:, 0]]
    bones = np.array([hinge_bone(m.joint(j).name) for j in m.actuator_trnid[:, 0]])
    group = {g: adr[np.isin(bones, b)] for g, b in GROUPS.items()}
    dyaw = _yaw(sim[:, 3:7]) - _yaw(qref[:, 3:7])

    def into_ref(cols, src=sim):
        h = qref.copy()
        h[:, cols] = src[:, cols]
        return _err(pts(h), p_ref)

    def fixed(cols):
        h = sim.copy()
        h[:, cols] = qref[:, cols]
        return _err(pts(h), p_ref)

    head = qref.copy()
    head[:, 3:7] = _turned(qref[:, 3:7], dyaw)
    tilt = qref.copy()
    tilt[:, 3:7] = _turned(sim[:, 3:7], -dyaw)
    rot = [3, 4, 5, 6]
    out.update(
        pelvis=into_ref(rot), tilt=_err(pts(tilt), p_ref), heading=_err(pts(head), p_ref),
        heading_deg=float(np.degrees(np.sqrt(np.mean(np.angle(np.exp(1j * dyaw)) ** 2)))),
        hinges=into_ref(list(adr)), **{g: into_ref(list(c)) for g, c in group.items()},
        fix_pelvis=fixed(rot), fix_trunk=fixed(list(group["trunk"])),
        fix_pelvis_trunk=fixed(rot + list(group["trunk"])),
        fix_pelvis_trunk_legs=fixed(rot + list(group["trunk"]) + list(group["legs"])),
    )  # fmt: skip
    for b in ("femur", "tibia", "foot", "toes", *GROUPS):
        cols = group[b] if b in GROUPS else adr[bones == b]
        out[f"{b}_deg"] = float(np.degrees(np.sqrt(np.mean((sim[:, cols] - qref[:, cols]) ** 2))))
    out["points"] = dict(zip(fv.names, _point_errors(p_sim, p_ref), strict=True))
    out.update(_offsets(sim, ref, kept, adr, frames))
    return out


def _offsets(sim, ref, kept: Kept, adr, frames) -> dict:
    """The sampler's offsets [deg RMS] at the recorded frames and the angle error [deg RMS] of
    the hinges it corrects, where their offset is above / below its median size, and of the
    others."""
    if kept.offsets is None:
        return {}
    off = kept.offsets[frames]
    err = sim[:, adr] - ref[frames][:, adr]
    corrected = np.abs(kept.offsets).max(axis=0) > 0
    big = np.abs(off[:, corrected]) > np.median(np.abs(off[:, corrected]))
    e = err[:, corrected]
    rms = lambda x: float(np.degrees(np.sqrt(np.mean(x**2))))  # noqa: E731
    return {"offsets_deg": rms(off[:, corrected]), "corrected_deg": rms(e),
            "where_big_deg": rms(e[big]), "where_small_deg": rms(e[~big]),
            "uncorrected_deg": rms(err[:, ~corrected])}  # fmt: skip


COLUMNS = (("error", "root-relative"), ("floor", "(a) floor"), ("lag_ms", "(b) best δ [ms]"),
           ("at_lag", "error at best δ"), ("pelvis", "pelvis orientation alone"),
           ("tilt", "tilt alone"), ("heading", "heading alone"), ("hinges", "hinges alone"),
           ("trunk", "trunk alone"), ("legs", "legs alone"), ("arms", "arms alone"),
           ("fix_pelvis_trunk", "pelvis and trunk put right"),
           ("fix_pelvis_trunk_legs", "and the legs"))  # fmt: skip


def markdown(rows: dict[str, dict]) -> str:
    """The per-clip table of :data:`COLUMNS` with its medians."""
    lines = [
        "| clip | " + " | ".join(c[1] for c in COLUMNS) + " |",
        "|---" * (len(COLUMNS) + 1) + "|",
    ]
    for clip, r in rows.items():
        lines.append(f"| {clip} | " + " | ".join(f"{r[k]:.0f}" for k, _ in COLUMNS) + " |")
    med = [np.median([r[k] for r in rows.values()]) for k, _ in COLUMNS]
    lines.append("| median | " + " | ".join(f"{x:.0f}" for x in med) + " |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="../shared/cmu")
    ap.add_argument("--controller", default="mix0.5s40terrain")
    ap.add_argument("--clips", nargs="+", default=list(CLIPS))
    ap.add_argument("--json", help="write every clip's figures here")
    args = ap.parse_args()
    kept = Kept()
    kept.install()
    cases, _ = load_cases(args.data, progress=False, workers=1)
    want = {(c.split("@")[0], int(c.split("@")[1])) for c in args.clips}
    pick = [c for c in cases if (Path(c.clip.source).stem, c.clip.start_frame) in want]
    setup, bodies, rows = {}, {}, {}
    for c in pick:
        if c.clip.source not in setup:
            setup.update(bs.physics_setup([x for x in cases if x.clip.source == c.clip.source]))
        kept.reset()
        row = bs._clip_rows(c, setup, [args.controller], bodies, 1)[args.controller]
        clip = f"{Path(c.clip.source).stem}@{c.clip.start_frame}"
        rows[clip] = {**decompose(bodies[c.asf, args.controller], kept), "fell": row["sim_fell"],
                      "metric": row["sim_error_local_mm"], "cpu": row["sim_cpu_s_per_s"]}  # fmt: skip
        print(clip, json.dumps({k: round(v, 1) for k, v in rows[clip].items() if k != "points"}),
              flush=True)  # fmt: skip
    print(markdown(rows))
    if args.json:
        text = json.dumps(rows, indent=1).encode()
        write_atomic(Path(args.json), lambda f: f.write(text))


if __name__ == "__main__":
    main()
