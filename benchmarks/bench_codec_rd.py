"""The codec against what a user would do instead: rate against joint position error.

    python benchmarks/bench_codec_rd.py [--data ../shared/cmu] [--plot docs/codec_rd.png]
    # a fast screen of the position coding alone (no page written)
    python benchmarks/bench_codec_rd.py --codec-only [--targets 1,3,10] [--no-cones]

Every trial of ``--data`` (at least 60 frames) is read at 30 fps on its own skeleton; its 23
protocol points come from MuJoCo's forward kinematics of the ASF/AMC (``load_motion``), which the
codec never uses, and every scheme is judged on them: bytes per second over all trials (every
byte a decoder needs), mean and 95th-percentile Euclidean error of all points in all frames [mm]
and Q (eq. 18 [rad], from the chart of the decoded points). Schemes:

* **positions + delta + LZMA / zstd**: the 23 points quantised with a uniform step s [m],
  differenced along time, int16 channel by channel, compressed by stdlib ``lzma`` (preset 9e) or
  ``zstandard`` (level 22); 8 header bytes (step, frame count) counted. About 20 lines of numpy.
* the same after **2x / 4x temporal decimation** (every 2nd / 4th frame and the last), linear
  interpolation back to 30 fps.
* **per-channel DCT**: each coordinate in blocks of 64 frames, orthonormal DCT-II, uniform step,
  int16 coefficient by coefficient, LZMA.
* **codec (position)**: ``sidql encode --max-error E`` (coding 2), E from 0.5 to 15 mm.
* **codec (angle)**: the angle-error coding (coding 1, ``objective="angle"``) at a few rates.

The comparison tables read every curve at mean errors 1..10 mm and at 95th percentiles 2..20 mm
(log-log interpolation between measured points). The targets: the codec needs at most 1/3 of the
best baseline's bytes at each of these mean errors, and at most 1/2 at each of these 95th
percentiles. It also compares entropy coders on the angle
coding's packed keyframes (the same bytes, so the same Q): LZMA as the format uses it, zstd, brotli.
"""

from __future__ import annotations

import argparse
import json
import lzma
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

import codec_physics  # noqa: E402
import scipy.fft  # noqa: E402
from results import load_trials, write_results  # noqa: E402

from sidql.codec import format as sidq  # noqa: E402
from sidql.codec import position_coding  # noqa: E402
from sidql.codec.decode import reconstruct_stream  # noqa: E402
from sidql.codec.encode import encode_series  # noqa: E402
from sidql.keyframes.metrics import q_from_angles  # noqa: E402
from sidql.keyframes.spherical import chart, chart_arrays, protocol_indices  # noqa: E402
from sim.errors import UnmetTargetError  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402

ERRORS_MM = tuple(range(1, 11))
#: 95th percentiles the second table reads every curve at: about those the baselines have at
#: mean errors of 1 to 10 mm
P95_MM = (2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0)
CODEC_TARGETS_MM = (0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 7.0, 10.0, 12.0, 15.0)
ANGLE_RATES = (150.0, 250.0, 400.0, 600.0, 900.0, 1300.0)
STEPS_MM = (0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0, 48.0, 64.0, 96.0)
HEADER = 8  # a baseline stream's own header: step (float32) and frame count (uint32)


class Trial:
    def __init__(self, clip):
        self.series = chart(clip)
        self.points = clip.positions[:, protocol_indices(clip)]  # MuJoCo FK, world z up [m]
        self.n = clip.n_frames
        self.dt = clip.dt


def _lzma(raw: bytes) -> int:
    return len(lzma.compress(raw, preset=9 | lzma.PRESET_EXTREME))


def _zstd(raw: bytes) -> int:
    import zstandard

    return len(zstandard.ZstdCompressor(level=22).compress(raw))


def _brotli(raw: bytes) -> int:
    import brotli

    return len(brotli.compress(raw, quality=11))


COMPRESSORS = {"lzma": _lzma, "zstd": _zstd}


def _int_bytes(a: np.ndarray) -> bytes:
    a = np.ascontiguousarray(a)
    dtype = "<i2" if np.abs(a).max(initial=0) < 32768 else "<i4"
    return a.astype(dtype).tobytes()


