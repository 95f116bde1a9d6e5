"""The codec with foot contacts: skating in contact and floor penetration at equal rate.

    python benchmarks/codec_physics.py [--data ../shared/cmu] [--rates 200 400 800]

Every trial of ``--data`` (at least 60 frames, 30 fps, its own skeleton; as
``bench_codec_rd.py``) is encoded at each rate (B/s, whole file) by three variants of
``sidql encode``: the codec as it is (the position coding, ``auto``), ``--contacts`` (the
sender's foot-contact bits and floor in the stream, the decoder pins each foot in contact; the
section's bytes come out of the rate) and ``--physics`` (the same, and the physical cost in the
keyframe programme, :mod:`sidql.codec.contact_coding`), ``--physics`` also at 10x its weight.
Every decoded stream is judged against the trial's original (MuJoCo's forward kinematics of the
ASF/AMC), on the original's floor (:func:`sim.physics.ground.estimate_ground` of its 23 protocol
points over the whole trial) and contacts (:func:`sim.physics.contacts.motion_contacts`), by the
project's contact metrics (:func:`sim.physics.contact_metrics.contact_metrics`): skating in
contact (horizontal speed of the foot's lowest sole point on the original's contact frames
[mm/s]), penetration (depth below the floor, every frame [mm]) and float (height above it on
the original's contact frames [mm]), pooled over all trials' samples; and the mean joint
position error [mm]. Beside them the original's own figures (ground truth) and its figures
re-captured with 1.5 mm of marker noise (the noise floor, :func:`sim.physics.noise.noisy_original`).
A (trial, rate) that a variant cannot meet is left out of every variant.

``bench_codec_rd.py --physics`` appends the same table to its page; run alone, this writes
``docs/results/codec_physics.md``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from results import load_trials, write_results  # noqa: E402

from sidql.codec.contact_coding import encode_with_contacts  # noqa: E402
from sidql.codec.decode import reconstruct_stream  # noqa: E402
from sidql.codec.encode import encode_clip  # noqa: E402
from sidql.keyframes.physical_costs import PHYSICS_WEIGHT  # noqa: E402
from sidql.keyframes.spherical import POINTS, protocol_indices  # noqa: E402
from sim.errors import UnmetTargetError  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402
from sim.physics.contact_metrics import contact_metrics  # noqa: E402
from sim.physics.contacts import motion_contacts  # noqa: E402
from sim.physics.ground import estimate_ground  # noqa: E402
from sim.physics.noise import noisy_original  # noqa: E402

RATES = (200.0, 400.0, 800.0)
#: (label, encoder of a clip at a rate).
VARIANTS = (
    ("codec", lambda c, r: encode_clip(c, rate=r)),
    ("codec + contacts", lambda c, r: encode_with_contacts(c, rate=r)),
    ("codec + physics + contacts", lambda c, r: encode_with_contacts(c, rate=r, physics=True)),
    ("codec + physics x10 + contacts",
     lambda c, r: encode_with_contacts(c, rate=r, physics=True, weight=10 * PHYSICS_WEIGHT)),
)  # fmt: skip
#: The pooled figures: (key, column title, format).
FIGURES = (("skate_mm_s", "skating in contact (mm/s)", ".0f"),
           ("penetration_mm", "penetration (mm)", ".2f"),
           ("float_mm", "float (mm)", ".1f"))  # fmt: skip


class Judge:
    """One trial's original: its 23 points, floor and contact labels."""

    def __init__(self, clip):
        self.clip = clip
        self.points = clip.positions[:, protocol_indices(clip)]
        self.fps = clip.fps
        self.ground = estimate_ground(self.points, POINTS, self.fps)
        self.ref = motion_contacts(self.points, POINTS, self.fps, self.ground)

    def figures(self, positions: np.ndarray) -> dict:
        """Contact metrics (with their sample counts) and the mean point error [mm]."""
        m = contact_metrics(
            self.ref.contact, motion_contacts(positions, POINTS, self.fps, self.ground)
        )
        m["error_mm"] = 1e3 * float(np.linalg.norm(positions - self.points, axis=-1).mean())
        m["error_n"] = positions.shape[0] * positions.shape[1]
        return m

    def noisy(self) -> np.ndarray:
        z = np.zeros_like(self.points)
        return noisy_original(self.points, z, z, self.fps, self.fps, seed=0)[0]


