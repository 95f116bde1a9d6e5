"""Validation by forward simulation, per keyframe method: could a body perform the motion?

Usage::

    python benchmarks/bench_simulate.py --data ../shared/cmu [--keyframes 10] [--workers 2]
        [--samples 64] [--every 5] [--max-clips N]

Every 60-frame clip (30 fps) of the trials under ``--data`` is rebuilt by each method; the
subject's humanoid is fitted to the original and to every reconstruction (``sim.physics``) and
the subject's torque-limited body tracks each fit in ``mj_step`` with no assistance
(``sim.simulate.validate``), exactly as ``sidql eval --physics --simulate`` does. Per method:
the tracking error against the motion tracked and against the original, the share of clips in
which the body fell and when, and the joint torque it used; the original's own row is the
baseline. Written to ``docs/results/simulate.md`` (with ``--samples N``, the sampling tracker
of ``sim.simulate.sampling``: ``docs/results/simulate_sampled.md``). Quality figures: the machine's load does not
change them.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results import keep_rows, write_results  # noqa: E402
from simulate_controllers import CONTROLLERS  # noqa: E402

from sidql.evaluation.cases import load_cases  # noqa: E402
from sidql.evaluation.evaluate import evaluate  # noqa: E402
from sidql.evaluation.tables import simulate_markdown  # noqa: E402
from sidql.evaluation.trial_physics import _protocol_names, physics_setup  # noqa: E402
from sim.model.humanoid import subject_model  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402
from sim.simulate.gainchoice import common_body  # noqa: E402
from sim.simulate.validate import ForwardValidation, validation_spec  # noqa: E402


def _clip_rows(c, setup, names, bodies: dict, threads: int) -> dict[str, dict]:
    """Per controller name, the figures of ``ForwardValidation.run`` on case ``c``'s original
    motion (its IK fit from ``setup``, :func:`physics_setup`); ``bodies`` caches each subject's
    body per controller."""
    qpos = setup[c.clip.source].analyse(c.clip)["per_frame"]["qpos"]
    out = {}
    for n in names:
        _, kw, actuators = CONTROLLERS[n][:3]
        model_kw = dict(CONTROLLERS[n][3]) if len(CONTROLLERS[n]) > 3 else {}
        if (c.asf, n) not in bodies:
            skeleton = subject_model(c.asf)[0]
            alternate = model_kw.pop("alternate_gains", ())  # gain sets chosen per window
            specs = [validation_spec(skeleton, actuators=actuators, **{**model_kw, **g})
                     for g in ({}, *({"gains": a} for a in alternate))]  # fmt: skip
            models = [x.compile() for x in specs]  # validation_model's bodies
            model, *alts = common_body(models) if alternate else models
            if alts:
                kw = {**kw, "search": {**kw.get("search", {}), "alternates": tuple(alts)}}
            if kw.get("terrain"):  # a clip's scene is compiled from these
                kw = {**kw, "specs": tuple(specs)}
            bodies[c.asf, n] = ForwardValidation(
                model, _protocol_names(c.clip), threads=threads, **kw
            )
        t0 = time.process_time()
        w0 = time.perf_counter()
        row = bodies[c.asf, n].run(qpos, c.clip.fps)  # the fits above are not timed
        seconds = c.clip.n_frames / c.clip.fps
        cpu = (time.process_time() - t0) / seconds
        wall = (time.perf_counter() - w0) / seconds
        out[n] = {"clip": f"{c.clip.source}@{c.clip.start_frame}", **row,
                  "sim_unstable": int(bodies[c.asf, n].last_unstable),
                  "sim_cpu_s_per_s": cpu, "sim_wall_s_per_s": wall}  # fmt: skip
        if bodies[c.asf, n].terrain:  # the scene's boxes: [top, half x, half y] [m]
            out[n]["sim_terrain"] = [[round(b.top, 3), *np.round(b.half[:2], 3).tolist()]
                                     for b in bodies[c.asf, n].last_boxes]  # fmt: skip
    return out


_WORKER: dict = {"setup": {}, "bodies": {}}  # a pool worker's fits per trial, bodies per subject


def _clip_task(item) -> dict[str, dict]:
    """One clip in a pool worker: ``item`` = (case, every case of its trial, names, threads);
    the trial's physics set up once per worker from all its clips, as one process would."""
    c, trial_cases, names, threads = item
    if c.clip.source not in _WORKER["setup"]:
        _WORKER["setup"].update(physics_setup(trial_cases))
    return _clip_rows(c, _WORKER["setup"], names, _WORKER["bodies"], threads)


