"""Evaluate keyframe methods on the paper's protocol and tabulate them like its Table 3.

Protocol: every CMU trial at 30 fps (every 4th frame of 120 fps), cut into non-overlapping 60-frame
clips from frame 0; each method chooses W keyframes per clip (both ends included); the clip is
rebuilt with the reconstruction the method declares (:mod:`sidql.keyframes.reconstructions`:
spherical cubic Hermite for every method except ``pitch``, which declares Li et al.'s slerp) and
scored by

* ``q``: the paper's eq. 18 [rad] on the reconstruction's angles (22 bones);
* ``q_hermite``: eq. 18 of the same keyframes under the Hermite reconstruction (equal to ``q``
  for methods that declare Hermite: it separates the choice of keyframes from the way they are interpolated);
* ``geodesic_deg``: mean angle between true and rebuilt bone directions [deg];
* ``mpjpe_mm``: mean joint position error over the 23 points [mm];
* ``velocity_error``: mean joint velocity error over the 23 points [m/s];
* ``li_error_mm``: Li et al. 2015's error as we read it (:func:`sidql.keyframes.pitch.pitch_error`) [mm];
* ``decision_ms``: wall time of the method's choice, chart included [ms].

Loading needs ``sim.motion.ingest`` (MuJoCo); everything after it is pure numpy.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from sidql.evaluation.significance import CLOSENESS, paired_comparisons
from sidql.keyframes import methods, reconstructions
from sidql.keyframes.metrics import geodesic_deg, mpjpe_mm, q_error, q_from_angles, velocity_error
from sidql.keyframes.pitch import pitch_error
from sidql.keyframes.spherical import POINTS, SphericalSeries, chart, protocol_indices
from sim.analysis.figures import HEIGHT_KEYS
from sim.analysis.job import PhysicsJob
from sim.batch import iter_batch, run_batch
from sim.errors import MotionDataError
from sim.model.humanoid import subject_model
from sim.motion.clip import Clip
from sim.motion.dataset import dataset_clips, find_trials
from sim.motion.ingest import load_clips
from sim.physics.contacts import Contacts, trial_contacts
from sim.physics.ground import Ground, estimate_ground
from sim.physics.support import support_verdict
from sim.replay.checks import from_clip
from sim.simulate.model import sim_model
from sim.simulate.validate import SIMULATE_KEYS, ForwardValidation

#: The paper's Table 3 (mean Q at W = 5, 10, 15); "SIDQL" is its DQN.
PAPER_TABLE3: dict[str, dict[int, float]] = {
    "RC": {5: 0.1437, 10: 0.0833, 15: 0.0549},
    "UC": {5: 0.0945, 10: 0.0490, 15: 0.0328},
    "Greedy": {5: 0.0536, 10: 0.0311, 15: 0.0200},
    "SIDQL": {5: 0.0844, 10: 0.0443, 15: 0.0297},
}

#: Our method name -> the paper's row.
PAPER_NAMES = {"random": "RC", "uniform": "UC", "greedy": "Greedy", "dqn": "SIDQL"}


@dataclass(frozen=True)
class Case:
    """One evaluation clip with what every method's scoring needs.

    Attributes:
        clip: the 60-frame clip; series: its chart; pos, vel: (N, 23, 3) true protocol points
        [m, m/s]; index: position in the dataset (seeds the random method).
    """

    clip: Clip
    series: SphericalSeries
    pos: np.ndarray
    vel: np.ndarray
    index: int
    asf: str = ""


def make_case(clip: Clip, index: int = 0, asf: str = "") -> Case:
    """``asf``: the subject's skeleton file (needed by ``evaluate(..., physics=True)``)."""
    idx = protocol_indices(clip)
    return Case(clip, chart(clip), clip.positions[:, idx], clip.velocities[:, idx], index, asf)