def measure(clips, rates=RATES, progress=True) -> dict:
    """``{"rows": {(label, rate): [per-trial figures]}, "original": [...], "noise": [...],
    "left_out": [(trial, rate, problem)]}``."""
    out = {"rows": {}, "original": [], "noise": [], "left_out": [], "seconds": 0.0}
    for clip in clips:
        judge = Judge(clip)
        out["original"].append(judge.figures(judge.points))
        out["noise"].append(judge.figures(judge.noisy()))
        for rate in rates:
            got = {}
            try:
                for label, enc in VARIANTS:
                    e = enc(clip, rate)
                    got[label] = judge.figures(reconstruct_stream(e.stream).positions)
                    got[label]["bytes"] = len(e.data)
            except UnmetTargetError as err:
                out["left_out"].append((Path(clip.source).name, rate, str(err)))
                continue
            for label, f in got.items():
                f["seconds"] = clip.n_frames / clip.fps
                out["rows"].setdefault((label, rate), []).append(f)
        if progress:
            print(f"{Path(clip.source).name}: {clip.n_frames} frames", file=sys.stderr)
    return out


def pooled(rows: list[dict], key: str) -> float:
    """Mean of ``key`` over all samples of all trials (each trial weighted by its count)."""
    n = np.array([r[key.replace("_mm_s", "").replace("_mm", "") + "_n"] for r in rows], float)
    v = np.array([r[key] for r in rows], float)
    ok = n > 0
    return float((v[ok] * n[ok]).sum() / n[ok].sum()) if ok.any() else float("nan")


def markdown(out: dict, rates=RATES) -> str:
    """The table: per rate and variant, B/s, mean error and the pooled contact figures; the
    original's and the noise floor's figures."""
    head = " | ".join(t for _, t, _ in FIGURES)
    lines = [f"| rate asked (B/s) | variant | trials | B/s | mean error (mm) | {head} |",
             "|---:|---|---:|---:|---:|" + "---:|" * len(FIGURES)]  # fmt: skip
    for rate in rates:
        for label, _ in VARIANTS:
            rows = out["rows"].get((label, rate), [])
            if not rows:
                continue
            bps = sum(r["bytes"] for r in rows) / sum(r["seconds"] for r in rows)
            cells = [format(pooled(rows, k), f) for k, _, f in FIGURES]
            lines.append(f"| {rate:g} | {label} | {len(rows)} | {bps:.0f} | "
                         f"{pooled(rows, 'error_mm'):.2f} | " + " | ".join(cells) + " |")  # fmt: skip
    for label, key in (("original (ground truth)", "original"), ("noise floor", "noise")):
        cells = [format(pooled(out[key], k), f) for k, _, f in FIGURES]
        err = pooled(out[key], "error_mm")
        lines.append(f"| | {label} | {len(out[key])} | | {err:.2f} | " + " | ".join(cells) + " |")
    if out["left_out"]:
        lines.append("")
        lines.append(
            "Left out: " + "; ".join(f"{t} at {r:g} B/s" for t, r, _ in out["left_out"]) + "."
        )
    return "\n".join(lines)


def section(clips, rates=RATES) -> str:
    """The table with its heading, for ``bench_codec_rd.py --physics``."""
    return ("**Foot contacts at equal rate** (`benchmarks/codec_physics.py`):\n\n"
            + markdown(measure(clips, rates, progress=False), rates))  # fmt: skip


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--rates", type=float, nargs="+", default=list(RATES))
    ap.add_argument(
        "--trials", type=int, default=None, help="only the first N trials (a quick look)"
    )
    ap.add_argument("--no-write", action="store_true", help="print only (no docs/results file)")
    a = ap.parse_args(argv)
    t0, c0 = time.perf_counter(), time.process_time()
    clips, skipped = load_trials(a.data)
    clips = clips[: a.trials]
    out = measure(clips, a.rates)
    seconds = sum(c.n_frames / c.fps for c in clips)
    body = (
        f"{len(clips)} CMU trials of `{a.data.name}` ({seconds:.0f} s at 30 fps; left out: "
        f"{', '.join(skipped) or 'none'}), each encoded whole at each rate. Figures pooled over "
        "all trials' samples, on the original's floor and contact frames (module docstring of "
        "`benchmarks/codec_physics.py`); B/s counts every byte of the files, the contact "
        "section included.\n\n" + markdown(out, a.rates)
        + f"\n\n{time.perf_counter() - t0:.0f} s wall, {time.process_time() - c0:.0f} s CPU."
    )  # fmt: skip
    print(body)
    if not a.no_write:
        cmd = "python benchmarks/codec_physics.py"
        if a.trials is not None:
            cmd += f" --trials {a.trials}"
        if tuple(a.rates) != RATES:
            cmd += " --rates " + " ".join(f"{r:g}" for r in a.rates)
        print(
            write_results(
                "codec_physics",
                "Codec with foot contacts: skating and penetration at equal rate",
                body,
                cmd,
            )
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
