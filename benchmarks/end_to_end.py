"""The decision time a caller of ``select`` waits for (chart, segment costs and decision, one
clip at a time), beside its parts and beside the path it replaced, all timed in the same run
(shared by bench_dqn.py and bench_keyframes.py).

Every figure is the median over clips and repeats of single calls made back to back: hot
(``eval`` times one call per clip after scoring the last, a few per cent slower; the figure as
eval measures it is :mod:`decision_sides`'s), in CPU time of this process (``time.process_time``: what other
processes on a loaded machine take is not counted, though their sharing of the caches and of
the core's other hyperthread still is) and in wall time. The columns of one clip are timed
one after the other before the next clip, so a change of load hits every column alike; a
ratio between columns of one run is the figure to trust on a busy machine.
"""

from __future__ import annotations

import time

import numpy as np


def _timed(fn) -> tuple[float, float]:
    """(CPU ms, wall ms) of one call of ``fn()``."""
    c, w = time.process_time(), time.perf_counter()
    fn()
    return 1e3 * (time.process_time() - c), 1e3 * (time.perf_counter() - w)


def columns(clip, W: int, policy, with_dqn: bool) -> dict:
    """name -> zero-argument callable for one clip: the end-to-end paths, the paths they
    replaced and their parts."""
    from sidql.keyframes import methods
    from sidql.keyframes.optimal import (
        _banded_costs,
        clip_optimal_keyframes,
        clip_optimal_table,
        optimum_cost_matrix,
        solve,
    )
    from sidql.keyframes.segment_costs import (
        clip_stacked,
        clip_stacked_costs,
        segment_cost_matrix,
    )
    from sidql.keyframes.single_costs import single_costs
    from sidql.keyframes.spherical import chart
    from sidql.learning.tasks import clip_features, stacked_features

    cols = {
        "optimal: select (end to end)": lambda: methods.select("optimal", clip, W),
        "optimal: clip_optimal_keyframes (what select runs)": lambda: clip_optimal_keyframes(
            clip, W
        ),
        "optimal before: chart + costs it can use, then programme and walk back in Python": lambda: (
            solve(optimum_cost_matrix(clip, W), 22, W).keyframes(W)
        ),
        "optimal before: chart + full costs + programme": lambda: clip_optimal_table(
            clip, w_max=W
        ).keyframes(W),
        "  optimal part: chart + costs it can use": lambda: optimum_cost_matrix(clip, W),
        "  optimal part before: chart + the band's costs (the route before the screen, W <= 9)": (
            lambda: _banded_costs(*clip_stacked(clip), False, W)
        ),
    }
    C = optimum_cost_matrix(clip, W)
    cols["  optimal part: programme"] = lambda: solve(C, 22, W).keyframes(W)
    if not with_dqn:
        return cols

    def before():
        s = chart(clip)
        feats, cost = clip_features(s), segment_cost_matrix(s)
        return policy.decide(feats[None], cost[None], W)

    from sidql.learning.decide import decide_clip, encode_clip

    X, R, cost = clip_stacked_costs(clip)
    feats = stacked_features(X, R)
    enc_w, head_w = policy._weights()
    enc = encode_clip(feats.astype(np.float32), *enc_w)
    cost32 = cost.astype(np.float32).astype(np.float64)  # as Policy.decide passes them
    cols.update(
        {
            "dqn: select (end to end)": lambda: methods.select("dqn", clip, W),
            "dqn: Policy.select": lambda: policy.select(clip, W),
            "dqn before: Policy.select as it was (chart, features, costs, decide)": before,
            "  dqn part: chart": lambda: clip_stacked(clip),
            "  dqn part: segment costs, single precision (what select uses)": lambda: single_costs(
                X, R
            ),
            "  dqn part: chart + float64 costs (one pass, what select used)": lambda: (
                clip_stacked_costs(clip)
            ),
            "  dqn part: features": lambda: stacked_features(X, R),
            "  dqn part: decide (encoder + head)": lambda: policy.decide(
                feats[None], cost[None], W
            ),
            "    dqn part of decide: encoder": lambda: encode_clip(
                feats.astype(np.float32), *enc_w
            ),
            "    dqn part of decide: head, W - 2 steps with the rollout prior": lambda: decide_clip(
                *enc, cost32, W, policy.uses_prior, *head_w
            ),
        }
    )
    return cols