def load_cases(
    data_dir,
    *,
    fps: float = 30.0,
    length: int = 60,
    skeleton: str = "subject",
    progress: bool = True,
    subjects=None,
    workers: int = 1,
    ray: str | None = None,
) -> tuple[list[Case], list[dict]]:
    """Every ``length``-frame clip of every trial under ``data_dir``.

    ``subjects``: keep only these subject ids (e.g. a policy's held-out subjects); None keeps all.
    A folder with an ``index.json`` (written by ``sidql dataset`` or ``sidql synth``) is read from
    its ``.npz`` clips. Trials load through ``sim.batch.run_batch`` (``workers``, ``ray``).

    Returns:
        The cases, and ``{"amc", "problem"}`` for each trial skipped as bad input (also reported
        on stderr); good trials are kept.
    """
    cases: list[Case] = []
    skipped: list[dict] = []
    if (Path(data_dir) / "index.json").is_file():
        rows = dataset_clips(data_dir, length, skipped)  # each file read once, named as read
        for s in skipped:
            print(f"skipped {s['amc']}: {s['problem']}", file=sys.stderr)
        rates = sorted({r[0].fps for r in rows} - {float(fps)})
        if rates:  # the clips are what they are: a different rate would be mislabelled
            raise MotionDataError(
                str(Path(data_dir) / "index.json"), None,
                f"clips at {', '.join(f'{r:g}' for r in rates)} fps, not {fps:g} (pass --fps)",
            )  # fmt: skip
        bad: dict[str, str] = {}
        for c, s, a, file in rows:  # a clip without the protocol's bones: its file listed once
            if subjects is not None and s not in subjects:
                continue
            try:
                cases.append(make_case(c, len(cases), a))
            except MotionDataError as e:
                bad.setdefault(str(file), f"{e.problem if e.path == c.source else e}")
        for source, problem in bad.items():
            skipped.append({"amc": source, "problem": problem})
            print(f"skipped {source}: {problem}", file=sys.stderr)
        return cases, skipped
    outside: list[dict] = []  # symbolic links leaving data_dir: listed, never read
    trials = find_trials(data_dir, outside)
    for o in outside:
        skipped.append({"amc": o["amc"], "problem": o["error"]})
        print(f"skipped {o['amc']}: {o['error']}", file=sys.stderr)
    if subjects is not None:
        trials = [t for t in trials if t.subject in set(subjects)]
    load = partial(_trial_clips, fps=fps, length=length, skeleton=skeleton, load=load_clips)
    outcomes = run_batch(
        load, trials, workers=workers, ray=ray, desc="load trials", progress=progress
    )
    for trial, o in zip(trials, outcomes, strict=True):
        error = o.error
        if o.ok:
            first = len(cases)  # case index = position in the whole run (seeds depend on it)
            asf = str(trial.asf) if skeleton == "subject" else ""  # physics: the subject's model
            try:  # e.g. a skeleton without the protocol's bones: this trial only is bad
                cases += [make_case(c, first + i, asf) for i, c in enumerate(o.result)]
            except MotionDataError as e:
                error = str(e)
        if error is not None:
            skipped.append({"amc": str(trial.amc), "problem": error})
            print(f"skipped {trial.amc}: {error}", file=sys.stderr)
    return cases, skipped


def _trial_clips(trial, *, fps, length, skeleton, load):
    return load(trial.asf, trial.amc, fps=fps, length=length, skeleton=skeleton)


def clip_seed(seed: int, index: int, W: int) -> int:
    """Deterministic per-clip, per-W seed for randomised methods."""
    return int(np.random.SeedSequence([seed, index, W]).generate_state(1)[0])


def score(
    case: Case, keyframes: np.ndarray, method: str, physics=None, simulate=None, original_qpos=None
) -> dict:
    """Every error measure of one clip rebuilt from ``keyframes`` with the reconstruction
    ``method`` declares (:func:`sidql.keyframes.methods.reconstruction_of`; see the module
    docstring).

    ``physics``: the trial's :class:`TrialPhysics` adds the :mod:`sim.physics` figures of the
    reconstruction (its curve's own velocities and accelerations, the original's contacts
    labelled over the whole trial); ``simulate`` (a
    :class:`sim.simulate.validate.ForwardValidation`, with ``physics``) adds its forward
    simulation's figures (the IK fit tracked without assistance; ``original_qpos``: the
    original's fit, computed here when None)."""
    s = case.series
    rec = reconstructions.rebuild(methods.reconstruction_of(method), case.clip, keyframes, s)
    phys = {}
    if physics:
        analysis = physics.analyse(case.clip, rec)
        phys = physics_figures(analysis, physics.analyse(case.clip))
        if simulate is not None:
            if original_qpos is None:
                original_qpos = physics.analyse(case.clip)["per_frame"]["qpos"]
            phys.update(simulate.run(analysis["per_frame"]["qpos"], case.clip.fps, original_qpos))
    return {
        **phys,
        "q": q_from_angles(s, rec.theta, rec.phi),
        "q_hermite": q_error(s, keyframes, "hermite"),
        "geodesic_deg": geodesic_deg(case.pos, rec.positions, rec.parents),
        "mpjpe_mm": mpjpe_mm(case.pos, rec.positions),
        "velocity_error": velocity_error(case.vel, rec.velocities),
        "li_error_mm": 1000.0 * pitch_error(case.pos, rec.positions),
    }