def controller_rows(
    cases,
    names: list[str],
    log=None,
    threads: int = 1,
    workers: int = 1,
    deadline: float | None = None,
) -> dict[str, list[dict]]:
    """Per controller name (:data:`CONTROLLERS`), the figures of
    ``ForwardValidation.run`` for the original motion (its IK fit) of every case, in case
    order: in one process (the sampler's rollouts on ``threads`` threads; its CPU time counts
    every thread's), or one clip per task on ``workers`` processes (the same figures: every
    controller is deterministic and each trial's physics is set up from all its clips).
    ``deadline`` [s of wall time from the call]: no clip is started after it (every
    controller still runs on each clip started, so the rows stay paired); the clips are then
    taken every fifth first (:func:`spread_order`), so those done spread over the trials."""
    out: dict[str, list[dict]] = {n: [] for n in names}
    if workers <= 1:
        setup, bodies = physics_setup(cases), {}
        order = spread_order(len(cases)) if deadline else range(len(cases))
        done = _in_time(((i, _clip_rows(cases[i], setup, names, bodies, threads))
                         for i in order), deadline)  # fmt: skip
    else:
        by_trial: dict[str, list] = {}
        for c in cases:
            by_trial.setdefault(c.clip.source, []).append(c)
        items = [(c, by_trial[c.clip.source], names, threads) for c in cases]
        done = _pool_rows(items, workers, deadline)
    got: dict[int, dict] = {}
    for i, rows in done:
        got[i] = rows
        if log:
            for n in names:
                log(f"{i + 1}/{len(cases)} {n} {rows[n]}", rows[n] | {"controller": n})
    for i in sorted(got):
        for n in names:
            out[n].append(got[i][n])
    return out


def spread_order(n: int, stride: int = 5) -> list[int]:
    """The positions 0..n-1, every ``stride``-th first (0, 5, 10, ..., then 1, 6, ...): any
    prefix of the clips spreads over the trials (the first n / 5 are ``--every 5``'s clips)."""
    return sorted(range(n), key=lambda i: (i % stride, i))


def _in_time(pairs, deadline: float | None):
    """``pairs`` (any items, lazily) until ``deadline`` seconds have passed since the first was
    asked: none is asked for after it."""
    t0 = time.perf_counter()
    for pair in pairs:
        yield pair
        if deadline is not None and time.perf_counter() - t0 > deadline:
            return


def _pool_rows(items: list, workers: int, deadline: float | None = None):
    """(position, rows) of :func:`_clip_task` per item as the clips finish, none started after
    ``deadline`` seconds (then in :func:`spread_order`); a clip whose simulation failed is
    reported and left out."""
    from sim.batch import iter_batch

    order = spread_order(len(items)) if deadline else range(len(items))
    started = _in_time((items[i] for i in order), deadline)  # lazily: none after the deadline
    tasks = list(order)  # the pool numbers items by their place in the stream
    for k, outcome in iter_batch(_clip_task, started, workers=workers, progress=False,
                                 in_flight=workers):  # fmt: skip
        i = tasks[k]
        if outcome.ok:
            yield i, outcome.result
        else:
            print(f"clip {i} failed: {outcome.error}", flush=True)


def jsonl_log(path: str | None):
    """A log function printing each row, and appending it as a JSON line to ``path`` (a new
    file, not followed through a link) where given: a long run's rows survive its end."""
    import json

    fd = None
    if path:
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
        except OSError as e:  # refused before any clip runs: a long run never ends on this
            raise SystemExit(f"{path}: {e.strerror}: --log takes a new file") from None

    def log(message: str, row: dict | None = None) -> None:
        print(message, flush=True)
        if fd is not None and row is not None:
            os.write(fd, (json.dumps(row) + "\n").encode())

    return log


