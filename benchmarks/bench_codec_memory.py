"""Codec memory and speed at any length: ``sidql encode --rate 942`` of long takes in a child process.

    python benchmarks/bench_codec_memory.py [--data ../shared/cmu] [--minutes 2.5 5 10 30 60]
        [--baseline-minutes 2.5 5 10] [--bvh-minutes 5 10] [--contacts-minutes 5 10 30]
        [--repeats 2]

Takes are written to a temporary folder (never the repository) from real trials of ``--data``
played forwards and backwards (no jumps): ``01_02`` (a walk and climb) at every length of
``--minutes``, and 5 minutes of ``17_10`` (boxing) and ``05_06`` (dance: cartwheel, pirouettes,
jete) for the vigorous kinds of motion. Each is encoded by the command line as a user runs it
(``sidql encode ASF AMC --out F --rate 942``) in a child process whose peak resident memory
(``ru_maxrss``), wall time and CPU time (user + system) are read from ``wait4``. The baseline is
the whole-take path the codec had before it encoded in windows (``load_motion`` of the whole take,
its chart, ``encode_series``, the file written), run the same way in a child, for the lengths in
``--baseline-minutes`` (its reader refuses AMC files over 64 MB, about 13 minutes). The longest
take is decoded back to ``.npz``, the longest of at most 10 minutes to ``.amc`` (``sidql
decode``), in a child too.

The walk take of every length of ``--bvh-minutes`` is also written as BVH (``sidql convert``) and
encoded from it (``sidql encode F.bvh --rate 942``) against the same baseline; a BVH over the
reader's bound (:data:`sim.bvh.records.MAX_BVH_BYTES`, 64 MiB: about 9 minutes of CMU's
skeleton) is refused, in one line, and said so.

The walk take of every length of ``--contacts-minutes`` is also encoded with its foot contacts
(``sidql encode ... --contacts``), against the whole-take path that command had before (the take
read whole, one stream) at the lengths of ``--baseline-minutes``.

The cost of windowing in bytes is measured on the trials of ``--data`` (all shorter than one
window): each is encoded whole and in 300-frame windows (several cuts per trial) at a mean
position error of 2 mm (bytes) and at 942 B/s (mean error).

Targets: peak <= 300 MB whatever the length; >= 100x real time for every kind of motion. The
machine may be shared: CPU time and the load average are printed beside the wall times.
"""

from __future__ import annotations

import argparse
import io
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from results import write_results  # noqa: E402

SOURCE_FPS = 120.0
RATE = "942"
TAKES = {"walk": ("01", "01_02"), "boxing": ("17", "17_10"), "dance": ("05", "05_06")}
VIGOROUS_MINUTES = 5.0
AMC_DECODE_MINUTES = 10.0  # the longest take also decoded to AMC, and encoded at these targets:
OTHER_TARGETS = ("--max-error 1", "--rate 3000", "--max-q 0.003")
TARGET_MB = 300
PYCACHE = os.path.join(tempfile.gettempdir(), "sidql-bench-pycache")

BASELINE = """
import sys
from pathlib import Path
from sidql.codec.encode import encode_series
from sidql.codec.skeleton import skeleton_hash
from sidql.keyframes.spherical import chart
from sim.files import write_atomic
from sim.motion.ingest import load_motion
from sim.motion.trial import read_skeleton
asf, amc, out, rate = sys.argv[1:5]
clip = load_motion(asf, amc, fps=30.0, derivatives=False)
enc = encode_series(chart(clip), rate=float(rate), skel_hash=skeleton_hash(read_skeleton(asf)))
write_atomic(Path(out), lambda f: f.write(enc.data))
"""
#: the whole-take path of ``sidql encode --contacts`` before it was streamed: the take read whole,
#: its floor and bits on the whole clip, one stream
BASELINE_CONTACTS = """
import sys
from sidql.codec.contact_coding import encode_with_contacts
from sidql.codec.encode import encode_files
asf, amc, out, rate = sys.argv[1:5]
encode_files(asf, amc, out, rate=float(rate), encoder=encode_with_contacts)
"""


def default_data() -> Path:
    for base in (REPO.parent, REPO.parent.parent):
        if (base / "shared" / "cmu").is_dir():
            return base / "shared" / "cmu"
    return REPO.parent / "shared" / "cmu"


