"""BVH round trip: every CMU trial written as BVH and ingested back, against its AMC.

Usage: .venv/bin/python benchmarks/bench_bvh.py [--data CMU_DIR] [--real DIR] [--write]

Per trial: the largest distance [mm] between a point of the AMC's clip and the same point of the
BVH's (``load_motion``, 30 fps), on the subject's own humanoid and on the shared one (the issue's
target: 0.1 mm), and the BVH's size against the AMC's. Reading speed: the BVH reader (skeleton
and motion, ``parse_bvh`` + ``to_acclaim``) against the AMC readers (``parse_asf`` +
``parse_amc``) on the same trials in the same run, source frames per second of this process's CPU
time. ``--real DIR``: BVH files of other skeletons (not in the repository; the table names where
they came from): each segment of the subject humanoid built from a file against the file's
OFFSETs, and every point of its clip against an independent forward kinematics of the file (a
parser and scipy rotations written here, sharing nothing with ``sim.bvh``). ``--write`` writes
``docs/results/bvh.md``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from sim.acclaim.amc import parse_amc  # noqa: E402
from sim.acclaim.asf import parse_asf  # noqa: E402
from sim.bvh.convert import to_acclaim  # noqa: E402
from sim.bvh.reader import parse_bvh  # noqa: E402
from sim.bvh.writer import write_bvh  # noqa: E402
from sim.errors import MotionDataWarning  # noqa: E402
from sim.motion.dataset import find_trials  # noqa: E402
from sim.motion.ingest import load_motion  # noqa: E402
from sim.motion.trial import (
    read_trial,  # noqa: E402
    subject_model,  # noqa: E402
)
from sim.paths import default_data_dir  # noqa: E402


def point_error_mm(a, b) -> float:
    return float(np.linalg.norm(a.positions - b.positions, axis=-1).max() * 1000)


def oracle_points(text: str, metres: float) -> tuple[np.ndarray, np.ndarray, float]:
    """(T, J, 3) every joint's and End Site's position [m, z up] of a y-up BVH text, its (J,)
    OFFSET lengths [m] (the ROOT's excluded: NaN) and its rate, by a parser of its own and scipy's
    intrinsic Euler rotations (``"ZXY"`` = ``Rz Rx Ry``)."""
    from scipy.spatial.transform import Rotation

    tokens = text.split()
    i, nodes, stack = 0, [], []
    while tokens[i] != "MOTION":
        t = tokens[i]
        if t in ("ROOT", "JOINT") or (t == "End" and tokens[i + 1] == "Site"):
            nodes.append({"parent": stack[-1] if stack else -1, "channels": []})
            i += 2
        elif t == "{":
            stack.append(len(nodes) - 1)
            i += 1
        elif t == "}":
            stack.pop()
            i += 1
        elif t == "OFFSET":
            nodes[stack[-1]]["offset"] = np.array([float(x) for x in tokens[i + 1 : i + 4]])
            i += 4
        elif t == "CHANNELS":
            n = int(tokens[i + 1])
            nodes[stack[-1]]["channels"] = tokens[i + 2 : i + 2 + n]
            i += 2 + n
        else:
            i += 1
    frames, dt = int(tokens[i + 2]), float(tokens[i + 5])
    table = np.array([float(x) for x in tokens[i + 6 :]]).reshape(frames, -1)
    p, R, col = np.zeros((frames, len(nodes), 3)), [None] * len(nodes), 0
    for k, n in enumerate(nodes):
        block = table[:, col : col + len(n["channels"])]
        col += len(n["channels"])
        rot = [c for c, ch in enumerate(n["channels"]) if ch.endswith("rotation")]
        order = "".join(n["channels"][c][0] for c in rot)
        local = (
            Rotation.from_euler(order, block[:, rot], degrees=True).as_matrix()
            if rot
            else np.eye(3)
        )
        if n["parent"] < 0:
            p[:, k] = n["offset"]
            for c, ch in enumerate(n["channels"]):
                if ch.endswith("position"):
                    p[:, k, "XYZ".index(ch[0])] = block[:, c]
            R[k] = np.broadcast_to(local, (frames, 3, 3))
        else:
            p[:, k] = p[:, n["parent"]] + np.einsum("tij,j->ti", R[n["parent"]], n["offset"])
            R[k] = R[n["parent"]] @ local
    lengths = np.array([np.linalg.norm(n["offset"]) if n["parent"] >= 0 else np.nan for n in nodes])
    p *= metres
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1), lengths * metres, 1.0 / dt


def real_files(folder: Path) -> str:
    """The table of ``--real``: per file, segments against OFFSETs and points against the oracle."""
    rows = []
    for path in sorted(folder.glob("*.bvh")):
        take = to_acclaim(parse_bvh(path))
        skeleton, model = subject_model(path)
        expected, lengths, _ = oracle_points(
            path.read_text(), {"m": 1, "cm": 0.01, "mm": 0.001, "in": 0.0254}[take.unit]
        )
        segments = np.array(
            [np.linalg.norm(model.site(f"{b.name}_end").pos) for b in skeleton.bones]
        )
        offsets = lengths[~np.isnan(lengths)]
        # every segment is one OFFSET, every non-zero OFFSET a segment
        seg_err = max(np.abs(offsets - s).min() for s in segments)
        off_err = max(np.abs(segments - o).min() for o in offsets)
        clip = load_motion(path, fps=take.fps, derivatives=False)
        d = np.linalg.norm(expected[:, :, None] - clip.positions[:, None], axis=-1)
        point_err = max(d.min(axis=2).max(), d.min(axis=1).max())
        rows.append(
            f"| {path.name} | {len(take.skeleton.bones)} bones from {len(lengths)} joints and End "
            f"Sites, {clip.n_frames} frames at {take.fps:g} fps, unit {take.unit} (detected) | "
            f"{max(seg_err, off_err) * 1000:.2e} | {point_err * 1000:.2e} |"
        )
        print(rows[-1], flush=True)
    return (
        "| file | read as | segment vs OFFSET [mm] | points vs independent FK [mm] |\n|---|---|---|---|\n"
        + "\n".join(rows)
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--real", type=Path, help="a folder of BVH files of other skeletons")
    ap.add_argument("--write", action="store_true", help="write docs/results/bvh.md")
    args = ap.parse_args()
    real = real_files(args.real) if args.real else ""
    warnings.simplefilter("ignore", MotionDataWarning)
    trials = find_trials(args.data)
    rows, frames, t_bvh, t_amc = [], 0, 0.0, 0.0
    worst = {"subject": 0.0, "humanoid": 0.0}
    velocity = {"subject": [], "humanoid": []}
    with tempfile.TemporaryDirectory() as tmp:
        for t in trials:
            skeleton, motion, fps = read_trial(t.asf, t.amc)
            path = write_bvh(Path(tmp) / f"{t.name}.bvh", skeleton, motion, fps)
            errors, speeds = [], []
            for which in worst:
                a = load_motion(t.asf, t.amc, skeleton=which, derivatives=False)
                b = load_motion(path, skeleton=which, derivatives=False)
                assert a.names == b.names
                errors.append(point_error_mm(a, b))
                worst[which] = max(worst[which], errors[-1])
                dv = np.linalg.norm(a.velocities - b.velocities, axis=-1)
                speeds.append(dv.ravel())
                velocity[which].append(dv.ravel())
            start = time.process_time()
            to_acclaim(parse_bvh(path))
            t_bvh += time.process_time() - start
            start = time.process_time()
            parse_amc(t.amc, parse_asf(t.asf))
            t_amc += time.process_time() - start
            frames += motion.n_frames
            ratio = path.stat().st_size / Path(t.amc).stat().st_size
            v = [f"{np.percentile(x, 99) * 1000:.1f} / {x.max() * 1000:.0f}" for x in speeds]
            rows.append(
                f"| {t.name} | {motion.n_frames:,} | {errors[0]:.6f} | {errors[1]:.6f} | "
                f"{v[0]} | {v[1]} | {ratio:.2f} |"
            )
            print(rows[-1], flush=True)
    text = (
        f"{len(trials)} CMU trials ({frames:,} frames at 120 Hz), each written as BVH (centimetres, "
        "y up, `sim.bvh.writer`) and ingested back at 30 fps; the largest distance of any point in "
        "any frame from the AMC's clip. Target: 0.1 mm.\n\n"
        "True velocities (30 fps, `velocities`: the chain's `J(q) qdot` from central differences "
        "of `qpos`) depend on the model's joints, not only on the points: the BVH's subject "
        "humanoid turns each bone by three Euler hinges about the file's axes where the ASF's "
        "turns it by its dofs about its axis frame, so their finite differences differ at second "
        "order, most at the take's pose jumps; the shared humanoid has the same hinges both "
        "ways. Velocity columns: p99 / max of the difference [mm/s] over every point and "
        "frame.\n\n"
        "| trial | frames | points, subject [mm] | points, shared humanoid [mm] | velocity, "
        "subject [mm/s] | velocity, shared humanoid [mm/s] | BVH / AMC size |\n"
        "|---|---|---|---|---|---|---|\n"
        + "\n".join(rows)
        + f"\n| **worst / all** | | **{worst['subject']:.6f}** | **{worst['humanoid']:.6f}** | "
        + " | ".join(
            f"**{np.percentile(np.concatenate(velocity[k]), 99) * 1000:.1f} / "
            f"{np.concatenate(velocity[k]).max() * 1000:.0f}** (median "
            f"{np.median(np.concatenate(velocity[k])) * 1000:.2f})"
            for k in ("subject", "humanoid")
        )
        + " | |\n\n"
        f"Reading (one process, CPU time): BVH {frames / t_bvh:,.0f} frames/s, ASF + AMC "
        f"{frames / t_amc:,.0f} frames/s in the same run (ratio {t_amc / t_bvh:.2f}x)."
    )
    if real:
        text += (
            "\n\nReal BVH files of other skeletons (`--real`: "
            f"{', '.join(sorted(p.name for p in args.real.glob('*.bvh')))}, from "
            "github.com/20tab/bvh-python `tests/`, commit b7e0058; not in the repository): each "
            "segment of the humanoid built from the file is one of its OFFSETs and each non-zero "
            "OFFSET a segment (largest difference), and every joint and End Site of its clip "
            "against an independent forward kinematics of the file, frame by frame.\n\n" + real
        )
    print(text)
    if args.write:
        from results import write_results

        cmd = "python benchmarks/bench_bvh.py --write" + (" --real DIR" if real else "")
        print("wrote", write_results("bvh", "BVH round trip", text, cmd))


if __name__ == "__main__":
    main()