#: The :mod:`sim.physics` figures ``evaluate(..., physics=True)`` adds to rows (means over clips).
PHYSICS_KEYS = (
    "penetration_mm", "float_mm", "skate_mm_s", "contact_precision", "contact_recall",
    "physdiff_penetrate_mm", "physdiff_float_mm", "physdiff_skate",
    "self_pen_excess_mm", "lost_contacts", "limit_excess_deg", "residual_force_bw",
    "residual_force_bw_p95", "residual_torque_nm_kg", "joint_torque_rms_nm_kg",
    "joint_torque_rms_nm_kg_distance",
    "residual_force_bw_excess", "residual_torque_nm_kg_excess", "joint_torque_rms_nm_kg_excess",
    "ik_error_mm",
)  # fmt: skip

#: Heights above the floor: not scored (None) in a trial whose floor does not fit.
FLOOR_KEYS = HEIGHT_KEYS


def physics_figures(analysis: dict, original: dict | None = None) -> dict:
    """The per-clip numbers of a :mod:`sim.physics` analysis (no per-frame arrays; NaN, a mean
    over no samples, becomes None so that the JSON is standard). With the ``original``'s
    analysis, figures of :data:`sidql.evaluation.significance.CLOSENESS` also get
    ``<key>_distance``, |value - original's|. Where the floor does not fit, the heights above it
    (:data:`FLOOR_KEYS`) are None."""
    out = {k: _none_if_nan(v) for k, v in analysis.items() if k != "per_frame"}
    base = analysis if original is None else original
    for k in CLOSENESS:
        if out.get(k) is not None and base.get(k) is not None:
            out[f"{k}_distance"] = abs(float(out[k]) - float(base[k]))
    if not analysis.get("floor_fits", True):
        for k in FLOOR_KEYS:
            out[k] = None
    return out


def _none_if_nan(v):
    return None if isinstance(v, float) and np.isnan(v) else v


def simulate_setup(cases: Sequence[Case], samples: int = 0) -> dict:
    """Per trial (``clip.source``): the :class:`sim.simulate.validate.ForwardValidation` of its
    subject (one torque-limited simulated body per skeleton) for :func:`score`; ``samples``:
    its sampling tracker's rollouts per window (0: the plain tracker)."""
    bodies, out = {}, {}
    for c in cases:
        if c.asf not in bodies:
            skeleton = subject_model(c.asf)[0]
            bodies[c.asf] = ForwardValidation(
                sim_model(skeleton), _protocol_names(c.clip), samples=samples
            )
        out[c.clip.source] = bodies[c.asf]
    return out


def _protocol_names(clip: Clip) -> tuple[str, ...]:
    return from_clip(clip).restrict(POINTS).names


def _simulate_means(rows: Sequence[dict]) -> dict:
    """Mean over clips of each :data:`sim.simulate.validate.SIMULATE_KEYS` figure (the fall
    time: over the clips that fell, None if none did)."""
    out = {}
    for k in SIMULATE_KEYS:
        v = np.array([np.nan if r.get(k) is None else r[k] for r in rows], dtype=float)
        v = v[np.isfinite(v)]
        out[k] = float(v.mean()) if v.size else None
    return out