def positions_delta(P: np.ndarray, step: float, decimate: int, compress) -> tuple[int, np.ndarray]:
    """Quantised points, differenced along time, compressed; decoded by linear interpolation."""
    N = len(P)
    keep = np.unique(np.r_[np.arange(0, N, decimate), N - 1])
    codes = np.rint(P[keep].reshape(len(keep), -1) / step).astype(np.int64)
    delta = np.diff(codes, axis=0, prepend=0)
    size = compress(_int_bytes(delta.T)) + HEADER
    dec = codes * step
    out = np.empty((N, dec.shape[1]))
    for c in range(dec.shape[1]):
        out[:, c] = np.interp(np.arange(N), keep, dec[:, c])
    return size, out.reshape(P.shape)


def positions_dct(P: np.ndarray, step: float, block: int = 64) -> tuple[int, np.ndarray]:
    """Per-coordinate block DCT-II (orthonormal), uniform step, LZMA."""
    N = len(P)
    X = P.reshape(N, -1)
    pad = (-N) % block
    Xp = np.concatenate([X, np.repeat(X[-1:], pad, axis=0)])
    coef = scipy.fft.dct(Xp.reshape(-1, block, X.shape[1]), axis=1, norm="ortho")
    q = np.rint(coef / step).astype(np.int64)
    size = _lzma(_int_bytes(q.transpose(2, 1, 0))) + HEADER
    dec = scipy.fft.idct(q * step, axis=1, norm="ortho").reshape(-1, X.shape[1])[:N]
    return size, dec.reshape(P.shape)


class Pool:
    """Bytes, seconds, per-point errors and frame-weighted Q over trials."""

    def __init__(self):
        self.bytes = self.seconds = self.q = self.frames = 0.0
        self.errors: list[np.ndarray] = []

    def add(self, t: Trial, nbytes: int, decoded: np.ndarray, q: float | None = None):
        self.bytes += nbytes
        self.seconds += t.n * t.dt
        self.errors.append(1000.0 * np.linalg.norm(decoded - t.points, axis=-1).ravel())
        if q is None:  # Q of the decoded points' chart
            s = chart_arrays(decoded, np.zeros_like(decoded), t.series.parents, t.dt)
            q = q_from_angles(t.series, s.theta, s.phi)
        self.q += q * t.n
        self.frames += t.n

    def point(self, **extra) -> dict:
        e = np.concatenate(self.errors)
        return {
            "bytes_per_second": self.bytes / self.seconds,
            "mean_mm": float(e.mean()),
            "p95_mm": float(np.percentile(e, 95)),
            "q": self.q / self.frames,
            **extra,
        }


def baselines(trials) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for name in COMPRESSORS:
        for dec in (1, 2, 4):
            key = f"positions + delta + {name}" + (f", {dec}x decimated" if dec > 1 else "")
            rows = []
            for s_mm in STEPS_MM:
                pool = Pool()
                for t in trials:
                    size, P = positions_delta(t.points, s_mm / 1000.0, dec, COMPRESSORS[name])
                    pool.add(t, size, P)
                rows.append(pool.point(step_mm=s_mm))
            out[key] = rows
    rows = []
    for s_mm in STEPS_MM:
        pool = Pool()
        for t in trials:
            size, P = positions_dct(t.points, 2.0 * s_mm / 1000.0)
            pool.add(t, size, P)
        rows.append(pool.point(step_mm=2.0 * s_mm))
    out["per-channel DCT (64) + lzma"] = rows
    return out


def codec_position(trials, targets=CODEC_TARGETS_MM) -> list[dict]:
    rows = []
    for e in targets:
        pool = Pool()
        t0 = time.perf_counter()
        for t in trials:
            enc = encode_series(t.series, max_error=e)
            rec = reconstruct_stream(sidq.from_bytes(enc.data))
            pool.add(t, len(enc.data), rec.positions, enc.q)
        rows.append(pool.point(max_error_mm=e, seconds=time.perf_counter() - t0))
    return rows


def codec_angle(trials) -> tuple[list[dict], list[dict]]:
    rows, coders = [], []
    for rate in ANGLE_RATES:
        pool = Pool()
        sizes = {"lzma (format)": 0, "zstd 22": 0, "brotli 11": 0}
        for t in trials:
            try:
                enc = encode_series(t.series, rate=rate, objective="angle")
            except UnmetTargetError:  # a rate below the trial's sparsest plan
                continue
            rec = reconstruct_stream(sidq.from_bytes(enc.data))
            pool.add(t, len(enc.data), rec.positions, enc.q)
            if enc.stream.coding == 1:
                raw = sidq._planar(enc.stream)
                rest = len(enc.data) - len(sidq.packed_bytes(enc.stream))
                sizes["lzma (format)"] += len(enc.data)
                sizes["zstd 22"] += rest + 4 + _zstd(raw)
                sizes["brotli 11"] += rest + 4 + _brotli(raw)
        rows.append(pool.point(rate=rate))
        coders.append({"rate": rate, **sizes})
    return rows, coders


