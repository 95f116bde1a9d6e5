"""``sidql demo``: the main job on an embedded default (what ``./run.sh demo`` runs)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from sidql.commands.ingest import describe
from sidql.evaluation.report import joint_ranges, report_clips
from sidql.keyframes.methods import available
from sim.model.humanoid import humanoid_model, subject_model
from sim.motion.clip import save_npz
from sim.motion.ingest import load_motion
from sim.motion.synthetic import synthetic_motion

DEFAULT_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "cmu"
DEFAULT_TRIAL = ("02", "02_01")


def register(sub) -> None:
    p = sub.add_parser(
        "demo",
        help="run the main job on the embedded default",
        description="Ingest a real CMU trial (from ../shared/cmu when present, else a motion "
        "generated on the humanoid) and print its summary; then choose keyframes of its first "
        "60-frame clip with every method, reconstruct, replay in MuJoCo, render and write the "
        "HTML report (OUT/report/index.html).",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--data", default=str(DEFAULT_DATA), help="folder of CMU files")
    p.add_argument("--out", default="out/demo", help="output folder")
    p.add_argument("--keyframes", "-W", type=int, default=10, help="keyframes of the report's clip")
    p.add_argument(
        "--methods",
        nargs="+",
        default=None,
        help="keyframe methods (default: every registered one)",
    )
    p.add_argument("--no-report", action="store_true", help="stop after ingesting")
    p.set_defaults(func=run)


def default_clip(data: str | Path):
    """The demo's motion: CMU trial 02_01 (walk) if present, else synthetic motion."""
    subject, trial = DEFAULT_TRIAL
    asf, amc = Path(data) / subject / f"{subject}.asf", Path(data) / subject / f"{trial}.amc"
    if asf.exists() and amc.exists():
        return load_motion(asf, amc)
    print(f"no CMU data at {data}: using synthetic motion generated on the humanoid")
    return synthetic_motion(8.0, seed=0)


def run(args) -> int:
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
    asf = Path(args.data) / subject / f"{subject}.asf"
    model = subject_model(asf)[1] if clip.source and asf.exists() else humanoid_model()[1]
    methods = args.methods or available()
    first = clip.slice(0, min(60, clip.n_frames))
    page = report_clips(
        [first], Path(args.out) / "report", W=args.keyframes, methods=methods,
        joint_ranges=joint_ranges(model), title=f"Replay checks: {Path(clip.source).name or 'synthetic'}",
        meta={"source": clip.source or "synthetic motion", "clip": "frames 0-59 at 30 fps"},
        model=model,
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
