"""Which clips' captures are held up by nothing: frames that need the floor with nothing to push on.

Usage::

    python benchmarks/bench_capture_support.py --data ../shared/cmu \
        [--rows ROWS.jsonl] [--controller mix0.5s40terrain] [--force-share 1.5] [--reach 0.4] \
        [--residual] [--page capture_support] [--no-write]

Per clip of eval's cases (60 frames), on the CMU capture's own joint positions (no IK fit, no
simulation) above its trial's floor (``sim.physics.ground.estimate_ground`` over the trial's
clips, as eval's physics finds it): the frames where the root's vertical acceleration asks the
floor for more than 1.5 times the body's weight (``--force-share``) while no joint is within 8 cm
of the floor or the nearest such joint is over 0.4 m from the root horizontally (``--reach``;
``sim.simulate.capture_support.unsupported_frames``). A clip with at least
:data:`MIN_UNSUPPORTED_S` of such frames cannot be performed as captured by any body without
help. With ``--rows`` (a ``bench_simulate.py --log`` of eval's forward simulation) each clip's
fall is set beside it, and a second table counts the clips flagged under other thresholds.
With ``--residual`` the original's inverse dynamics (``eval --physics``: the residual force no
ground contact supplies, ``sim.physics``) is set beside it, clip by clip, and with ``--rows``
both are scored against the falls: each signal's AUC, and the clips each rule flags at a
threshold set before the falls were looked at (the physics' own ``SUPPORT_MISSING_BW`` and
``SUPPORT_FLAG_SHARE``, the trial rule of ``sim.physics.support.support_verdict``).
Writes ``docs/results/<page>.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results import write_results  # noqa: E402

from sidql.evaluation.cases import load_cases  # noqa: E402
from sidql.evaluation.trial_physics import physics_setup  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402
from sim.physics.ground import estimate_ground  # noqa: E402
from sim.physics.support import (  # noqa: E402
    SUPPORT_FLAG_SHARE,
    SUPPORT_MISSING_BW,
    capture_unsupported,
)
from sim.simulate.capture_support import (  # noqa: E402
    FORCE_SHARE,
    NEAR_FLOOR,
    REACH,
    support_demand,
    unsupported_frames,
)

#: [s] a clip with at least this much unsupported capture is not performable as captured
MIN_UNSUPPORTED_S = 0.1
TITLE = "The captures held up by nothing: frames that need the floor with nothing to push on"


#: (force share, reach [m]) of the sensitivity table
SENSITIVITY = ((1.0, 0.4), (1.0, 0.6), (1.5, 0.3), (1.5, 0.6), (2.0, 0.4))


def trial_floors(cases) -> dict:
    """Per trial (``clip.source``): its floor from all its clips among ``cases`` (in time
    order), as eval's physics finds it (``estimate_ground``)."""
    by_trial: dict[str, list] = {}
    for c in cases:
        by_trial.setdefault(c.clip.source, []).append(c)
    grounds = {}
    for source, group in by_trial.items():
        group = sorted(group, key=lambda c: c.clip.start_frame)
        pos = np.concatenate([c.clip.positions for c in group])
        grounds[source] = estimate_ground(pos, group[0].clip.names, group[0].clip.fps)
    return grounds


def clip_rows(cases, force_share: float = FORCE_SHARE, reach: float = REACH) -> list[dict]:
    """Per case (in order): its clip name, unsupported frames, the first one [s], the largest
    force asked among them [body weights] and the root's lowest height [m]."""
    grounds = trial_floors(cases)
    rows = []
    for c in cases:
        pos = np.array(c.clip.positions, dtype=float)
        pos[..., 2] -= grounds[c.clip.source].level(pos[..., :2])
        root = list(c.clip.names).index("root")
        flags = unsupported_frames(pos, c.clip.fps, root, force_share=force_share, reach=reach)
        demand = support_demand(pos[:, root, 2], c.clip.fps)
        rows.append({
            "clip": f"{Path(c.clip.source).stem}@{c.clip.start_frame}",
            "unsupported": int(flags.sum()),
            "unsupported_s": float(flags.sum() / c.clip.fps),
            "first_s": float(np.argmax(flags) / c.clip.fps) if flags.any() else None,
            "demand_max": float(demand[flags].max()) if flags.any() else None,
            "root_min_m": float(pos[:, root, 2].min()),
        })  # fmt: skip
    return rows


