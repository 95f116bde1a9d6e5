"""When is one method better than another? Paired bootstrap confidence intervals over clips.

Two methods scored on the same clips differ clip by clip; the mean of those paired differences
has a sampling error that a table of means hides. :func:`paired_comparisons` resamples the clips
with replacement (the same resample for every pair, seeded) and takes the 2.5th and 97.5th
percentiles of the mean difference: a method is *better* than another on a figure only when that
95 % interval excludes zero, in the figure's better direction; otherwise the two are not told
apart.

Figures that measure closeness to the original (a reconstruction should need the original's
joint torques, not less: over-smoothed motion needs less) are compared as their distance from
the original's value on the same clip (``<key>_distance``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: Figures compared, and which way is better.
COMPARED: dict[str, str] = {
    "q": "lower",
    "mpjpe_mm": "lower",
    "residual_force_bw": "lower",
    "residual_torque_nm_kg": "lower",
    "joint_torque_rms_nm_kg_distance": "lower",
    "penetration_mm": "lower",
    "float_mm": "lower",
    "skate_mm_s": "lower",
    "contact_recall": "higher",
    "physdiff_skate": "lower",
    "self_pen_excess_mm": "lower",
    "lost_contacts": "lower",
    "limit_excess_deg": "lower",
}

#: Figures whose closeness to the original's is what counts: scored as ``|value - original|``.
CLOSENESS = ("joint_torque_rms_nm_kg",)


def bootstrap_mean_ci(
    diffs: np.ndarray, *, resamples: int = 2000, level: float = 0.95, seed: int = 0
) -> tuple[float, float, float]:
    """Mean of ``diffs`` (n,) and its percentile bootstrap interval (``level``, seeded)."""
    d = np.asarray(diffs, dtype=np.float64)
    if d.size == 0:
        return float("nan"), float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, d.size, (resamples, d.size))
    means = d[idx].mean(axis=1)
    a = (1 - level) / 2
    return float(d.mean()), float(np.quantile(means, a)), float(np.quantile(means, 1 - a))


def paired_comparisons(
    rows: Sequence[dict],
    methods: Sequence[str],
    *,
    keys: dict[str, str] | None = None,
    resamples: int = 2000,
    seed: int = 0,
) -> list[dict]:
    """Every pair of ``methods`` at every W on every figure of ``keys`` (default
    :data:`COMPARED`), paired over the clips both have a value for.

    Args:
        rows: per-clip rows (``source``, ``start_frame``, ``method``, ``keyframes`` and figures).
    Returns:
        Rows ``{"keyframes", "metric", "a", "b", "clips", "mean_diff" (a - b), "ci_low",
        "ci_high", "better"}`` with ``better`` the better method's name when the interval
        excludes zero, else None.
    """
    keys = COMPARED if keys is None else keys
    by = {}
    for r in rows:
        by[(r["method"], r["keyframes"], r["source"], r["start_frame"])] = r
    counts = sorted({r["keyframes"] for r in rows if r["method"] in methods})
    out = []
    for W in counts:
        for key, better in keys.items():
            for i, a in enumerate(methods):
                for b in methods[i + 1 :]:
                    d = []
                    for (m, w, src, st), ra in by.items():
                        if m != a or w != W:
                            continue
                        rb = by.get((b, W, src, st))
                        if rb is None:
                            continue
                        va, vb = ra.get(key), rb.get(key)
                        if va is None or vb is None or not np.isfinite(va) or not np.isfinite(vb):
                            continue
                        d.append(float(va) - float(vb))
                    if not d:
                        continue
                    mean, lo, hi = bootstrap_mean_ci(np.array(d), resamples=resamples, seed=seed)
                    winner = None
                    if lo > 0 or hi < 0:
                        a_higher = lo > 0
                        winner = a if a_higher == (better == "higher") else b
                    out.append({
                        "keyframes": W, "metric": key, "a": a, "b": b, "clips": len(d),
                        "mean_diff": mean, "ci_low": lo, "ci_high": hi, "better": winner,
                    })  # fmt: skip
    return out


def comparisons_markdown(comparisons: Sequence[dict]) -> str:
    """Markdown: per W, one row per pair of methods, one column per figure: the better method
    (when the 95 % interval of the paired mean difference excludes zero) or ``=``, with the mean
    difference ``a - b`` and its interval."""
    if not comparisons:
        return ""
    metrics = list(dict.fromkeys(c["metric"] for c in comparisons))
    lines = []
    for W in sorted({c["keyframes"] for c in comparisons}):
        rows = [c for c in comparisons if c["keyframes"] == W]
        pairs = list(dict.fromkeys((c["a"], c["b"]) for c in rows))
        cell = {(c["a"], c["b"], c["metric"]): c for c in rows}
        lines.append(f"W = {W} (a vs b: the better one where the 95 % CI of mean(a - b) over "
                     "clips excludes 0, else =; then mean(a - b) [CI])")  # fmt: skip
        lines.append("")
        lines.append("| a vs b | " + " | ".join(metrics) + " |")
        lines.append("|---|" + "---|" * len(metrics))
        for a, b in pairs:
            cells = []
            for m in metrics:
                c = cell.get((a, b, m))
                if c is None:
                    cells.append("-")
                    continue
                word = c["better"] or "="
                cells.append(
                    f"**{word}** {c['mean_diff']:+.3g} [{c['ci_low']:+.3g}, {c['ci_high']:+.3g}]"
                    if c["better"]
                    else f"= {c['mean_diff']:+.3g} [{c['ci_low']:+.3g}, {c['ci_high']:+.3g}]"
                )
            lines.append(f"| {a} vs {b} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


#: The forward simulation's figures a method is compared on with the original (higher: worse).
SIMULATE_COMPARED = ("sim_fell", "sim_error_mm", "sim_error_local_mm")


def paired_bootstrap(
    a: np.ndarray, b: np.ndarray, *, resamples: int = 10000, level: float = 0.95, seed: int = 0
) -> dict:
    """Whether ``a`` (n,) exceeds ``b`` (n,) paired sample by sample: a bootstrap over the n
    pairs of the mean difference ``d = a - b``.

    Returns:
        ``{"n", "mean_diff", "ci_low", "ci_high", "p_value", "more"}``: the mean of ``d``, its
        percentile bootstrap interval at ``level`` (``resamples`` resamples of the pairs with
        replacement, seeded), the one-sided p-value of "``a`` is not larger on average" (the
        share of resampled means of ``d`` centred on 0 that reach the observed mean, ``(count +
        1) / (resamples + 1)``, so never 0), and ``more``: the interval lies above 0. With no
        pairs every figure is nan and ``more`` False; with identical samples ``d`` is 0, the
        interval [0, 0] and the p-value 1.
    """
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"paired samples need equal 1-D shapes; got {a.shape} and {b.shape}")
    d = a - b
    nan = float("nan")
    if d.size == 0:
        return {"n": 0, "mean_diff": nan, "ci_low": nan, "ci_high": nan, "p_value": nan,
                "more": False}  # fmt: skip
    rng = np.random.default_rng(seed)
    means = d[rng.integers(0, d.size, (resamples, d.size))].mean(axis=1)
    observed = float(d.mean())
    tail = (1 - level) / 2
    lo, hi = (float(x) for x in np.quantile(means, [tail, 1 - tail]))
    # null: the same spread around 0; ties count against significance
    count = int(np.count_nonzero(means - observed >= observed - 1e-12 * max(1.0, abs(observed))))
    return {"n": int(d.size), "mean_diff": observed, "ci_low": lo, "ci_high": hi,
            "p_value": (count + 1) / (resamples + 1), "more": bool(lo > 0)}  # fmt: skip


def versus_original(
    per_clip: Sequence[dict],
    methods: Sequence[str],
    *,
    keys: Sequence[str] = SIMULATE_COMPARED,
    resamples: int = 10000,
    seed: int = 0,
) -> list[dict]:
    """Per method, W and figure of ``keys``: :func:`paired_bootstrap` of the method's value
    against the original's on the same clip (``source``, ``start_frame``), over the clips where
    both are finite.

    Returns:
        Rows ``{"method", "keyframes", "metric", "clips", "original", "value" (the two means),
        "mean_diff", "ci_low", "ci_high", "p_value", "more"}`` (``more``: the method's value is
        higher than the original's, the interval of the mean difference above 0).
    """
    original = {(r["source"], r["start_frame"]): r for r in per_clip if r["method"] == "original"}
    out = []
    for m in methods:
        rows = [r for r in per_clip if r["method"] == m]
        for W in sorted({r["keyframes"] for r in rows}):
            for key in keys:
                pairs = []
                for r in rows:
                    o = original.get((r["source"], r["start_frame"]))
                    if r["keyframes"] != W or o is None:
                        continue
                    va, vb = r.get(key), o.get(key)
                    if va is not None and vb is not None and np.isfinite([va, vb]).all():
                        pairs.append((float(va), float(vb)))
                if not pairs:
                    continue
                a, b = np.array(pairs).T
                test = paired_bootstrap(a, b, resamples=resamples, seed=seed)
                out.append({"method": m, "keyframes": W, "metric": key, "clips": test.pop("n"),
                            "original": float(b.mean()), "value": float(a.mean()), **test})  # fmt: skip
    return out


def versus_original_markdown(rows: Sequence[dict]) -> str:
    """Markdown: per method and W, each figure's mean against the original's, the paired mean
    difference with its 95 % interval and one-sided p-value, and the verdict."""
    if not rows:
        return ""
    lines = [
        "| method | W | clips | figure | method | original | mean difference [95 % CI] | p "
        "(one-sided) | more than the original? |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['method']} | {r['keyframes']} | {r['clips']} | {r['metric']} "
            f"| {r['value']:.3g} | {r['original']:.3g} | {r['mean_diff']:+.3g} "
            f"[{r['ci_low']:+.3g}, {r['ci_high']:+.3g}] | {r['p_value']:.4f} "
            f"| {'**yes**' if r['more'] else 'no'} |"
        )
    return "\n".join(lines)