@dataclass(frozen=True)
class TrialPhysics:
    """What the physics of one trial's clips share: the subject's
    :class:`sim.analysis.job.PhysicsJob` on the protocol points, the trial's ground, and the
    original's contacts labelled once over the whole trial (``start``: each clip's
    ``start_frame`` -> its first frame in ``contacts``; clip objects do not keep their identity
    on the way to worker processes or Ray)."""

    job: PhysicsJob
    ground: Ground
    contacts: Contacts
    start: dict

    def clip_contacts(self, clip: Clip) -> Contacts | None:
        """The original's contacts over ``clip``'s frames (None for a clip not of this trial:
        the job labels it on its own)."""
        i = self.start.get(clip.start_frame)
        return None if i is None else self.contacts.slice(i, i + clip.n_frames)

    def noise_floor(self, clip: Clip, *, seed: int = 0) -> dict:
        """The original re-captured with marker noise, analysed against the original
        (:meth:`sim.analysis.job.PhysicsJob.noise_floor`)."""
        return self.job.noise_floor(clip, self.ground, contacts=self.clip_contacts(clip), seed=seed)

    def analyse(self, clip: Clip, rec=None) -> dict:
        """:meth:`sim.analysis.job.PhysicsJob.analyse` of the original (``rec`` None) or of a
        reconstruction (its points, velocities and accelerations)."""
        c = self.clip_contacts(clip)
        if rec is None:
            return self.job.analyse(clip, None, self.ground, contacts=c)
        acc = getattr(rec, "accelerations", None)
        return self.job.analyse(
            clip, rec.positions, self.ground, contacts=c,
            velocities=None if acc is None else rec.velocities, accelerations=acc,
        )  # fmt: skip


def physics_setup(cases: Sequence[Case]) -> dict:
    """Per trial (``clip.source``): its :class:`TrialPhysics` for :func:`score`: the ground and
    the original's contacts from all the trial's clips (in time order), one
    :class:`sim.analysis.job.PhysicsJob` per subject skeleton."""

    jobs, out = {}, {}
    by_trial: dict[str, list[Case]] = {}
    for c in cases:
        if not c.asf:
            raise MotionDataError(
                c.clip.source, None, "physics needs the clip on its subject's own skeleton (ASF); "
                "e.g. a folder of CMU files, or 'sidql dataset --skeleton subject' output",
            )  # fmt: skip
        by_trial.setdefault(c.clip.source, []).append(c)
    for source, group in by_trial.items():
        group = sorted(group, key=lambda c: c.clip.start_frame)
        clip = group[0].clip
        if group[0].asf not in jobs:
            pts = from_clip(clip).restrict(POINTS)
            model = subject_model(group[0].asf)[1]
            jobs[group[0].asf] = PhysicsJob(model, pts.names, pts.parents, clip.fps)
        pos = np.concatenate([c.clip.positions for c in group])
        vel = np.concatenate([c.clip.velocities for c in group])
        ground = estimate_ground(pos, clip.names, clip.fps)
        start, i = {}, 0
        for c in group:
            start[c.clip.start_frame] = i
            i += c.clip.n_frames
        out[source] = TrialPhysics(
            jobs[group[0].asf], ground,
            trial_contacts(pos, clip.names, clip.fps, ground, vel, clip.parents,
                           body_points=jobs[group[0].asf].names),
            start,
        )  # fmt: skip
    return out


def _physics_means(rows: Sequence[dict]) -> dict:
    """Mean over clips of each :data:`PHYSICS_KEYS` figure, and its median (``<key>_median``:
    a few violent clips dominate the dynamics means), over ``<key>_clips`` clips with a value."""
    out = {}
    for k in PHYSICS_KEYS:
        v = np.array([np.nan if r.get(k) is None else r[k] for r in rows], dtype=float)
        v = v[np.isfinite(v)]
        out[k] = float(v.mean()) if v.size else None
        out[f"{k}_median"] = float(np.median(v)) if v.size else None
        out[f"{k}_clips"] = int(v.size)
    return out


