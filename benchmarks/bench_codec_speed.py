"""Codec speed where users feel it: ``sidql encode`` of a 5-minute take, CLI start-up included.

    python benchmarks/bench_codec_speed.py [--data ../shared/cmu] [--repeats 3]

A 5-minute AMC (36,920 frames at 120 fps, 307.7 s) is written to a temporary folder from the
longest trial of ``--data`` played forwards and backwards (no jumps), and encoded by the command
line exactly as a user would (``sidql encode ASF AMC --out F --rate 942``: start-up, reading,
retargeting, charting, encoding at 30 fps, writing), best of ``--repeats`` wall times. In the same
run: ``sidql --help`` (start-up alone), the same encode with ``--max-error 3``, the angle coding
(``--max-q``, the pre-position coder's path), and the in-process steps (read + retarget, chart,
position encoding with ``auto``, decoding). Figures are multiples of real time (307.7 s over the
wall time) and ratios between the rows; the machine's load is printed with them.
Target: ``sidql encode --rate 942`` of the take at >= 100x real time, auto included.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from results import write_results  # noqa: E402

FRAMES = 36920  # 5 min 7.7 s at 120 fps


def default_data() -> Path:
    for base in (REPO.parent, REPO.parent.parent):
        if (base / "shared" / "cmu").is_dir():
            return base / "shared" / "cmu"
    return REPO.parent / "shared" / "cmu"


def five_minute_take(data: Path, out: Path) -> tuple[Path, Path, str]:
    """Write a 36,920-frame AMC of the longest trial of ``data`` played forwards and backwards."""
    from sim.acclaim.amc import parse_amc
    from sim.acclaim.asf import parse_asf
    from sim.acclaim.records import Motion
    from sim.acclaim.writer import write_amc
    from sim.motion.dataset import find_trials

    trials = find_trials(data)
    longest = max(trials, key=lambda t: Path(t.amc).stat().st_size)
    skel = parse_asf(longest.asf)
    m = parse_amc(longest.amc, skel)
    idx, forwards = [], True
    while len(idx) < FRAMES:
        r = np.arange(m.n_frames) if forwards else np.arange(m.n_frames - 1, -1, -1)
        idx.extend(r[1:] if idx else r)
        forwards = not forwards
    idx = np.array(idx[:FRAMES])
    long = Motion(
        path="", root=m.root[idx], angles={k: v[idx] for k, v in m.angles.items()}, first_frame=1
    )
    amc = out / "five_minutes.amc"
    write_amc(amc, skel, long, comment=f"{Path(longest.amc).name} forwards and backwards")
    return Path(longest.asf), amc, Path(longest.amc).name


def wall(cmd: list[str], repeats: int) -> float:
    best = np.inf
    env = dict(os.environ, PYTHONPATH=str(REPO))
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, env=env, capture_output=True)
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    seconds = FRAMES / 120.0
    sidql = [sys.executable, "-m", "sidql.commands.main"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        asf, amc, source = five_minute_take(args.data, tmp)
        out = str(tmp / "f.sidq")
        enc = [*sidql, "encode", str(asf), str(amc), "--out", out]
        wall([*enc, "--rate", "942"], 1)  # compiled kernels cached, files in the page cache
        rows = {
            "sidql --help": wall([*sidql, "--help"], args.repeats),
            "sidql encode --rate 942 (auto)": wall([*enc, "--rate", "942"], args.repeats),
            "sidql encode --max-error 3 (auto)": wall([*enc, "--max-error", "3"], args.repeats),
            "sidql encode --max-q 0.003 (angle coding, auto)": wall(
                [*enc, "--max-q", "0.003"], args.repeats
            ),
        }
        from sidql.codec import format as sidq
        from sidql.codec.decode import reconstruct_stream
        from sidql.codec.encode import encode_series
        from sidql.keyframes.spherical import chart
        from sim.motion.ingest import load_motion

        def best(fn):
            b = np.inf
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                r = fn()
                b = min(b, time.perf_counter() - t0)
            return b, r

        t_load, clip = best(lambda: load_motion(asf, amc, derivatives=False))
        t_chart, s = best(lambda: chart(clip))
        t_enc, e = best(lambda: encode_series(s, rate=942.0))
        t_dec, _ = best(lambda: reconstruct_stream(sidq.from_bytes(e.data)))
        steps = {
            "read + retarget (load_motion, as encode: no source derivatives)": t_load,
            "chart": t_chart,
            "position encoding, auto (encode_series)": t_enc,
            "decoding, bytes -> points": t_dec,
        }
    load = os.getloadavg()
    lines = [
        f"A {seconds:.1f} s take ({FRAMES:,} frames at 120 fps: `{source}` forwards and backwards), "
        f"encoded at 30 fps; best of {args.repeats} wall times; load average "
        f"{load[0]:.1f} / {load[1]:.1f} (1 / 5 min) at the end, {os.cpu_count()} cores.",
        "",
        "| | seconds | x real time |",
        "|---|---|---|",
    ]
    for k, v in {**rows, **steps}.items():
        x = f"{seconds / v:.0f}x" if k != "sidql --help" else "-"
        lines.append(f"| {k} | {v:.3f} | {x} |")
    r = rows["sidql encode --rate 942 (auto)"]
    lines += [
        "",
        f"`sidql encode --rate 942` of the take: {seconds / r:.0f}x real time (aim: at least "
        "100x); start-up (`sidql --help`) is "
        f"{rows['sidql --help'] / r:.1%} of it, reading and retargeting {t_load / r:.0%}, the "
        f"encoder itself {t_enc / r:.0%}. The angle coding takes "
        f"{rows['sidql encode --max-q 0.003 (angle coding, auto)'] / r:.2f}x as long.",
    ]
    text = "\n".join(lines)
    print(text)
    if not args.no_write:
        print(
            "wrote",
            write_results(
                "codec_speed",
                "Codec speed: a 5-minute take through the command line",
                text,
                command="python benchmarks/bench_codec_speed.py",
            ),
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
