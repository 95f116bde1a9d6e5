"""The motion codec against its anchors, on whole CMU trials.

    python benchmarks/bench_codec.py [--data ../shared/cmu] [--plot docs/codec_rate_distortion.png]

Every trial of ``--data`` is loaded at 30 fps on its own skeleton and cut to a whole number of
60-frame clips (so every scheme covers the same frames; trials shorter than 60 frames are left
out). Errors are averaged over all frames of all trials (frame-weighted): Q (eq. 18, mean
|angle error| [rad]), MPJPE [mm] and mean velocity error [mm/s] over the 23 protocol points.

(a) **paper**: Hermite with transmitted rates, W keyframes per 60-frame clip, float32 pose and
    rates plus an index byte (``sidql.evaluation.rate``'s convention, 377 B per keyframe),
    uniform and per-clip optimal keyframes; bytes/s = W * 377 * 30 / 60.
(b) **codec**: ``sidql encode`` of each whole (cut) trial at the same bytes/s, the whole .sidq
    file counted (header and checksum included), ``auto`` and each reconstruction alone
    (offline: packed coding, 9-16 bits).
(c) **raw + lzma**: every frame's pose quantised to b bits per channel (b = 16 and coarser, same
    grids as the codec) and compressed by stdlib ``lzma`` (preset 9 | extreme, with the delta
    filter over one frame when that is smaller); velocities by finite differences.

Then: the cost of latency (Q against ``--latency`` L at a fixed rate, all trials), and speed on
one core: encoding and decoding a 5-minute trial (the longest trial played forwards and backwards
until 9000 frames), as multiples of real time, and the encoder's memory for N and 2N frames.

Targets: codec Q <= 1/4 of paper-optimal Q at equal bytes/s; encoding >= 100x real time
(5 min in <= 3 s) with O(N G) memory; decoding >= 1000x real time. Everything printed is also
written to ``docs/results/codec_anchors.md``. (The codec against what users would do instead,
by position error: ``benchmarks/bench_codec_rd.py``; through the command line:
``benchmarks/bench_codec_speed.py``.)
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import lzma
import os
import sys
import time
import tracemalloc
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from results import load_trials  # noqa: E402

from sidql.codec import format as sidq  # noqa: E402
from sidql.codec.decode import reconstruct_stream  # noqa: E402
from sidql.codec.encode import encode_series  # noqa: E402
from sidql.codec.quantise import fit_quantiser  # noqa: E402
from sidql.evaluation.rate import bytes_per_second, write_rd_figure  # noqa: E402
from sidql.keyframes.metrics import mpjpe_mm, q_from_angles, velocity_error_mm_s  # noqa: E402
from sidql.keyframes.optimal import solve  # noqa: E402
from sidql.keyframes.reconstructions import reconstruct_series  # noqa: E402
from sidql.keyframes.segment_costs import segment_cost_matrix  # noqa: E402
from sidql.keyframes.spherical import chart, protocol_indices, split_channels  # noqa: E402
from sidql.keyframes.unchart import positions_from_chart  # noqa: E402
from sim.errors import UnmetTargetError  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402

COUNTS = (2, 3, 4, 5, 6, 8, 10, 12, 15, 20)
LATENCIES = (2, 4, 8, 15, 30, 60, 10000)
BITS = (6, 7, 8, 9, 10, 12, 16)


class Trial:
    def __init__(self, clip):
        n = 60 * (clip.n_frames // 60)
        self.clip = clip.slice(0, n)
        self.series = chart(self.clip)
        idx = protocol_indices(self.clip)
        self.pos = self.clip.positions[:, idx]
        self.vel = self.clip.velocities[:, idx]
        self.n = n


class Acc:
    """Frame-weighted sums of Q, MPJPE and velocity error, and bytes over seconds."""

    def __init__(self):
        self.q = self.mm = self.v = self.frames = self.bytes = self.seconds = 0.0

    def add(self, trial_or_n, q, mm, v, nbytes, seconds):
        n = trial_or_n
        self.q += q * n
        self.mm += mm * n
        self.v += v * n
        self.frames += n
        self.bytes += nbytes
        self.seconds += seconds

    def add_stream(self, t, enc):
        """Add trial ``t``'s encoding ``enc``: its Q, the decoded stream's errors, its size."""
        rec = reconstruct_stream(sidq.from_bytes(enc.data))
        self.add(
            t.n,
            enc.q,
            mpjpe_mm(t.pos, rec.positions),
            velocity_error_mm_s(t.vel, rec.velocities),
            len(enc.data),
            t.n / 30.0,
        )

    def row(self):
        f = max(self.frames, 1)
        return {
            "bytes_per_second": self.bytes / self.seconds,
            "mean_q": self.q / f,
            "mpjpe_mm": self.mm / f,
            "velocity_error_mm_s": self.v / f,
        }


def paper(trials, counts):
    out = {"uniform": [], "optimal": []}
    for W in counts:
        acc = {"uniform": Acc(), "optimal": Acc()}
        for t in trials:
            for c0 in range(0, t.n, 60):
                clip = t.clip.slice(c0, c0 + 60)
                s = chart(clip)
                table = solve(segment_cost_matrix(s, "hermite"), s.n_bones, W)
                for method in acc:
                    if method == "uniform":
                        k = np.floor(np.linspace(0.0, 59.0, W) + 0.5).astype(np.int64)
                    else:
                        k = table.keyframes(W)
                    rec = reconstruct_series(s, k, "hermite")
                    acc[method].add(
                        60,
                        q_from_angles(s, rec.theta, rec.phi),
                        mpjpe_mm(t.pos[c0 : c0 + 60], rec.positions),
                        velocity_error_mm_s(t.vel[c0 : c0 + 60], rec.velocities),
                        bytes_per_second("hermite", W) * 2.0,
                        2.0,
                    )
        for method in acc:
            out[method].append({"keyframes": W, **acc[method].row()})
    return out


def codec(trials, rates, reconstruction, latency=0):
    rows = []
    for rate in rates:
        acc = Acc()
        failed = 0
        for t in trials:
            try:
                enc = encode_series(
                    t.series, rate=rate, reconstruction=reconstruction, latency=latency
                )
            except UnmetTargetError:  # a rate below the trial's sparsest plan
                failed += 1
                continue
            acc.add_stream(t, enc)
        row = acc.row() if acc.frames else {}
        rows.append({"rate": rate, "trials_failed": failed, **row})
    return rows


def _lzma_size(raw: bytes, frame_bytes: int) -> int:
    plain = len(lzma.compress(raw, preset=9 | lzma.PRESET_EXTREME))
    filters = [
        {"id": lzma.FILTER_DELTA, "dist": frame_bytes},
        {"id": lzma.FILTER_LZMA2, "preset": 9 | lzma.PRESET_EXTREME},
    ]
    delta = len(lzma.compress(raw, format=lzma.FORMAT_XZ, filters=filters))
    return min(plain, delta)


def raw_lzma(trials, bits_list):
    rows = []
    for bits in bits_list:
        acc = Acc()
        for t in trials:
            s = t.series
            M = s.n_bones
            v, _ = s.channels()
            q = fit_quantiser(v, None, M)
            codes = q.encode_pose(v).astype(np.int64)
            shift = 16 - bits  # coarser grid: drop the low bits
            coarse = codes >> shift
            back = q.decode_pose(((coarse << shift) + (1 << shift >> 1)).astype(np.uint16))
            dtype = np.uint8 if bits <= 8 else np.uint16
            raw = coarse.astype(dtype).tobytes()
            size = _lzma_size(raw, v.shape[1] * np.dtype(dtype).itemsize) + 200  # + a header
            theta, phi, root = split_channels(back, M)
            z = np.zeros_like(theta)
            P, _ = positions_from_chart(
                root, np.zeros_like(root), theta, phi, z, z, s.lengths, s.parents
            )
            V = np.gradient(P, s.dt, axis=0)
            acc.add(
                t.n,
                q_from_angles(s, theta, phi),
                mpjpe_mm(t.pos, P),
                velocity_error_mm_s(t.vel, V),
                size,
                t.n / 30.0,
            )
        rows.append({"bits": bits, **acc.row()})
    return rows


def five_minutes(trials):
    """A 9000-frame chart: the longest trial forwards, backwards, forwards... (no jumps)."""
    s = max(trials, key=lambda t: t.n).series
    idx = []
    fwd = True
    while len(idx) < 9000:
        r = np.arange(s.n_frames) if fwd else np.arange(s.n_frames - 1, -1, -1)
        idx.extend(r[1:] if idx else r)
        fwd = not fwd
    idx = np.array(idx[:9000])
    return s.frames(idx)


def speed(series, rate, repeats=3):
    out = {}
    seconds = series.n_frames * series.dt
    for recon in ("catmull_rom", "hermite", "linear", "auto"):
        best = np.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            enc = encode_series(series, rate=rate, reconstruction=recon)
            best = min(best, time.perf_counter() - t0)
        out[f"encode {recon}"] = (best, seconds / best)
    data = enc.data
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        reconstruct_stream(sidq.from_bytes(data))
        best = min(best, time.perf_counter() - t0)
    out["decode (bytes -> points)"] = (best, seconds / best)
    # memory: Python-visible peak (numpy arrays) and the band table's size, N and N / 2
    mem = {}
    for n in (series.n_frames // 2, series.n_frames):
        sub = series.frames(slice(0, n))
        tracemalloc.start()
        encode_series(sub, rate=rate, reconstruction="catmull_rom")
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        mem[n] = peak
    return out, mem


def write_plot(res, path):
    series = [
        ("paper: Hermite + rates, optimal W/clip, float32", res["paper"]["optimal"], "C0", "-o"),
        ("paper: Hermite + rates, uniform W/clip, float32", res["paper"]["uniform"], "C2", "-o"),
        ("codec: auto (whole-trial DP, packed 9-16 bits)", res["codec"]["auto"], "C3", "-s"),
        ("codec: Hermite + rates (packed)", res["codec"]["hermite"], "C1", "--s"),
        ("raw 30 fps, b bits + lzma", res["raw_lzma"], "k", ":^"),
    ]

    def draw(ax, key):
        for name, rows, color, style in series:
            rows = [r for r in rows if "bytes_per_second" in r]
            ax.plot(
                [r["bytes_per_second"] for r in rows],
                [r[key] for r in rows],
                style,
                color=color,
                ms=4,
                label=name,
            )

    write_rd_figure(
        path,
        f"Motion codec vs anchors on {res['trials']} whole CMU trials "
        f"({res['seconds']:.0f} s of motion at 30 fps)",
        draw,
    )


class _Tee(io.TextIOBase):
    """Print and keep everything printed (the results file is the printed report)."""

    def __init__(self, out):
        self.out, self.parts = out, []

    def write(self, text):
        self.parts.append(text)
        return self.out.write(text)

    def flush(self):
        self.out.flush()


def main(argv=None) -> int:
    tee = _Tee(sys.stdout)
    with contextlib.redirect_stdout(tee):
        code = _main(argv)
    args = [a for a in (argv if argv is not None else sys.argv[1:])]
    if "--no-write" not in args:
        from results import write_results

        text = "```text\n" + "".join(tee.parts).strip() + "\n```\n"
        text += "\n![codec rate/distortion](../codec_rate_distortion.png)\n"
        print("wrote", write_results("codec_anchors", "Codec against the paper's scheme", text,
                                     command="python benchmarks/bench_codec.py"))  # fmt: skip
    return code


def _main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--no-write", action="store_true", help="print only")
    ap.add_argument("--plot", type=Path, default=REPO / "docs" / "codec_rate_distortion.png")
    ap.add_argument("--json", type=Path, default=None, help="also write all numbers here")
    ap.add_argument("--latency-rate", type=float, default=942.5, help="B/s of the latency table")
    args = ap.parse_args(argv)

    clips, skipped = load_trials(args.data)
    trials = [Trial(clip) for clip in clips]
    seconds = sum(t.n for t in trials) / 30.0
    print(f"{len(trials)} trials from {args.data}, {seconds:.1f} s at 30 fps; skipped: {skipped}")
    rates = [bytes_per_second("hermite", W) for W in COUNTS]
    res = {"trials": len(trials), "seconds": seconds, "skipped": skipped}
    res["paper"] = paper(trials, COUNTS)
    res["codec"] = {
        r: codec(trials, rates, r) for r in ("auto", "hermite", "catmull_rom", "linear")
    }
    res["raw_lzma"] = raw_lzma(trials, BITS)

    print("\n(a) paper vs (b) codec at equal bytes/s (codec: whole .sidq files)")
    print(
        f"{'W/clip':>6} {'B/s':>7} | {'paper opt Q':>11} {'mm':>6} {'mm/s':>6} | {'paper uni Q':>11} | "
        f"{'codec B/s':>9} {'Q':>8} {'mm':>6} {'mm/s':>6} | {'Q ratio':>7} | codec-hermite Q"
    )
    for i, W in enumerate(COUNTS):
        po, pu = res["paper"]["optimal"][i], res["paper"]["uniform"][i]
        c, h = res["codec"]["auto"][i], res["codec"]["hermite"][i]
        cq = c.get("mean_q", np.nan)
        print(
            f"{W:>6} {rates[i]:>7.1f} | {po['mean_q']:>11.4f} {po['mpjpe_mm']:>6.1f} "
            f"{po['velocity_error_mm_s']:>6.0f} | {pu['mean_q']:>11.4f} | "
            f"{c.get('bytes_per_second', np.nan):>9.1f} {cq:>8.4f} {c.get('mpjpe_mm', np.nan):>6.1f} "
            f"{c.get('velocity_error_mm_s', np.nan):>6.0f} | {cq / po['mean_q']:>7.3f} | "
            f"{h.get('mean_q', np.nan):.4f} ({h['trials_failed']} trials failed)"
        )
    print("\n(c) raw 30-fps pose stream, b bits per channel + lzma")
    print(f"{'bits':>4} {'B/s':>8} {'Q':>9} {'mm':>7} {'mm/s':>7}")
    for r in res["raw_lzma"]:
        print(
            f"{r['bits']:>4} {r['bytes_per_second']:>8.1f} {r['mean_q']:>9.5f} "
            f"{r['mpjpe_mm']:>7.2f} {r['velocity_error_mm_s']:>7.0f}"
        )
    # the codec at the raw stream's errors: --max-q equal to raw's Q
    eq = []
    for r in res["raw_lzma"]:
        acc = Acc()
        for t in trials:
            enc = encode_series(t.series, max_q=r["mean_q"], reconstruction="auto")
            acc.add_stream(t, enc)
        eq.append({"bits": r["bits"], "raw": r, "codec": acc.row()})
    res["equal_error"] = eq
    print("\n(c') at equal Q: codec --max-q = raw stream's Q")
    print(
        f"{'bits':>4} {'Q target':>9} | {'raw B/s':>8} | {'codec B/s':>9} {'Q':>9} {'mm':>7} | ratio"
    )
    for e in eq:
        print(
            f"{e['bits']:>4} {e['raw']['mean_q']:>9.5f} | {e['raw']['bytes_per_second']:>8.1f} | "
            f"{e['codec']['bytes_per_second']:>9.1f} {e['codec']['mean_q']:>9.5f} "
            f"{e['codec']['mpjpe_mm']:>7.2f} | {e['raw']['bytes_per_second'] / e['codec']['bytes_per_second']:.2f}x"
        )

    print(f"\nlatency: Q against look-ahead L at {args.latency_rate:g} B/s (all trials)")
    lat = {}
    for recon in ("catmull_rom", "linear", "hermite"):
        rows = [codec(trials, [args.latency_rate], recon, L)[0] for L in LATENCIES]
        rows.append(codec(trials, [args.latency_rate], recon, 0)[0])
        lat[recon] = rows
    res["latency"] = lat
    head = " ".join(f"{'L=' + str(L) if L < 10000 else 'L=inf':>9}" for L in LATENCIES)
    print(f"{'':>12} {head} {'offline':>9}")
    for recon, rows in lat.items():
        cells = " ".join(
            f"{r['mean_q']:>9.4f}" if "mean_q" in r and not r["trials_failed"] else f"{'-':>9}"
            for r in rows
        )
        print(f"{recon:>12} {cells}")
    print(
        "(-: the rate is below what the latency's largest gap needs on some trial; L=inf: the "
        "live coding (fixed 16-bit records) without a latency bound; offline: packed coding)"
    )

    five = five_minutes(trials)
    sp, mem = speed(five, args.latency_rate)
    res["speed"] = {k: {"seconds": v[0], "x_real_time": v[1]} for k, v in sp.items()}
    res["memory"] = mem
    print(f"\nspeed on one core, {five.n_frames} frames = {five.n_frames / 30:.0f} s of motion:")
    for k, (sec, x) in sp.items():
        print(f"  {k:<26} {sec:7.3f} s   {x:8.0f}x real time")
    (n1, m1), (n2, m2) = sorted(mem.items())
    print(
        f"  encoder peak Python memory: {m1 / 1e6:.1f} MB at N = {n1}, {m2 / 1e6:.1f} MB at N = {n2} "
        f"(ratio {m2 / m1:.2f}; band table N (G+1) float64 = {n2 * 61 * 8 / 1e6:.1f} MB at N = {n2})"
    )
    if args.plot:
        args.plot.parent.mkdir(parents=True, exist_ok=True)
        write_plot(res, args.plot)
        print(f"wrote {args.plot}")
    if args.json:
        args.json.write_text(json.dumps(res, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