def at_error(
    rows: list[dict], e: float, key: str = "bytes_per_second", by: str = "mean_mm"
) -> float:
    """``key`` of a curve where its ``by`` error (mean or p95) is ``e`` [mm], log-log
    interpolated; nan outside its range."""
    pts = sorted((r[by], r[key]) for r in rows)
    x = np.log([p[0] for p in pts])
    y = np.log([p[1] for p in pts])
    if not (x[0] <= np.log(e) <= x[-1]):
        return float("nan")
    return float(np.exp(np.interp(np.log(e), x, y)))


def at_rate(rows: list[dict], rate: float, key: str) -> float:
    pts = sorted((r["bytes_per_second"], r[key]) for r in rows)
    x = np.log([p[0] for p in pts])
    y = np.log([p[1] for p in pts])
    if not (x[0] <= np.log(rate) <= x[-1]):
        return float("nan")
    return float(np.exp(np.interp(np.log(rate), x, y)))


def compare(base: dict, codec: list[dict]) -> list[dict]:
    """Every curve read at equal mean error (:data:`ERRORS_MM`): the best baseline's bytes and
    the codec's, and their 95th percentiles."""
    out = []
    for e in ERRORS_MM:
        rates = {k: at_error(v, e) for k, v in base.items()}
        ok = {k: r for k, r in rates.items() if np.isfinite(r)}
        best = min(ok, key=ok.get) if ok else None
        c = at_error(codec, e)
        p95_equal_rate = min(
            (x for x in (at_rate(v, c, "p95_mm") for v in base.values()) if np.isfinite(x)),
            default=float("nan"),
        )
        out.append(
            {
                "mean_mm": e,
                "best_baseline": best,
                "baseline_bps": ok.get(best, float("nan")),
                "baseline_p95_mm": at_error(base[best], e, "p95_mm") if best else float("nan"),
                "codec_bps": c,
                "codec_p95_mm": at_error(codec, e, "p95_mm"),
                "ratio": c / ok[best] if best else float("nan"),
                "baseline_p95_at_codec_rate": p95_equal_rate,
            }
        )
    return out


def compare_p95(base: dict, codec: list[dict]) -> list[dict]:
    """Every curve read at equal 95th percentile (:data:`P95_MM`): the best baseline's bytes
    and the codec's, and their mean errors."""
    out = []
    for e in P95_MM:
        rates = {k: at_error(v, e, by="p95_mm") for k, v in base.items()}
        ok = {k: r for k, r in rates.items() if np.isfinite(r)}
        best = min(ok, key=ok.get) if ok else None
        c = at_error(codec, e, by="p95_mm")
        out.append(
            {
                "p95_mm": e,
                "best_baseline": best,
                "baseline_bps": ok.get(best, float("nan")),
                "baseline_mean_mm": at_error(base[best], e, "mean_mm", "p95_mm")
                if best
                else float("nan"),
                "codec_bps": c,
                "codec_mean_mm": at_error(codec, e, "mean_mm", "p95_mm"),
                "ratio": c / ok[best] if best else float("nan"),
            }
        )
    return out