def evaluate(
    cases: Sequence[Case],
    method_names: Iterable[str],
    keyframe_counts: Iterable[int],
    *,
    seed: int = 0,
    progress: bool = True,
    physics: bool = False,
    simulate: bool = False,
    simulate_samples: int = 0,
    workers: int = 1,
    ray: str | None = None,
    chunk: int = 4,
) -> dict:
    """Run every method at every W on every case.

    The per-clip work (each method's choice and reconstruction, the physics of the original and
    of every reconstruction, the forward simulations) runs through ``sim.batch.iter_batch``:
    in this process (``workers=1``), ``workers`` processes or Ray (``ray``), in tasks of up to
    ``chunk`` clips of one trial that carry their trial's physics set-up; the rows come back in
    the same order whatever the executor (decision times are measured where the method ran).

    Returns:
        ``{"results": [row...], "per_clip": [row...]}``; a result row holds method, keyframes,
        clips, mean_q, mean_q_hermite, mean_geodesic_deg, mpjpe_mm, mean_velocity_error,
        mean_li_error_mm, median_decision_ms; a per-clip row holds source, start_frame, method,
        keyframes, indices, q and the other scores. With ``physics`` every row also carries the
        :mod:`sim.physics` figures (result rows: means over clips, :data:`PHYSICS_KEYS`), and one
        result row (and per-clip rows) for method ``original``, the clip itself (all frames
        kept: ``keyframes`` = clip length, errors 0). With ``simulate`` (needs ``physics``)
        every row also carries the forward-simulation figures of
        :mod:`sim.simulate.validate` (result rows: means over clips); ``simulate_samples``:
        rollouts per window of its sampling tracker (0: the plain tracker).
    """
    if simulate and not physics:
        raise ValueError("simulate needs physics (the IK fit it tracks)")
    method_names = list(method_names)
    counts = list(keyframe_counts)
    for name in method_names:
        methods.get(name)  # fail early, listing the known methods
        if cases and counts:  # and here, not in a worker: e.g. a learned method's missing file
            methods.select(name, cases[0].clip, counts[0], seed=0)
    setup = physics_setup(cases) if physics else {}
    bodies = simulate_setup(cases, simulate_samples) if simulate else {}
    items = []
    for group in _trial_chunks(cases, chunk):
        source = cases[group[0]].clip.source
        items.append(([(i, cases[i]) for i in group], setup.get(source), bodies.get(source)))
    task = partial(_evaluate_chunk, method_names=tuple(method_names), counts=tuple(counts),
                   seed=seed)  # fmt: skip
    by_case: dict[int, list[dict]] = {}
    for _, o in iter_batch(task, items, workers=workers, ray=ray, desc="evaluate",
                           progress=progress, total=len(items)):  # fmt: skip
        if not o.ok:
            raise RuntimeError(f"evaluating {o.item[0][0][1].clip.source}: {o.error}")
        by_case.update(o.result)
    per_clip: list[dict] = []
    results: list[dict] = []
    originals: list[dict] = []
    if physics and cases:
        originals = [by_case[i][0] for i in range(len(cases))]
        noise = [by_case[i][1] for i in range(len(cases))]
        per_clip.extend(originals + noise)
        zero = ("mean_q", "mean_q_hermite", "mean_geodesic_deg", "mpjpe_mm", "mean_velocity_error")
        for name, group in (("original", originals), (NOISE_FLOOR, noise)):
            results.append(
                {
                    "method": name, "keyframes": cases[0].clip.n_frames, "clips": len(group),
                    **dict.fromkeys(zero, 0.0), "mean_li_error_mm": 0.0,
                    "median_decision_ms": 0.0, **_physics_means(group),
                    **(_simulate_means(group) if simulate and name == "original" else {}),
                }
            )  # fmt: skip
    first = 2 if physics else 0
    for j, (name, W) in enumerate((m, W) for m in method_names for W in counts):
        rows = [by_case[i][first + j] for i in range(len(cases))]
        per_clip.extend(rows)
        if rows:
            results.append(
                {
                    "method": name,
                    "keyframes": W,
                    "clips": len(rows),
                    "mean_q": float(np.mean([r["q"] for r in rows])),
                    "mean_q_hermite": float(np.mean([r["q_hermite"] for r in rows])),
                    "mean_geodesic_deg": float(np.mean([r["geodesic_deg"] for r in rows])),
                    "mpjpe_mm": float(np.mean([r["mpjpe_mm"] for r in rows])),
                    "mean_velocity_error": float(np.mean([r["velocity_error"] for r in rows])),
                    "mean_li_error_mm": float(np.mean([r["li_error_mm"] for r in rows])),
                    "median_decision_ms": float(np.median([r["decision_ms"] for r in rows])),
                    **(_physics_means(rows) if physics else {}),
                    **(_simulate_means(rows) if simulate else {}),
                }
            )
    out = {"results": results, "per_clip": per_clip}
    out["comparisons"] = paired_comparisons(per_clip, method_names, seed=seed)
    if physics:
        out["floors"] = floor_report(setup, originals)
    return out