def end_to_end_table(clips, counts, repeats: int = 5, with_dqn: bool = True,
                     baseline=None) -> str:  # fmt: skip
    """Markdown table: per W and column, median CPU and wall ms per clip, and the
    before / after ratios of the same run; with ``baseline`` (a :class:`baseline.Baseline`)
    also its ``select`` per method, on each clip right after this process's columns of it."""
    policy = None
    if with_dqn:
        from sidql.learning.policy import load_policy

        policy = load_policy()
    lines = [
        "| W | path | CPU ms per clip | wall ms per clip |",
        "|---|---|---|---|",
    ]
    notes = []
    for W in counts:
        for fn in columns(clips[0], W, policy, with_dqn).values():
            fn()  # compile and warm up
        got: dict[str, list] = {}
        base_methods = () if baseline is None else ("optimal", "dqn")[: 2 if with_dqn else 1]
        for index, clip in enumerate(clips):
            for name, fn in columns(clip, W, policy, with_dqn).items():
                got.setdefault(name, []).extend(_timed(fn) for _ in range(repeats))
            for m in base_methods:
                got.setdefault(f"{m} baseline: select (end to end) at {baseline.short}", []).extend(
                    baseline.times_ms(m, W, index, repeats)
                )
        med = {k: np.median(np.array(v), axis=0) for k, v in got.items()}
        for name, (cpu, wall) in med.items():
            lines.append(f"| {W} | {name} | {cpu:.3f} | {wall:.3f} |")
        for m, aim in (("optimal", 0.7), ("dqn", 1.0)):
            after = f"{m}: select (end to end)"
            if after not in med:
                continue
            same = {
                "dqn": "dqn: Policy.select",
                "optimal": "optimal: clip_optimal_keyframes (what select runs)",
            }[m]  # what 'before' replaced
            ratios = "; ".join(
                f"{k[len(m) + 9 :]}: {med[k][0] / med[same][0]:.2f}x CPU, "
                f"{med[k][1] / med[same][1]:.2f}x wall"
                for k in med
                if k.startswith(f"{m} before")
            )
            verdict = "met" if med[after][0] <= aim else "UNMET"
            base = next((k for k in med if k.startswith(f"{m} baseline")), None)
            against = (
                f"; after / baseline {med[after][0] / med[base][0]:.2f}x CPU, "
                f"{med[after][1] / med[base][1]:.2f}x wall (baseline {med[base][0]:.3f} ms CPU)"
                if base
                else ""
            )
            notes.append(
                f"W = {W}, {m}: end to end {med[after][0]:.3f} ms CPU per clip (aim: at most "
                f"{aim} ms, quiet: {verdict}){against}; before / after in this run ({ratios})."
            )
    return "\n".join(lines + [""] + notes)


def interleaving_table(clips, counts, n_rounds: int = 4, repeats: int = 5) -> str:
    """Markdown: ``select``'s end-to-end CPU ms (median over clips of the median of ``repeats``
    calls back to back) timed two ways in this process, round after round: *interleaved* as
    :func:`end_to_end_table` times it (every column of a clip, then the next clip) and *in
    blocks* (one method and W over all clips, nothing in between); per round both, and their
    ratio, so a difference between the two ways shows apart from the machine's drift."""
    from sidql.keyframes import methods
    from sidql.learning.policy import load_policy

    policy = load_policy()
    names = {"optimal": "optimal: select (end to end)", "dqn": "dqn: select (end to end)"}
    per_round = []
    for r in range(n_rounds):
        got = {}
        for W in counts:
            for fn in columns(clips[0], W, policy, True).values():
                fn()  # compile and warm up
            ways = ("interleaved", "blocks") if r % 2 == 0 else ("blocks", "interleaved")
            for way in ways:
                for m in names:
                    got[(way, m, W)] = []
                if way == "blocks":
                    for m in names:
                        for clip in clips:
                            got[(way, m, W)].append(np.median(
                                [_timed(lambda c=clip, m=m, W=W: methods.select(m, c, W))[0]
                                 for _ in range(repeats)]))  # fmt: skip
                    continue
                for clip in clips:
                    for name, fn in columns(clip, W, policy, True).items():
                        t = np.median([_timed(fn)[0] for _ in range(repeats)])
                        for m, want in names.items():
                            if name == want:
                                got[(way, m, W)].append(t)
        per_round.append({k: float(np.median(v)) for k, v in got.items()})
    lines = [
        "| round | W | method | interleaved CPU ms | in blocks CPU ms | interleaved / blocks |",
        "|---|---|---|---|---|---|",
    ]
    for r, got in enumerate(per_round, 1):
        for W in counts:
            for m in names:
                a, b = got[("interleaved", m, W)], got[("blocks", m, W)]
                lines.append(f"| {r} | {W} | {m} | {a:.3f} | {b:.3f} | {a / b:.2f}x |")
    notes = []
    for W in counts:
        for m in names:
            ratio = [g[("interleaved", m, W)] / g[("blocks", m, W)] for g in per_round]
            blocks = [g[("blocks", m, W)] for g in per_round]
            notes.append(
                f"W = {W}, {m}: interleaved / blocks {np.median(ratio):.2f}x, median over "
                f"rounds [{min(ratio):.2f}, {max(ratio):.2f}]; in blocks, slowest round / fastest "
                f"round {max(blocks) / min(blocks):.2f}x."
            )
    return "\n".join(lines + [""] + notes)