def write_plot(base, codec, angle, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2))
    styles = {
        "positions + delta + lzma": ("k", "-o"),
        "positions + delta + zstd": ("0.5", "--o"),
        "per-channel DCT (64) + lzma": ("C2", "-^"),
    }
    for name, rows in base.items():
        color, style = styles.get(
            name, ("C0" if "2x" in name else "C4", ":s" if "lzma" in name else ":x")
        )
        for ax, key in zip(axes, ("mean_mm", "p95_mm", "q"), strict=True):
            ax.plot([r["bytes_per_second"] for r in rows], [r[key] for r in rows], style,
                    color=color, ms=3, lw=1, label=name)  # fmt: skip
    for rows, name, color in ((codec, "codec, position coding (--max-error)", "C3"),
                              (angle, "codec, angle coding (Q objective)", "C1")):  # fmt: skip
        for ax, key in zip(axes, ("mean_mm", "p95_mm", "q"), strict=True):
            ax.plot([r["bytes_per_second"] for r in rows], [r[key] for r in rows], "-D",
                    color=color, ms=4, lw=2, label=name)  # fmt: skip
    for ax, label in zip(
        axes, ("mean joint position error [mm]", "95th percentile [mm]", "Q [rad]"), strict=True
    ):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("bytes per second (whole stream)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xlim(60, 3000)
    axes[0].axhspan(1, 10, color="C3", alpha=0.05)
    axes[0].legend(fontsize=7, loc="lower left")
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _mean_table(table: list[dict]) -> list[str]:
    lines = [
        "**At equal mean joint position error** (every curve read at the same mean error; the "
        "best baseline is the one needing the fewest bytes there):",
        "",
        "| mean error | best baseline | its B/s | its p95 | codec B/s | codec p95 | codec / best "
        "| baselines' best p95 at the codec's rate |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in table:
        at_rate_p95 = r["baseline_p95_at_codec_rate"]
        cell = f"{at_rate_p95:.1f} mm" if np.isfinite(at_rate_p95) else "below their rates"
        lines.append(
            f"| {r['mean_mm']:g} mm | {r['best_baseline']} | {r['baseline_bps']:.0f} | "
            f"{r['baseline_p95_mm']:.1f} mm | {r['codec_bps']:.0f} | {r['codec_p95_mm']:.1f} mm | "
            f"**{r['ratio']:.2f}** | {cell} |"
        )
    ratios = [r["ratio"] for r in table]
    # a codec rate below every baseline's lowest measured rate has nothing to compare with
    read = [r for r in table if np.isfinite(r["baseline_p95_at_codec_rate"])]
    p95_ok = all(r["codec_p95_mm"] <= r["baseline_p95_at_codec_rate"] for r in read)
    unread = len(table) - len(read)
    where = "every error"
    if unread:
        where += (
            f" but {unread} of {len(table)}, where the codec's rate is below every baseline's "
            "lowest measured rate"
        )
    met = "met" if max(ratios) <= 0.33 else "not met"
    return lines + [
        "",
        f"Codec bytes over the best baseline's at equal mean error: {min(ratios):.2f} to "
        f"{max(ratios):.2f} (aim: at most 0.33; {met}); codec p95 below the baselines' best p95 "
        f"at the same rate: {'yes' if p95_ok else 'no'} at {where}.",
    ]


def _p95_table(table: list[dict]) -> list[str]:
    lines = [
        "**At equal 95th percentile** of the joint position error (every curve read at the same "
        "p95; the best baseline is the one needing the fewest bytes there):",
        "",
        "| p95 | best baseline | its B/s | its mean | codec B/s | codec mean | codec / best |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in table:
        lines.append(
            f"| {r['p95_mm']:g} mm | {r['best_baseline']} | {r['baseline_bps']:.0f} | "
            f"{r['baseline_mean_mm']:.2f} mm | {r['codec_bps']:.0f} | {r['codec_mean_mm']:.2f} mm "
            f"| **{r['ratio']:.2f}** |"
        )
    ratios = [r["ratio"] for r in table]
    met = "met" if max(ratios) <= 0.5 else "not met"
    return lines + [
        "",
        f"Codec bytes over the best baseline's at equal p95: {min(ratios):.2f} to "
        f"{max(ratios):.2f} (aim: at most 0.5; {met}).",
    ]


def _points_and_coders(base, codec, angle, coders, seconds) -> list[str]:
    lines = ["**Every measured point** (B/s, mean / p95 [mm], Q [rad]):", ""]
    for name, rows in [
        *base.items(),
        ("codec, position coding", codec),
        ("codec, angle coding", angle),
    ]:
        cells = "; ".join(
            f"{r['bytes_per_second']:.0f}: {r['mean_mm']:.2f} / {r['p95_mm']:.1f}, {r['q']:.4f}"
            for r in rows
        )
        lines.append(f"- {name}: {cells}")
    lines += [
        "",
        "**Entropy coders on the angle coding's packed keyframes** (coding 1; the same keyframes "
        "and codes, so the same Q; whole files, B/s):",
        "",
        "| rate asked | LZMA (format) | zstd 22 | brotli 11 |",
        "|---|---|---|---|",
    ]
    for c in coders:
        lines.append(
            f"| {c['rate']:.0f} | {c['lzma (format)'] / seconds:.1f} | {c['zstd 22'] / seconds:.1f} | "
            f"{c['brotli 11'] / seconds:.1f} |"
        )
    return lines


def screen(trials, args) -> int:
    """The position coding alone: its points, then its B/s read at equal mean error and p95."""
    targets = CODEC_TARGETS_MM
    if args.targets:
        targets = tuple(float(x) for x in args.targets.split(","))
    codec = codec_position(trials, targets)
    for r in codec:
        print(f"--max-error {r['max_error_mm']:g}: {r['bytes_per_second']:.1f} B/s, mean "
              f"{r['mean_mm']:.3f} mm, p95 {r['p95_mm']:.2f} mm, {r['seconds']:.1f} s")  # fmt: skip
    means = {e: at_error(codec, e) for e in ERRORS_MM}
    p95s = {e: at_error(codec, e, by="p95_mm") for e in P95_MM}
    print("B/s at mean error: " + ", ".join(f"{e} mm {b:.1f}" for e, b in means.items()
                                              if np.isfinite(b)))  # fmt: skip
    print("B/s at p95: " + ", ".join(f"{e:g} mm {b:.1f}" for e, b in p95s.items()
                                       if np.isfinite(b)))  # fmt: skip
    if args.json:
        args.json.write_text(json.dumps({"codec": codec, "at_mean": means, "at_p95": p95s}))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--plot", type=Path, default=REPO / "docs" / "codec_rd.png")
    ap.add_argument("--json", type=Path, default=None, help="also write every number here")
    ap.add_argument("--no-write", action="store_true", help="print only (no docs/results file)")
    ap.add_argument("--physics", action="store_true", help="also foot contacts at equal rate "
                    "(benchmarks/codec_physics.py, which alone writes its own page)")  # fmt: skip
    ap.add_argument("--codec-only", action="store_true", help="only the position coding's "
                    "points and its bytes read at equal mean error and p95 (a fast screen: "
                    "writes no page)")  # fmt: skip
    ap.add_argument("--targets", type=str, default=None, help="with --codec-only: its "
                    "--max-error targets [mm], comma-separated (default: the page's)")  # fmt: skip
    ap.add_argument("--no-cones", action="store_true", help="the position coding without "
                    "cones (sidql.codec.position_coding.CONES off: version 5's prediction)")  # fmt: skip
    args = ap.parse_args(argv)
    if args.no_cones:
        position_coding.CONES = False

    clips, skipped = load_trials(args.data)
    trials = [Trial(clip) for clip in clips]
    seconds = sum(t.n * t.dt for t in trials)
    print(f"{len(trials)} trials, {seconds:.1f} s at 30 fps; skipped: {skipped}")
    if args.codec_only:
        return screen(trials, args)
    base = baselines(trials)
    codec = codec_position(trials)
    angle, coders = codec_angle(trials)
    table, table95 = compare(base, codec), compare_p95(base, codec)

    lines = [
        f"{len(trials)} CMU trials of `{args.data.name}` ({seconds:.0f} s at 30 fps; left out: "
        f"{', '.join(skipped) or 'none'}). Reference points: MuJoCo's forward kinematics of the "
        "ASF/AMC (`load_motion`), independent of the codec; errors over all 23 points and frames.",
        "",
        *_mean_table(table),
        "",
        *_p95_table(table95),
        "",
        *_points_and_coders(base, codec, angle, coders, seconds),
    ]
    text = "\n".join(lines)
    if args.physics:
        text += "\n\n" + codec_physics.section(clips)
    print(text)
    if args.plot:
        write_plot(base, codec, angle, args.plot,
                   f"Rate against joint position error, {len(trials)} CMU trials ({seconds:.0f} s)")  # fmt: skip
        print(f"wrote {args.plot}")
    if not args.no_write:
        path = write_results(
            "codec_rd",
            "Codec against practical baselines: rate and joint position error",
            text + f"\n\n![rate-distortion](../{args.plot.name})\n",
            command="python benchmarks/bench_codec_rd.py" + " --physics" * args.physics,
        )
        print(f"wrote {path}")
    if args.json:
        args.json.write_text(json.dumps({"baselines": base, "codec": codec, "angle": angle,
                                         "compare": table, "compare_p95": table95,
                                         "coders": coders}, indent=1))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
