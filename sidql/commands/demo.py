"""``sidql demo``: the main job on CMU trial 02_01, or on motion generated on the humanoid when the
data folder lacks it (what ``./run.sh demo`` runs)."""

from __future__ import annotations

import json
from pathlib import Path

from sidql.commands.ingest import describe
from sidql.commands.usage import (
    add_data,
    add_keyframes,
    add_methods,
    add_quiet,
    check_keyframes,
    data_folder,
)
from sidql.evaluation.report import report_clips
from sidql.evaluation.validation import joint_ranges
from sidql.keyframes.methods import available, reconstruction_of
from sim.model.humanoid import humanoid_model
from sim.motion.clip import save_npz
from sim.motion.ingest import load_motion
from sim.motion.synthetic import synthetic_motion
from sim.motion.trial import subject_model

DEFAULT_TRIAL = ("02", "02_01")

DESCRIPTION = (
    "Ingest CMU trial 02_01 from the data folder and print its summary; without it (no folder, or "
    "no 02/02.asf and 02/02_01.amc in it), generate 8 s of motion on the shared humanoid instead "
    "(every hinge a sum of sinusoids inside its joint limits, the root travelling and turning: "
    "sim.motion.synthetic, seed 0). Then choose keyframes of the first 60-frame clip with every "
    "method, reconstruct, replay in MuJoCo, fit the humanoid for the contact and dynamics checks, "
    "render and write the HTML report (OUT/report/index.html)."
)


def register(p) -> None:
    add_data(p, "folder of CMU trials holding 02/02.asf and 02/02_01.amc")
    p.add_argument("--out", default="out/demo", metavar="DIR", help="output folder")
    add_keyframes(p, "keyframes W of the report's clip", default=10)
    add_methods(p, None, "keyframe methods (default: every registered one)")
    p.add_argument("--no-report", action="store_true", help="stop after ingesting")
    add_quiet(p)
    p.set_defaults(func=run)


def default_clip(data: str | Path | None):
    """The demo's motion: CMU trial 02_01 (walk) if present under ``data``, else synthetic
    motion."""
    subject, trial = DEFAULT_TRIAL
    if data is not None:
        asf, amc = Path(data) / subject / f"{subject}.asf", Path(data) / subject / f"{trial}.amc"
        if asf.exists() and amc.exists():
            return load_motion(asf, amc)
    print(f"no CMU trial {trial} in {data or 'no data folder'}: using synthetic motion "
          "generated on the humanoid")  # fmt: skip
    return synthetic_motion(8.0, seed=0)


def run(args) -> int:
    check_keyframes(args, 60)
    args.data = data_folder(args, required=False)
    clip = default_clip(args.data)
    print(describe(clip))
    path = save_npz(clip, Path(args.out) / "motion.npz")
    print(f"wrote {path}")
    if args.no_report:
        return 0
    return report_step(clip, args)


def report_step(clip, args) -> int:
    """Keyframes by every method on the first 60-frame clip, reconstruction, replay, report."""
    subject, _ = DEFAULT_TRIAL
    asf = Path(args.data or ".") / subject / f"{subject}.asf"
    model = subject_model(asf)[1] if clip.source and asf.exists() else humanoid_model()[1]
    # Hermite methods first: a method meant for another reconstruction is then shown under the
    # Hermite only where no earlier method already shows its keyframes (cartesian's = uniform's).
    methods = args.methods or sorted(available(), key=lambda m: reconstruction_of(m) != "hermite")
    first = clip.slice(0, min(60, clip.n_frames))
    page = report_clips(
        [first], Path(args.out) / "report", W=args.W, methods=methods,
        joint_ranges=joint_ranges(model), title=f"Replay checks: {Path(clip.source).name or 'synthetic'}",
        meta={"source": clip.source or "synthetic motion", "clip": "frames 0-59 at 30 fps"},
        model=model, progress=not args.quiet,
    )  # fmt: skip
    print(summary_table(Path(args.out) / "report" / "checks.json"))
    print(f"report: {page.resolve()}")
    return 0


def summary_table(checks_path: Path) -> str:
    """The report's headline figures per method, as a Markdown table for the terminal."""
    doc = json.loads(Path(checks_path).read_text())
    clip = doc["clips"][0]
    rows = [
        f"W = {clip['keyframes']}, {clip['frames']} frames; contacts against the original's, "
        "residual force in body weights (the original's in the first row)",
        "| method | reconstruction | keyframes | MPJPE mm | vel. err mm/s | float mm | skate mm/s "
        "| residual BW |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def physics(entry, key, fmt):
        value = entry.get("physics", {}).get(key)
        return "n/a" if value is None else fmt.format(value)

    o = clip["original"]
    rows.append(
        f"| original | - | all | 0.0 | 0 | {physics(o, 'float_mm', '{:.1f}')} | "
        f"{physics(o, 'skate_mm_s', '{:.0f}')} | {physics(o, 'residual_force_bw', '{:.2f}')} |"
    )
    for m in clip["methods"]:
        s = m["summary"]
        rows.append(
            f"| {m['method']} | {m['reconstruction']} | {' '.join(map(str, m['indices']))} | "
            f"{s['mpjpe_mm']:.1f} | {s['velocity_error_mm_s']:.0f} | "
            f"{physics(m, 'float_mm', '{:.1f}')} | {physics(m, 'skate_mm_s', '{:.0f}')} | "
            f"{physics(m, 'residual_force_bw', '{:.2f}')} |"
        )
    return "\n".join(rows)