#: The method name of the noise-floor rows: the original re-captured with marker noise.
NOISE_FLOOR = "noise floor"


def noise_figures(noisy: dict, original: dict) -> dict:
    """A noise-floor row: per figure, how far the original re-captured with marker noise
    (:meth:`sim.analysis.job.PhysicsJob.noise_floor`) departs from the original,
    ``|noisy - original|`` (None where either lacks it)."""
    out = {}
    for k, v in noisy.items():
        o = original.get(k)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        out[k] = None if v is None or o is None else abs(float(v) - float(o))
    return out


def floor_report(setup: dict, originals: Sequence[dict] = ()) -> list[dict]:
    """Per trial its floor (:meth:`sim.physics.ground.Ground.summary`) and whether it fits, and,
    from its original's rows, where its support was found: the original's mean residual force
    (``original_residual_force_bw``), the body points other than feet on the floor
    (``ground_parts``: share of frames), the share of frames whose support was found nowhere
    (``support_missing_share``), the share held by something else (``support_held_share``),
    the frames whose derivatives are not measured (``dynamics_unmeasured_n``, summed over the
    clips) and the verdict (``support_off_floor``, ``support_why``:
    :func:`sim.physics.support.support_verdict`)."""
    out = []
    for src, tp in setup.items():
        row = {"source": src, **tp.ground.summary()}
        rows = [r for r in originals if r["source"] == src]
        if rows:
            n = np.array([r.get("dynamics_n") or 1 for r in rows], dtype=float)

            def mean(k, rows=rows, n=n):
                return float(np.average([r.get(k) or 0.0 for r in rows], weights=n))

            parts: dict[str, float] = {}
            for r, w in zip(rows, n, strict=True):
                for part, share in (r.get("ground_parts") or {}).items():
                    parts[part] = parts.get(part, 0.0) + share * w / n.sum()
            missing, above = mean("support_missing_share"), mean("support_above_floor_share")
            high = [(r["support_above_floor_mm"], w) for r, w in zip(rows, n, strict=True)
                    if r.get("support_above_floor_mm") is not None]  # fmt: skip
            above_mm = (
                float(np.average([h for h, _ in high], weights=[w for _, w in high]))
                if high
                else None
            )
            held = mean("support_held_share")
            flag, why = support_verdict(missing, above, row["floor_fits"], above_mm, held)
            row.update(
                original_residual_force_bw=mean("residual_force_bw"), ground_parts=parts,
                support_missing_share=missing, support_above_floor_share=above,
                support_held_share=held, dynamics_unmeasured_n=int(
                    sum(r.get("dynamics_unmeasured_n") or 0 for r in rows)),
                support_above_floor_mm=above_mm, support_off_floor=flag, support_why=why,
            )  # fmt: skip
        out.append(row)
    return out


def floors_markdown(floors: Sequence[dict]) -> str:
    """The trials whose floor does not fit, with how far their planted feet depart from it (their
    float and penetration are not scored), the trials whose support is off the floor and why,
    and the original's residual force over the trials where floor and support are found."""
    bad = [f for f in floors if not f["floor_fits"]]
    if not bad:
        lines = [f"The floor fits every one of the {len(floors)} trials."]
    else:
        lines = [
            f"Floor does not fit {len(bad)} of {len(floors)} trials (float and penetration not "
            "scored there):",
            "",
            "| trial | deviation (mm) | spread (mm) | drift (mm) | below (mm) | footprints |",
            "|---|---|---|---|---|---|",
        ]
        keys = ("floor_deviation_mm", "floor_spread_mm", "floor_drift_mm", "floor_below_mm")
        for f in bad:
            cells = " | ".join("-" if f[k] is None else f"{f[k]:.1f}" for k in keys)
            lines.append(f"| {Path(f['source']).stem} | {cells} | {f['floor_footprints']} |")
    off = [f for f in floors if f.get("support_off_floor")]
    if off:
        lines += ["", f"Support off the floor in {len(off)} of {len(floors)} trials:", "",
                  "| trial | original's residual force (BW) | why |", "|---|---|---|"]  # fmt: skip
        for f in off:
            lines.append(
                f"| {Path(f['source']).stem} | {f['original_residual_force_bw']:.3f} "
                f"| {f['support_why']} |"
            )
    parts = {Path(f["source"]).stem: f["ground_parts"] for f in floors if f.get("ground_parts")}
    if parts:
        lines += ["", "Body points other than the feet on the floor (share of the original's "
                  "frames): " + "; ".join(
                      f"{t}: " + ", ".join(f"{p} {100 * x:.1f} %" for p, x in ps.items())
                      for t, ps in parts.items())]  # fmt: skip
    return "\n".join(lines)


