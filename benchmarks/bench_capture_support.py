"""Which clips' captures are held up by nothing: frames that need the floor with nothing to push on.

Usage::

    python benchmarks/bench_capture_support.py --data ../shared/cmu \
        [--rows ROWS.jsonl] [--controller mix0.5s40terrain] [--force-share 1.5] [--reach 0.4] \
        [--page capture_support] [--no-write]

Per clip of eval's cases (60 frames), on the CMU capture's own joint positions (no IK fit, no
simulation) above its trial's floor (``sim.physics.ground.estimate_ground`` over the trial's
clips, as eval's physics finds it): the frames where the root's vertical acceleration asks the
floor for more than 1.5 times the body's weight (``--force-share``) while no joint is within 8 cm
of the floor or the nearest such joint is over 0.4 m from the root horizontally (``--reach``;
``sim.simulate.capture_support.unsupported_frames``). A clip with at least
:data:`MIN_UNSUPPORTED_S` of such frames cannot be performed as captured by any body without
help. With ``--rows`` (a ``bench_simulate.py --log`` of eval's forward simulation) each clip's
fall is set beside it, and a second table counts the clips flagged under other thresholds.
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
from sim.paths import default_data_dir  # noqa: E402
from sim.physics.ground import estimate_ground  # noqa: E402
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
    text = page(clip_rows(cases, args.force_share, args.reach), falls, args.controller, args)
    text += sensitivity(cases, falls)
    print(text)
    print(f"({time.perf_counter() - t0:.0f} s)")
    if not args.no_write:
        write_results(args.page, TITLE, text, command)


if __name__ == "__main__":
    main()