def read_falls(path: str | None, controller: str) -> dict[str, dict]:
    """``controller``'s rows of a ``bench_simulate.py --log`` by clip name (``02_01@240``)."""
    if not path:
        return {}
    out = {}
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.strip():
                r = json.loads(line)
                if r.get("controller", controller) == controller:
                    out[f"{Path(r['clip'].split('@')[0]).stem}@{r['clip'].split('@')[1]}"] = r
    return out


def flagged(rows: list[dict]) -> list[str]:
    """The clips of ``rows`` with at least :data:`MIN_UNSUPPORTED_S` unsupported."""
    return [r["clip"] for r in rows if r["unsupported_s"] >= MIN_UNSUPPORTED_S - 1e-9]


def page(rows: list[dict], falls: dict[str, dict], controller: str, args) -> str:
    """The page's markdown: a summary and a row per clip with any unsupported frame."""
    hits = flagged(rows)
    text = (
        f"{len(rows)} clips. A frame is unsupported where the root's vertical acceleration "
        f"asks the floor for more than {args.force_share:g} times the body's weight while no "
        f"captured joint is within {NEAR_FLOOR * 100:g} cm of the floor or the nearest such "
        f"joint is over {args.reach:g} m from the root horizontally. **{len(hits)} clips** "
        f"have at least {MIN_UNSUPPORTED_S:g} s of them"
    )
    if falls:
        fell = {k for k, r in falls.items() if r.get("sim_fell")}
        hit = [c for c in hits if c in fell]
        up = [c for c in hits if c in falls and c not in fell]
        text += (
            f"; `{controller}` (the rows given) falls in {len(hit)} of them and stays up in "
            f"{len(up)}{' (' + ', '.join(up) + ')' if up else ''}; of its {len(fell)} falls "
            f"{len(hit)} are in these clips"
        )
    text += ".\n\n| clip | unsupported [s] | first [s] | force asked there, max [body weights] | root lowest [m] |"
    text += " fell [s] |\n|---|---|---|---|---|---|\n" if falls else "\n|---|---|---|---|---|\n"
    for r in rows:
        if not r["unsupported"]:
            continue
        cells = [r["clip"], f"{r['unsupported_s']:.2f}", f"{r['first_s']:.2f}",
                 f"{r['demand_max']:.1f}", f"{r['root_min_m']:.2f}"]  # fmt: skip
        if falls:
            f = falls.get(r["clip"], {})
            cells.append("-" if not f else f"{f['sim_fall_s']:.2f}" if f.get("sim_fell") else "no")
        text += "| " + " | ".join(cells) + " |\n"
    return text


def sensitivity(cases, falls: dict[str, dict]) -> str:
    """A table: per (force share, reach) of :data:`SENSITIVITY`, the clips flagged and, with
    ``falls``, how many of them fall and which stay up."""
    fell = {k for k, r in falls.items() if r.get("sim_fell")}
    text = "\n| force share | reach [m] | clips flagged | of them fall | stay up |\n|---|---|---|---|---|\n"
    for share, reach in SENSITIVITY:
        hits = flagged(clip_rows(cases, share, reach))
        up = [c for c in hits if c in falls and c not in fell]
        down = len([c for c in hits if c in fell]) if falls else "-"
        text += f"| {share:g} | {reach:g} | {len(hits)} | {down} | {', '.join(up) or '-'} |\n"
    return text