def write_take(asf: Path, amc: Path, frames: int, out: Path) -> Path:
    """An AMC of ``frames`` source frames: ``amc`` forwards, backwards, forwards... (no jumps),
    written frame by frame (the take is never held whole)."""
    lines = amc.read_text().splitlines()
    starts = [i for i, line in enumerate(lines) if line.strip().isdigit()]
    bodies = [
        "\n".join(lines[a + 1 : b]) for a, b in zip(starts, starts[1:] + [len(lines)], strict=True)
    ]
    n = len(bodies)
    with open(out, "w") as f:  # a benchmark's temporary folder, not a user's output
        f.write(f"# {amc.name} forwards and backwards\n:FULLY-SPECIFIED\n:DEGREES\n")
        k, forwards, last = 0, True, None
        while k < frames:
            order = range(n) if forwards else range(n - 1, -1, -1)
            block = []
            for i in order:
                if i == last or k >= frames:
                    continue
                k += 1
                block.append(f"{k}\n{bodies[i]}")
                last = i
            f.write("\n".join(block) + "\n")
            forwards = not forwards
    return out


def measured(cmd: list[str]) -> dict:
    """``cmd`` in a child process: wall [s], cpu [s], peak [MB] (from ``wait4``)."""
    # bytecode cached (in the temporary folder, not the repository), as an installed package's
    # is: a shell that says not to write it would otherwise compile every module on every run
    env = dict(os.environ, PYTHONPATH=str(REPO), PYTHONPYCACHEPREFIX=PYCACHE)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    out, err = p.stdout.read().decode(), p.stderr.read().decode()
    p.stdout.close()
    p.stderr.close()
    if os.waitstatus_to_exitcode(status):
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed: {err[-2000:]}")
    return {
        "wall": wall,
        "cpu": usage.ru_utime + usage.ru_stime,
        "peak": usage.ru_maxrss / 1024,
        "out": out,
    }


def best(cmd: list[str], repeats: int) -> dict:
    runs = [measured(cmd) for _ in range(repeats)]
    return {
        "wall": min(r["wall"] for r in runs),
        "cpu": min(r["cpu"] for r in runs),
        "peak": max(r["peak"] for r in runs),
        "out": runs[-1]["out"],
    }


def bvh_row(sidql: list, baseline: list, asf: Path, amc: Path, tmp: Path) -> dict:
    """The take written as BVH and encoded from it (a refusal: its one-line error), and the
    baseline's whole-take path on the same BVH."""
    bvh, out = tmp / "take.bvh", str(tmp / "bvh.sidq")
    measured([*sidql, "convert", str(asf), str(amc), str(bvh)])
    row = {"mb": bvh.stat().st_size / 2**20}
    try:
        row["new"] = measured([*sidql, "encode", str(bvh), "--out", out, "--rate", RATE])
        row["old"] = measured([*baseline, str(bvh), str(bvh), str(tmp / "old.sidq"), RATE])
        row["bytes"] = Path(out).stat().st_size
    except RuntimeError as e:
        row["refused"] = str(e).split(" failed: ", 1)[-1].strip().splitlines()[-1]
    os.unlink(bvh)
    return row