def read_log(path: str) -> dict[str, list[dict]]:
    """Per controller name, the rows of a ``--log`` file (JSON lines), in clip order."""
    import json

    out: dict[str, list[dict]] = {}
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.strip():
                row = json.loads(line)
                out.setdefault(row["controller"], []).append(row)
    return out


#: appended to the label of this run's rows (``--label``: what the code measured differs in)
RUN_LABEL = {"text": ""}


def label(name: str) -> str:
    """The table label of a row name: a controller's, or ``<name> (<log>)`` for a baseline's
    rows read from a log (``--baseline-log``: ``name@log``); this run's rows carry
    ``--label``."""
    if "@" in name:
        n, log = name.split("@", 1)
        return f"{CONTROLLERS[n][0]}, the baseline's rows ({Path(log).name})"
    extra = RUN_LABEL["text"]
    return CONTROLLERS[name][0] + (f", {extra}" if extra else "")


def paired_markdown(rows: dict[str, list[dict]]) -> str:
    """Each controller against the first, paired over the clips both ran
    (``sidql.evaluation.significance.paired_bootstrap``: the mean difference, its 95 %
    interval over 10,000 resamples of the clips): falls, root-relative and global error, and
    the median per-clip change of each error."""
    from sidql.evaluation.significance import paired_bootstrap

    names = list(rows)
    base = {r["clip"]: r for r in rows[names[0]]}
    head = (
        f"Against the first row ({label(names[0])}), paired over the clips both ran: "
        "mean difference [95 % interval]; the median per-clip change.\n\n"
        "| controller | clips | falls | root-relative [mm] | median change | global [mm] | "
        "median change |\n|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for n in names[1:]:
        both = [(r, base[r["clip"]]) for r in rows[n] if r["clip"] in base]
        cells = [label(n), str(len(both))]
        for key in ("sim_fell", "sim_error_local_mm", "sim_error_mm"):
            a = np.array([r[key] for r, _ in both], dtype=float)
            b = np.array([q[key] for _, q in both], dtype=float)
            t = paired_bootstrap(a, b)
            fmt = "+.2f" if key == "sim_fell" else "+.0f"
            cells.append(f"{t['mean_diff']:{fmt}} [{t['ci_low']:{fmt}}, {t['ci_high']:{fmt}}]")
            if key != "sim_fell":
                cells.append(f"{np.median(a - b) if a.size else float('nan'):+.0f}")
        lines.append("| " + " | ".join(cells) + " |")
    return head + "\n".join(lines) + "\n"


def controllers_markdown(rows: dict[str, list[dict]]) -> str:
    """The controllers' table: falls, root-relative and global tracking error
    (mean over the protocol points, median over clips), foot skating in contact against the
    tracked motion's (medians over clips, the same estimator), CPU s per simulated s (mean)."""
    head = (
        "| controller | clips | falls | root-relative error, median [mm] | global error, "
        "median [mm] | skating in contact, median [mm/s] | the reference's [mm/s] | CPU s per "
        "simulated s |\n|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for n, rs in rows.items():

        def med(k, rs=rs):
            v = np.array([np.nan if r[k] is None else r[k] for r in rs], dtype=float)
            v = v[np.isfinite(v)]
            return float(np.median(v)) if v.size else float("nan")

        fell = float(np.mean([r["sim_fell"] for r in rs]))
        cpu = float(np.mean([r["sim_cpu_s_per_s"] for r in rs]))
        lines.append(
            f"| {label(n)} | {len(rs)} | {fell:.2f} | {med('sim_error_local_mm'):.0f} "
            f"| {med('sim_error_mm'):.0f} | {med('sim_skate_mm_s'):.0f} "
            f"| {med('sim_skate_ref_mm_s'):.0f} | {cpu:.2f} |"
        )
    unstable = {n: sum(r.get("sim_unstable", 0) for r in rs) for n, rs in rows.items()}
    note = "".join(f"\n{label(n)}: MuJoCo flagged a diverging acceleration in {k} "
                   "clips.\n" for n, k in unstable.items() if k)  # fmt: skip
    return head + "\n".join(lines) + "\n" + note


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--data", "--cmu", dest="cmu", default=default_data_dir(),
        help="folder of CMU trials (default: $SIDQL_DATA or ../shared/cmu)",
    )  # fmt: skip
    ap.add_argument("--keyframes", type=int, nargs="+", default=[10])
    ap.add_argument("--methods", nargs="+",
                    default=["random", "uniform", "greedy", "optimal", "pitch"])  # fmt: skip
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--max-clips", type=int, default=None)
    ap.add_argument(
        "--every",
        type=int,
        default=1,
        help="keep every N-th clip (a subset spread over the trials)",
    )
    ap.add_argument(
        "--offset", type=int, default=0,
        help="with --every: start at this clip (another subset: --every 5 --offset 2)",
    )  # fmt: skip
    ap.add_argument(
        "--samples",
        type=int,
        default=0,
        help="sampling tracker's rollouts per window (0: the plain tracker)",
    )
    ap.add_argument(
        "--controllers", nargs="+", choices=sorted(CONTROLLERS), default=None,
        help="compare these controllers on the original motion only (one clip per process on "
        "--workers; writes docs/results/simulate_controllers.md or --page)",
    )  # fmt: skip
    ap.add_argument(
        "--threads", type=int, default=1,
        help="with --controllers: the sampler's rollouts on this many threads",
    )  # fmt: skip
    ap.add_argument(
        "--page", default="simulate_controllers",
        help="with --controllers: the docs/results page written (default simulate_controllers)",
    )  # fmt: skip
    ap.add_argument(
        "--log", default=None,
        help="with --controllers: also append every clip's row as a JSON line to this new file",
    )  # fmt: skip
    ap.add_argument(
        "--deadline", type=float, default=None, metavar="S",
        help="with --controllers: start no clip after S seconds (every fifth clip first); the "
        "page says how many were done",
    )  # fmt: skip
    ap.add_argument(
        "--baseline-log", default=None, metavar="LOG",
        help="with --controllers: pair every controller against its rows in LOG (another "
        "run's --log, e.g. of another commit on the same clips), the baseline's rows first",
    )  # fmt: skip
    ap.add_argument(
        "--rows-log", default=None, metavar="LOG",
        help="with --controllers: take this run's rows from LOG (a finished run's --log) "
        "instead of simulating",
    )  # fmt: skip
    ap.add_argument("--note", default="", help="a line for the page (where its rows came from)")
    ap.add_argument(
        "--label", default="", help="with --controllers: appended to this run's rows' labels"
    )
    ap.add_argument("--no-write", action="store_true", help="print only")
    return ap


def controllers_page(args, cases, command: str, t0: float) -> None:
    """``--controllers``: each controller on the original motion of ``cases`` (or the rows
    of ``--rows-log``), paired with the first row (``--baseline-log``'s rows first where
    given); printed and written to ``docs/results/<--page>.md``."""
    if args.rows_log:
        logged = read_log(args.rows_log)
        rows = {n: logged[n] for n in args.controllers}
    else:
        rows = controller_rows(cases, args.controllers, log=jsonl_log(args.log),
                               threads=args.threads, workers=args.workers,
                               deadline=args.deadline)  # fmt: skip
    kept = {"": [r | {"controller": n} for n in rows for r in rows[n]]}
    if args.baseline_log:  # the baseline's rows of each controller first, then this run's
        logged = read_log(args.baseline_log)
        kept[".baseline"] = [r for n in rows if n in logged for r in logged[n]]
        rows = {**{f"{n}@{args.baseline_log}": logged[n] for n in rows if n in logged},
                **rows}  # fmt: skip
    limited = f", one clip in {args.every} only (--every)" if args.every > 1 else ""
    limited += f", from clip {args.offset} (--offset)" if args.offset else ""
    done = len(next(iter(rows.values())))
    if done < len(cases):
        limited += (
            f"; {done} of these {len(cases)} clips done within --deadline "
            f"{args.deadline:g} s (every fifth clip first, then the next fifth)"
        )
    text = (
        f"{len(cases)} clips of 60 frames (30 fps, 2 s) from "
        f"{len({c.clip.source for c in cases})} trials{limited}: the original motion (its "
        "IK fit on the subject's skeleton) tracked by each controller with no assistance; a "
        "fall as `sim.simulate.falls` defines it; CPU time of every thread "
        + (f"(the rows read from {Path(args.rows_log).name}, a finished run's --log).\n\n"
           if args.rows_log else f"(--threads {args.threads}; one clip per process on "
           f"--workers {args.workers}).\n\n")
        + controllers_markdown(rows)
        + ("\n" + paired_markdown(rows) if len(rows) > 1 else "")
        + ("" if args.rows_log else f"\nWall time {time.perf_counter() - t0:.0f} s "
           "(loading and fits included).\n")
    )  # fmt: skip
    print(text)
    if not args.no_write:
        notes = args.note + "\n\n" + _kept_rows_note(args, kept)
        write_results(args.page, "Forward simulation: the controllers on the "
                      "original motion", text, command, notes=notes.strip())  # fmt: skip


def _kept_rows_note(args, kept: dict[str, list[dict]]) -> str:
    """Keep the page's rows in ``docs/results/rows/`` and say how to write the page again
    from them alone (no simulation)."""
    paths = {suffix: keep_rows(args.page, rows, suffix) for suffix, rows in kept.items()}
    again = (
        f"python benchmarks/bench_simulate.py --data {args.cmu} --controllers "
        f"{' '.join(args.controllers)} --every {args.every} --offset {args.offset} "
        f"--rows-log {paths['']}"
        + (f" --baseline-log {paths['.baseline']}" if ".baseline" in paths else "")
        + f" --page {args.page}"
    )
    return f"The rows are kept in {', '.join(paths.values())}; the page again from them: `{again}`."


def main() -> None:
    ap = _parser()
    args = ap.parse_args()
    RUN_LABEL["text"] = args.label
    if not args.page.replace("_", "").isalnum():
        ap.error(f"--page must be a plain name (letters, digits, _); got {args.page!r}")
    if args.log and os.path.lexists(args.log):  # before the fits: --log takes a new file
        ap.error(f"--log {args.log}: exists; the rows go to a new file")
    command = "python benchmarks/bench_simulate.py " + " ".join(sys.argv[1:])
    t0 = time.perf_counter()
    cases, skipped = load_cases(args.cmu, progress=False, workers=args.workers)
    cases = cases[args.offset :: args.every][: args.max_clips]
    if args.controllers:
        controllers_page(args, cases, command, t0)
        return
    out = evaluate(cases, args.methods, args.keyframes, physics=True, simulate=True,
                   simulate_samples=args.samples, workers=args.workers,
                   progress=False)  # fmt: skip
    trials = len({c.clip.source for c in cases})
    sampled = f" --samples {args.samples}" if args.samples else ""
    note = " (the sampling tracker, `sim.simulate.sampling`)" if args.samples else ""
    limited = f", one clip in {args.every} only (--every)" if args.every > 1 else ""
    limited += f", from clip {args.offset} (--offset)" if args.offset else ""
    if args.max_clips:
        limited += f", the first {args.max_clips} clips only (--max-clips)"
    text = (
        f"{len(cases)} clips of 60 frames from {trials} trials ({len(skipped)} skipped); the "
        f"equivalent command: `sidql eval --data {args.cmu} --keyframes "
        f"{' '.join(map(str, args.keyframes))} --methods {' '.join(args.methods)} --physics "
        f"--simulate{sampled}`{note}{limited}. Means over clips (fall time: over the clips that "
        "fell).\n\n" + simulate_markdown(out["results"])
    )
    if args.samples:  # what the sampling costs (the machine's load changes this one)
        text += (
            f"\nWall time {time.perf_counter() - t0:.0f} s for the whole run (loading, fits and "
            f"{len(cases) * (1 + len(args.methods) * len(args.keyframes))} simulations) on "
            f"{args.workers} workers.\n"
        )
    print(text)
    print(f"({time.perf_counter() - t0:.0f} s)")
    if not args.no_write:
        name, title = (
            "simulate",
            "Forward simulation per method: the human-strength body, no assistance",
        )
        if args.samples:
            name, title = "simulate_sampled", title + ", the sampling tracker"
        write_results(name, title, text, command)


if __name__ == "__main__":
    main()