def _trial_chunks(cases: Sequence[Case], size: int) -> list[list[int]]:
    """Positions of consecutive cases of one trial, at most ``size`` per chunk (the tasks of
    :func:`evaluate`)."""
    out: list[list[int]] = []
    for i, c in enumerate(cases):
        if out and cases[out[-1][0]].clip.source == c.clip.source and len(out[-1]) < size:
            out[-1].append(i)
        else:
            out.append([i])
    return out


def _evaluate_chunk(item, *, method_names, counts, seed) -> list[tuple[int, list[dict]]]:
    """One task of :func:`evaluate`: per case of ``item = ([(position, case)...], physics set-up
    or None, simulated body or None)``, its position and rows: the original's (with physics),
    then each method at each W."""
    cases, phys, body = item
    out = []
    for position, case in cases:
        rows, original_qpos = [], None
        if phys is not None:  # the original's row, then the noise floor's
            analysis = phys.analyse(case.clip)
            original_qpos = analysis["per_frame"]["qpos"]
            sim = body.run(original_qpos, case.clip.fps) if body is not None else {}
            key = {"source": case.clip.source, "start_frame": case.clip.start_frame}
            rows.append(
                {**key, "method": "original", "keyframes": case.clip.n_frames,
                 **physics_figures(analysis), **sim}
            )  # fmt: skip
            noisy = phys.noise_floor(case.clip, seed=clip_seed(seed, case.index, 0))
            rows.append(
                {**key, "method": NOISE_FLOOR, "keyframes": case.clip.n_frames,
                 **noise_figures(physics_figures(noisy, analysis), rows[-1])}
            )  # fmt: skip
        for name in method_names:
            for W in counts:
                t0 = time.perf_counter()
                k = methods.select(name, case.clip, W, seed=clip_seed(seed, case.index, W))
                ms = 1000.0 * (time.perf_counter() - t0)
                rows.append(
                    {
                        "source": case.clip.source,
                        "start_frame": case.clip.start_frame,
                        "method": name,
                        "keyframes": W,
                        "indices": k.tolist(),
                        **score(case, k, name, phys, body, original_qpos),
                        "decision_ms": ms,
                    }
                )
        out.append((position, rows))
    return out


def table3_markdown(results: Sequence[dict]) -> str:
    """Markdown table of mean Q per method (rows) and W (columns), the paper's figure beside ours
    where it has one, then the chart-free errors."""
    results = [r for r in results if r["method"] not in ("original", NOISE_FLOOR)]
    counts = sorted({r["keyframes"] for r in results})
    names = list(dict.fromkeys(r["method"] for r in results))
    by = {(r["method"], r["keyframes"]): r for r in results}
    head = "| method | " + " | ".join(f"Q, W={W} (paper)" for W in counts) + " |"
    lines = [head, "|---|" + "---|" * len(counts)]
    for name in names:
        paper = PAPER_TABLE3.get(PAPER_NAMES.get(name, ""), {})
        cells = []
        for W in counts:
            r = by.get((name, W))
            ours = f"{r['mean_q']:.4f}" if r else "-"
            cells.append(f"{ours} ({paper[W]:.4f})" if W in paper else ours)
        label = f"{name} ({PAPER_NAMES[name]})" if name in PAPER_NAMES else name
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(
        "| method | W | clips | Q | Q of its keyframes, Hermite | geodesic (deg) | MPJPE (mm) "
        "| velocity error (m/s) | Li error (mm) | median decision (ms) |"
    )
    lines.append("|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        lines.append(
            f"| {r['method']} | {r['keyframes']} | {r['clips']} | {r['mean_q']:.4f} "
            f"| {r['mean_q_hermite']:.4f} | {r['mean_geodesic_deg']:.2f} | {r['mpjpe_mm']:.1f} "
            f"| {r['mean_velocity_error']:.3f} | {r['mean_li_error_mm']:.1f} "
            f"| {r['median_decision_ms']:.2f} |"
        )
    return "\n".join(lines)