def bvh_page(bvh_rows) -> str:
    """The BVH table (see the module docstring)."""
    if not bvh_rows:
        return ""
    lines = [
        "", "",
        f"BVH takes: the walk take written as BVH (`sidql convert`), `sidql encode F.bvh --rate "
        f"{RATE}` (read a chunk of frames at a time) against the baseline's whole-take path on "
        "the same file:",
        "",
        "| take | minutes | BVH MB | peak MB | wall s | CPU s | file bytes | baseline peak MB "
        "| baseline wall s | baseline CPU s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]  # fmt: skip
    for minutes, r in bvh_rows:
        if "refused" in r:
            lines.append(f"| 01_02 walk | {minutes:g} | {r['mb']:.0f} | refused: "
                         f"`{r['refused'][-160:]}` | - | - | - | - | - | - |")  # fmt: skip
            continue
        new, old = r["new"], r["old"]
        lines.append(
            f"| 01_02 walk | {minutes:g} | {r['mb']:.0f} | {new['peak']:.0f} | {new['wall']:.1f} "
            f"| {new['cpu']:.1f} | {r['bytes']:,} | {old['peak']:.0f} | {old['wall']:.1f} "
            f"| {old['cpu']:.1f} |"
        )
    return "\n".join(lines)


def contacts_row(sidql: list, asf: Path, amc: Path, tmp: Path, baseline: bool) -> dict:
    """``sidql encode --contacts`` of the take, and (``baseline``) the whole-take path."""
    out = str(tmp / "contacts.sidq")
    cmd = [*sidql, "encode", str(asf), str(amc), "--out", out, "--rate", RATE, "--contacts"]
    row = {"new": measured(cmd), "bytes": Path(out).stat().st_size, "old": None}
    if baseline:
        old = [sys.executable, "-c", BASELINE_CONTACTS, str(asf), str(amc), str(tmp / "o.sidq"),
               RATE]  # fmt: skip
        row["old"] = measured(old)
    return row


def contacts_page(rows) -> str:
    """The ``--contacts`` table (see the module docstring)."""
    if not rows:
        return ""
    lines = [
        "", "",
        f"Foot contacts: `sidql encode --rate {RATE} --contacts` (the take read twice: its foot "
        "points for the floor and the bits, then window by window) against the whole-take path "
        "it had before (`encode_with_contacts` of the whole clip, one stream):",
        "",
        "| take | minutes | peak MB | wall s | CPU s | x real time (CPU) | file bytes "
        "| baseline peak MB | baseline wall s | baseline CPU s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]  # fmt: skip
    for minutes, seconds, r in rows:
        new, old = r["new"], r["old"]
        base = (f"| {old['peak']:.0f} | {old['wall']:.1f} | {old['cpu']:.1f}" if old
                else "| not run | - | -")  # fmt: skip
        lines.append(
            f"| 01_02 walk | {minutes:g} | {new['peak']:.0f} | {new['wall']:.1f} | "
            f"{new['cpu']:.1f} | {seconds / new['cpu']:.0f}x | {r['bytes']:,} {base} |"
        )
    worst = max(r["new"]["peak"] for _, _, r in rows)
    lines += ["", f"`--contacts` peak at most **{worst:.0f} MB** (aim: at most {TARGET_MB} MB: "
              f"{'met' if worst <= TARGET_MB else '**not met**'}); its foot points grow with the "
              "take (288 bytes a frame, 31 MB an hour at 30 fps)."]  # fmt: skip
    return "\n".join(lines)


def window_cost(data: Path) -> dict:
    """Bytes at 2 mm and mean error at 942 B/s of every trial of ``data``: whole against 300-frame
    windows."""
    from sidql.codec.encode import encode_series
    from sidql.codec.windows import encode_windows
    from sim.motion.chunks import stream_clips
    from sim.motion.dataset import find_trials

    out = {"trials": 0, "cuts": 0, "whole_bytes": 0, "window_bytes": 0, "frames": 0,
           "whole_err": 0.0, "window_err": 0.0, "rate_bytes_whole": 0, "rate_bytes_window": 0}  # fmt: skip
    for t in find_trials(data):
        runs = {}
        for name, window in (("whole", 10**6), ("window", 300)):
            for target in ({"max_error": 2.0}, {"rate": float(RATE)}):
                enc = encode_windows(
                    io.BytesIO(), stream_clips(t.asf, t.amc), encode_series, window=window,
                    **target,
                )  # fmt: skip
                runs[name, next(iter(target))] = enc
        w = runs["window", "max_error"]
        out["trials"] += 1
        out["cuts"] += w.streams - 1
        out["frames"] += w.n_frames
        out["whole_bytes"] += runs["whole", "max_error"].n_bytes
        out["window_bytes"] += w.n_bytes
        n = runs["whole", "rate"].n_frames
        out["whole_err"] += runs["whole", "rate"].mean_error_mm * n
        out["window_err"] += runs["window", "rate"].mean_error_mm * n
        out["rate_bytes_whole"] += runs["whole", "rate"].n_bytes
        out["rate_bytes_window"] += runs["window", "rate"].n_bytes
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--minutes", type=float, nargs="+", default=[2.5, 5.0, 10.0, 30.0, 60.0])
    ap.add_argument("--baseline-minutes", type=float, nargs="+", default=[2.5, 5.0, 10.0])
    ap.add_argument("--bvh-minutes", type=float, nargs="*", default=[5.0, 10.0])
    ap.add_argument("--contacts-minutes", type=float, nargs="*", default=[5.0, 10.0, 30.0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--vigorous-minutes", type=float, default=VIGOROUS_MINUTES)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    sidql = [sys.executable, "-m", "sidql.commands.main"]
    baseline = [sys.executable, "-c", BASELINE]
    load_start = os.getloadavg()
    amc_take, targets = None, []
    mem_rows, speed_rows, bvh_rows, contact_rows = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)

        def take(kind: str, minutes: float) -> tuple[Path, Path, float]:
            subject, trial = TAKES[kind]
            asf = args.data / subject / f"{subject}.asf"
            frames = int(round(minutes * 60 * SOURCE_FPS))
            amc = write_take(asf, args.data / subject / f"{trial}.amc", frames,
                             tmp / f"{kind}_{minutes:g}.amc")  # fmt: skip
            return asf, amc, frames / SOURCE_FPS

        out = str(tmp / "f.sidq")
        asf, amc, _ = take("walk", 0.5)
        measured([*sidql, "encode", str(asf), str(amc), "--out", out, "--rate", RATE])  # warm
        measured([*baseline, str(asf), str(amc), out, RATE])  # compiled kernels cached
        last = None
        for minutes in sorted(args.minutes):
            asf, amc, seconds = take("walk", minutes)
            new = measured([*sidql, "encode", str(asf), str(amc), "--out", out, "--rate", RATE])
            old = None
            if minutes in args.baseline_minutes:
                old = measured([*baseline, str(asf), str(amc), str(tmp / "old.sidq"), RATE])
            mem_rows.append((minutes, seconds, Path(amc).stat().st_size, new, old,
                             Path(out).stat().st_size))  # fmt: skip
            if minutes in args.bvh_minutes:
                bvh_rows.append((minutes, bvh_row(sidql, baseline, asf, amc, tmp)))
            if minutes in args.contacts_minutes:
                row = contacts_row(sidql, asf, amc, tmp, minutes in args.baseline_minutes)
                contact_rows.append((minutes, seconds, row))
            if last is not None:
                os.unlink(last)
            last = amc
            if minutes <= AMC_DECODE_MINUTES:  # the AMC decoder fits angles frame by frame: slow
                shutil.copyfile(out, tmp / "amc_source.sidq")
                amc_take = (minutes, asf)
                targets = [(t, minutes, measured([*sidql, "encode", str(asf), str(amc), "--out",
                                                  out, *t.split()])) for t in OTHER_TARGETS]  # fmt: skip
            print(mem_rows[-1][:3], new["peak"], old and old["peak"], flush=True)
        decoded = {}
        longest = mem_rows[-1][1]
        for suffix in (".npz", ".amc"):
            source, extra, minutes = out, [], longest / 60
            if suffix == ".amc" and amc_take is None:
                continue
            if suffix == ".amc":
                source, extra = str(tmp / "amc_source.sidq"), ["--asf", str(amc_take[1])]
                minutes = amc_take[0]
            r = measured([*sidql, "decode", source, "--out", str(tmp / f"d{suffix}"), *extra])
            decoded[suffix] = (minutes, r)
            os.unlink(tmp / f"d{suffix}")
        for kind in TAKES:
            asf, amc, seconds = take(kind, args.vigorous_minutes)
            cmd = [*sidql, "encode", str(asf), str(amc), "--out", out, "--rate", RATE]
            new = best(cmd, args.repeats)
            old = best([*baseline, str(asf), str(amc), str(tmp / "old.sidq"), RATE], args.repeats)
            speed_rows.append((kind, seconds, new, old))
            print(kind, new["wall"], old["wall"], flush=True)
            os.unlink(amc)
    cost = window_cost(args.data)
    text = page(args, mem_rows, speed_rows, decoded, targets, cost, load_start, os.getloadavg())
    text += bvh_page(bvh_rows) + contacts_page(contact_rows)
    print(text)
    if not args.no_write:
        print("wrote", write_results("codec_memory", "Codec memory and speed at any length", text,
                                     command="python benchmarks/bench_codec_memory.py"))  # fmt: skip
    return 0


def page(args, mem_rows, speed_rows, decoded, targets, cost, load_start, load_end) -> str:
    load = (f"load average {load_start[0]:.1f} / {load_start[1]:.1f} (1 / 5 min) at the start, "
            f"{load_end[0]:.1f} / {load_end[1]:.1f} at the end, {os.cpu_count()} cores")  # fmt: skip
    lines = [
        f"`sidql encode --rate {RATE}` in a child process; peak resident memory (`ru_maxrss`), "
        f"wall and CPU (user + system) times from `wait4`; {load}. Takes: real trials played "
        "forwards and backwards (120 fps source, encoded at 30 fps). Baseline: the whole-take "
        "path (`load_motion` of the whole take, its chart, `encode_series`) in the same run.",
        "",
        "| take | minutes | AMC MB | peak MB | wall s | CPU s | x real time (wall / CPU) "
        "| file bytes | baseline peak MB | baseline wall s | baseline CPU s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for minutes, seconds, size, new, old, nbytes in mem_rows:
        base = ("| {:.0f} | {:.1f} | {:.1f}".format(old["peak"], old["wall"], old["cpu"])
                if old else "| refused (AMC over 64 MB) or not run | - | -")  # fmt: skip
        lines.append(
            f"| 01_02 walk | {minutes:g} | {size / 2**20:.0f} | {new['peak']:.0f} | "
            f"{new['wall']:.1f} | {new['cpu']:.1f} | {seconds / new['wall']:.0f}x / "
            f"{seconds / new['cpu']:.0f}x | {nbytes:,} {base} |"
        )
    worst = max([r[3]["peak"] for r in mem_rows] + [r["peak"] for _, _, r in targets])
    lines += [
        "",
        f"Peak at most **{worst:.0f} MB** for takes of {mem_rows[0][0]:g} to {mem_rows[-1][0]:g} "
        f"minutes, every target below included (aim: at most {TARGET_MB} MB whatever the length: "
        f"{'met' if worst <= TARGET_MB else '**not met**'}).",
        "",
        "Other targets, the same way:",
        "",
        "| take | command | peak MB | wall s | CPU s | x real time (CPU) |",
        "|---|---|---|---|---|---|",
        *(
            f"| 01_02 walk, {m:g} min | `sidql encode {t}` | {r['peak']:.0f} | {r['wall']:.1f} | "
            f"{r['cpu']:.1f} | {m * 60 / r['cpu']:.0f}x |"
            for t, m, r in targets
        ),  # fmt: skip
        "",
        "Decoding takes back (`sidql decode`, a sequence of streams, one stream at a time):",
        "",
        "| take | output | peak MB | wall s | CPU s | x real time (CPU) |",
        "|---|---|---|---|---|---|",
    ]
    for suffix, (minutes, r) in decoded.items():
        lines.append(f"| 01_02 walk, {minutes:g} min | {suffix} | {r['peak']:.0f} | "
                     f"{r['wall']:.1f} | {r['cpu']:.1f} | {minutes * 60 / r['cpu']:.0f}x |")  # fmt: skip
    lines += [
        "",
        f"Speed by kind of motion, {args.vigorous_minutes:g}-minute takes, best of {args.repeats}:",
        "",
        "| take | wall s | CPU s | x real time (wall) | x real time (CPU) | peak MB "
        "| baseline wall s | baseline CPU s | baseline x (wall / CPU) | baseline peak MB |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for kind, seconds, new, old in speed_rows:
        subject, trial = TAKES[kind]
        lines.append(
            f"| {trial} {kind} | {new['wall']:.2f} | {new['cpu']:.2f} | "
            f"{seconds / new['wall']:.0f}x | {seconds / new['cpu']:.0f}x | {new['peak']:.0f} | "
            f"{old['wall']:.2f} | {old['cpu']:.2f} | {seconds / old['wall']:.0f}x / "
            f"{seconds / old['cpu']:.0f}x | {old['peak']:.0f} |"
        )
    slowest = min(s / n["cpu"] for _, s, n, _ in speed_rows)
    lines += [
        "",
        f"Slowest kind of motion: {slowest:.0f}x real time in CPU time (aim: at least 100x: "
        f"{'met' if slowest >= 100 else '**not met**'}); wall times depend on the load above.",
        "",
        f"**The cost of windowing** on the {cost['trials']} trials of `../shared` "
        f"({cost['frames']:,} frames), each encoded whole and in 300-frame windows "
        f"({cost['cuts']} cuts in all): at a mean position error of 2 mm "
        f"{cost['whole_bytes']:,} bytes whole, {cost['window_bytes']:,} in windows "
        f"({cost['window_bytes'] / cost['whole_bytes'] - 1:+.1%}, "
        f"{(cost['window_bytes'] - cost['whole_bytes']) / max(cost['cuts'], 1):.0f} bytes per "
        f"cut); at {RATE} B/s ({cost['rate_bytes_whole']:,} and {cost['rate_bytes_window']:,} "
        f"bytes) a mean error of {cost['whole_err'] / cost['frames']:.3f} mm whole and "
        f"{cost['window_err'] / cost['frames']:.3f} mm in windows. The command line's windows "
        "are 900 frames (30 s at 30 fps): a take of at most 960 frames is one window, the same "
        "bytes as before.",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