def long_runs(mask: np.ndarray, n: int) -> np.ndarray:
    """(T,) bool: the frames of ``mask`` (T,) bool in runs of at least ``n`` True frames."""
    out = np.zeros(len(mask), dtype=bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(mask, np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        out[a:b] = b - a >= n
    return out


def residual_rows(cases) -> list[dict]:
    """Per case (in order): the original's inverse dynamics as ``eval --physics`` runs it
    (``physics_setup``: the trial's floor and contacts over all its clips among ``cases``): its
    residual force's mean and p95 [BW], torque [N m/kg], ``support_missing_share``, and the
    seconds of measured frames in runs of at least :data:`MIN_UNSUPPORTED_S` whose residual
    exceeds ``SUPPORT_MISSING_BW`` (``over_s``; ``over_first_s`` the first, None if none)."""
    setup = physics_setup(cases)
    rows = []
    for c in cases:
        a = setup[c.clip.source].analyse(c.clip)
        pf = a["per_frame"]
        over = (np.asarray(pf["residual_force_bw"]) > SUPPORT_MISSING_BW) & np.asarray(
            pf["dynamics_measured"], dtype=bool
        )
        run = long_runs(over, int(round(MIN_UNSUPPORTED_S * c.clip.fps)))
        rows.append({
            "residual_bw": float(a["residual_force_bw"]),
            "residual_p95_bw": float(a["residual_force_bw_p95"]),
            "residual_torque": float(a["residual_torque_nm_kg"]),
            "missing_share": float(a["support_missing_share"]),
            "over_s": float(run.sum() / c.clip.fps),
            "over_first_s": float(np.argmax(run) / c.clip.fps) if run.any() else None,
        })  # fmt: skip
    return rows


def auc(scores, positive) -> float:
    """The area under the ROC curve of ``scores`` (N,) for ``positive`` (N,) bool: the chance
    that a positive scores above a negative, ties counting half (Mann-Whitney)."""
    s, y = np.asarray(scores, dtype=float), np.asarray(positive, dtype=bool)
    pos, neg = s[y][:, None], s[~y][None, :]
    return float(((pos > neg) + 0.5 * (pos == neg)).mean())


def auc_gain(better, worse, positive, resamples: int = 2000, seed: int = 0) -> tuple:
    """``auc(better) - auc(worse)`` over the same clips and its 95 % interval, the clips
    resampled with replacement (``resamples`` times, seeded; resamples without a positive or
    without a negative are skipped)."""
    a, b = np.asarray(better, dtype=float), np.asarray(worse, dtype=float)
    y = np.asarray(positive, dtype=bool)
    rng = np.random.default_rng(seed)
    gains = []
    for _ in range(resamples):
        i = rng.integers(0, len(y), len(y))
        if 0 < y[i].sum() < len(i):
            gains.append(auc(a[i], y[i]) - auc(b[i], y[i]))
    lo, hi = np.percentile(gains, [2.5, 97.5])
    return auc(a, y) - auc(b, y), float(lo), float(hi)


#: (label, key of the joined row, its unit) of the signals compared
SIGNALS = (
    ("capture_support: unsupported", "unsupported_s", "s"),
    ("residual force, mean", "residual_bw", "BW"),
    ("residual force, p95", "residual_p95_bw", "BW"),
    (f"residual force > {SUPPORT_MISSING_BW:g} BW for >= {MIN_UNSUPPORTED_S:g} s", "over_s", "s"),
    ("support missing (nothing on the floor, > 0.5 BW)", "missing_share", "share"),
    ("residual torque, mean", "residual_torque", "N m/kg"),
)


def comparison(rows: list[dict], falls: dict[str, dict]) -> str:
    """Markdown: each signal's AUC for the falls of ``falls`` over the joined per-clip ``rows``
    (``clip_rows`` and ``residual_rows`` merged), then the clips each rule flags at a threshold
    set before the falls were looked at, and how many of them fall."""
    rows = [r for r in rows if r["clip"] in falls]
    fell = np.array([bool(falls[r["clip"]].get("sim_fell")) for r in rows])
    text = (f"\n**Against the falls** ({len(rows)} clips, {int(fell.sum())} falls): the area under "
            "the ROC curve of each per-clip signal (0.5: chance; 1: every fall above every clip "
            "that stays up).\n\n| signal | unit | AUC |\n|---|---|---|\n")  # fmt: skip
    for label, key, unit in SIGNALS:
        text += f"| {label} | {unit} | {auc([r[key] for r in rows], fell):.3f} |\n"
    gain = auc_gain([r["missing_share"] for r in rows], [r["unsupported_s"] for r in rows], fell)
    text += ("\nSupport missing against capture_support, paired over the clips: AUC "
             "{:+.3f}, 95 % interval [{:+.3f}, {:+.3f}] (2000 resamples).\n").format(*gain)  # fmt: skip
    rules = (
        (f"capture_support >= {MIN_UNSUPPORTED_S:g} s (thresholds chosen on these clips)",
         lambda r: r["unsupported_s"] >= MIN_UNSUPPORTED_S - 1e-9, "first_s"),
        (f"residual > {SUPPORT_MISSING_BW:g} BW for >= {MIN_UNSUPPORTED_S:g} s",
         lambda r: r["over_s"] >= MIN_UNSUPPORTED_S - 1e-9, "over_first_s"),
        (f"support missing in > {SUPPORT_FLAG_SHARE:.0%} of frames (`capture_unsupported`)",
         lambda r: capture_unsupported(r["missing_share"]), None),
    )  # fmt: skip
    text += ("\n| rule | clips flagged | of them fall | flagged before the fall | falls missed "
             "| stay up |\n|---|---|---|---|---|---|\n")  # fmt: skip
    for label, rule, first in rules:
        hit = np.array([rule(r) for r in rows], dtype=bool)
        early = "-" if first is None else str(sum(
            1 for r, h, f in zip(rows, hit, fell, strict=True)
            if h and f and r[first] < falls[r["clip"]]["sim_fall_s"]
        ))  # fmt: skip
        up = [r["clip"] for r, h, f in zip(rows, hit, fell, strict=True) if h and not f]
        text += (f"| {label} | {hit.sum()} | {(hit & fell).sum()} | {early} | "
                 f"{(~hit & fell).sum()} | {', '.join(up) or '-'} |\n")  # fmt: skip
    return text


def joined_table(rows: list[dict], falls: dict[str, dict]) -> str:
    """Markdown: per clip that falls or that any signal flags, the signals side by side."""
    text = ("\nPer clip that falls or that any rule flags (first: the first flagged frame):\n"
            "\n| clip | fell [s] | capture_support [s] (first) | residual mean / p95 [BW] | "
            f"residual > {SUPPORT_MISSING_BW:g} BW [s] (first) | support missing [share] |\n"
            "|---|---|---|---|---|---|\n")  # fmt: skip

    def first(v):
        return "" if v is None else f" ({v:.2f})"

    for r in rows:
        f = falls.get(r["clip"], {})
        flags = (r["unsupported_s"] > 0, r["over_s"] > 0, capture_unsupported(r["missing_share"]))
        if not (f.get("sim_fell") or any(flags)):
            continue
        fell = "-" if not f else f"{f['sim_fall_s']:.2f}" if f.get("sim_fell") else "no"
        text += (f"| {r['clip']} | {fell} | {r['unsupported_s']:.2f}{first(r['first_s'])} | "
                 f"{r['residual_bw']:.2f} / {r['residual_p95_bw']:.2f} | "
                 f"{r['over_s']:.2f}{first(r['over_first_s'])} | {r['missing_share']:.2f} |\n")  # fmt: skip
    return text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=default_data_dir())
    ap.add_argument("--every", type=int, default=1)
    ap.add_argument("--offset", type=int, default=0)
    ap.add_argument("--rows", default=None, help="a bench_simulate.py --log: each clip's fall")
    ap.add_argument("--controller", default="mix0.5s40terrain", help="whose rows in --rows")
    ap.add_argument(
        "--force-share",
        type=float,
        default=FORCE_SHARE,
        help="body weights the floor must give for a frame to need support",
    )
    ap.add_argument(
        "--reach",
        type=float,
        default=REACH,
        help="[m] a joint on the floor farther than this from the root is not under it",
    )
    ap.add_argument(
        "--residual",
        action="store_true",
        help="set the original's inverse dynamics (eval --physics's residual) beside it",
    )
    ap.add_argument("--page", default="capture_support")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    if not args.page.replace("_", "").isalnum():
        ap.error(f"--page must be a plain name; got {args.page!r}")
    command = "python benchmarks/bench_capture_support.py " + " ".join(sys.argv[1:])
    t0 = time.perf_counter()
    cases, _ = load_cases(args.data, progress=False, workers=1)
    cases = cases[args.offset :: args.every]
    falls = read_falls(args.rows, args.controller)
    rows = clip_rows(cases, args.force_share, args.reach)
    text = page(rows, falls, args.controller, args) + sensitivity(cases, falls)
    if args.residual:
        rows = [{**r, **p} for r, p in zip(rows, residual_rows(cases), strict=True)]
        text += comparison(rows, falls) if falls else ""
        text += joined_table(rows, falls)
    print(text)
    print(f"({time.perf_counter() - t0:.0f} s)")
    if not args.no_write:
        write_results(args.page, TITLE, text, command)


if __name__ == "__main__":
    main()