def physics_markdown(results: Sequence[dict], stat: str = "mean") -> str:
    """Markdown table of the :mod:`sim.physics` means (``stat="median"``: medians) over clips per
    method and W: ``original`` first, then the ``noise floor`` (per figure, how far the original
    re-captured with marker noise departs from it), then the methods. ``|JT - orig|``: the joint
    torque RMS's distance from the original's (over-smoothed motion needs less than the
    original, not better); PhysDiff columns are Yuan et al.'s definitions."""
    rows = [r for r in results if "residual_force_bw" in r]
    rows.sort(key=lambda r: (r["method"] != "original", r["method"] != NOISE_FLOOR))
    cols = (
        ("Q", "mean_q", ".4f"), ("pen. (mm)", "penetration_mm", ".1f"),
        ("float (mm)", "float_mm", ".1f"), ("skate (mm/s)", "skate_mm_s", ".0f"),
        ("contact P", "contact_precision", ".2f"), ("contact R", "contact_recall", ".2f"),
        ("PhysDiff penetrate (mm)", "physdiff_penetrate_mm", ".1f"),
        ("PhysDiff float (mm)", "physdiff_float_mm", ".1f"),
        ("PhysDiff skate", "physdiff_skate", ".3f"),
        ("self-pen. excess (mm)", "self_pen_excess_mm", ".2f"),
        ("lost contacts", "lost_contacts", ".1f"), ("limit excess (deg)", "limit_excess_deg", ".2f"),
        ("residual force (BW)", "residual_force_bw", ".3f"),
        ("residual force p95 (BW)", "residual_force_bw_p95", ".2f"),
        ("residual torque (N m/kg)", "residual_torque_nm_kg", ".3f"),
        ("joint torque RMS (N m/kg)", "joint_torque_rms_nm_kg", ".3f"),
        ("\\|JT - orig\\| (N m/kg)", "joint_torque_rms_nm_kg_distance", ".3f"),
    )  # fmt: skip
    lines = [
        "| method | W | clips | " + " | ".join(c[0] for c in cols) + " |",
        "|---|---|---|" + "---|" * len(cols),
    ]
    for r in rows:
        vals = [
            r.get(k) if stat == "mean" or k == "mean_q" else r.get(f"{k}_median")
            for _, k, f in cols
        ]
        cells = [
            "-" if v is None else format(v, f) for v, (_, _, f) in zip(vals, cols, strict=True)
        ]
        lines.append(
            f"| {r['method']} | {r['keyframes']} | {r['clips']} | " + " | ".join(cells) + " |"
        )
    return "\n".join(lines)


def simulate_markdown(results: Sequence[dict]) -> str:
    """Markdown table of the forward-simulation means per method and W (``original`` first): the
    torque-limited body tracking each motion's IK fit with no assistance."""
    rows = [r for r in results if r.get("sim_error_mm") is not None]
    rows.sort(key=lambda r: r["method"] != "original")
    lines = [
        "| method | W | clips | error vs tracked (mm) | error vs original (mm) | fell (share) "
        "| fall time (s) | joint torque RMS (N m/kg) | torque at limit (share) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        fall = "-" if r["sim_fall_s"] is None else f"{r['sim_fall_s']:.2f}"
        lines.append(
            f"| {r['method']} | {r['keyframes']} | {r['clips']} | {r['sim_error_mm']:.1f} "
            f"| {r['sim_error_original_mm']:.1f} | {r['sim_fell']:.2f} | {fall} "
            f"| {r['sim_torque_rms_nm_kg']:.3f} | {r['sim_torque_saturated']:.3f} |"
        )
    return "\n".join(lines)
