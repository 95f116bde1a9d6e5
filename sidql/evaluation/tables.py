"""The Markdown tables of an evaluation (:func:`sidql.evaluation.evaluate.evaluate`'s output):
Table 3 beside the paper's, the physics means or medians, the forward simulation, the trials'
floors."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from sidql.evaluation.scoring import NOISE_FLOOR

#: The paper's Table 3 (mean Q at W = 5, 10, 15); "SIDQL" is its DQN.
PAPER_TABLE3: dict[str, dict[int, float]] = {
    "RC": {5: 0.1437, 10: 0.0833, 15: 0.0549},
    "UC": {5: 0.0945, 10: 0.0490, 15: 0.0328},
    "Greedy": {5: 0.0536, 10: 0.0311, 15: 0.0200},
    "SIDQL": {5: 0.0844, 10: 0.0443, 15: 0.0297},
}

#: Our method name -> the paper's row.
PAPER_NAMES = {"random": "RC", "uniform": "UC", "greedy": "Greedy", "dqn": "SIDQL"}


def table3_markdown(results: Sequence[dict]) -> str:
    """Markdown table of mean Q per method (rows) and W (columns), the paper's figure beside ours
    where it has one, then the chart-free errors."""
    results = [r for r in results if r["method"] not in ("original", NOISE_FLOOR)]
    counts = sorted({r["keyframes"] for r in results})
    names = list(dict.fromkeys(r["method"] for r in results))
    by = {(r["method"], r["keyframes"]): r for r in results}
    head = "| method | " + " | ".join(f"Q, W={W} (paper)" for W in counts) + " |"
    lines = [head, "|---|" + "---|" * len(counts)]
    for name in names:
        paper = PAPER_TABLE3.get(PAPER_NAMES.get(name, ""), {})
        cells = []
        for W in counts:
            r = by.get((name, W))
            ours = f"{r['mean_q']:.4f}" if r else "-"
            cells.append(f"{ours} ({paper[W]:.4f})" if W in paper else ours)
        label = f"{name} ({PAPER_NAMES[name]})" if name in PAPER_NAMES else name
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(
        "| method | W | clips | Q | Q of its keyframes, Hermite | geodesic (deg) | MPJPE (mm) "
        "| velocity error (mm/s) | Li error (mm) | median decision (ms) |"
    )
    lines.append("|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        lines.append(
            f"| {r['method']} | {r['keyframes']} | {r['clips']} | {r['mean_q']:.4f} "
            f"| {r['mean_q_hermite']:.4f} | {r['mean_geodesic_deg']:.2f} | {r['mpjpe_mm']:.1f} "
            f"| {r['velocity_error_mm_s']:.0f} | {r['mean_li_error_mm']:.1f} "
            f"| {r['median_decision_ms']:.2f} |"
        )
    return "\n".join(lines)


def physics_markdown(results: Sequence[dict], stat: str = "mean") -> str:
    """Markdown table of the :mod:`sim.physics` means (``stat="median"``: medians) over clips per
    method and W: ``original`` first, then the ``noise floor`` (per figure, how far the original
    re-captured with marker noise departs from it), then the methods. ``|JT - orig|``: the joint
    torque RMS's distance from the original's (over-smoothed motion needs less than the
    original, not better); PhysDiff columns are Yuan et al.'s definitions."""
    rows = [r for r in results if "residual_force_bw" in r]
    rows.sort(key=lambda r: (r["method"] != "original", r["method"] != NOISE_FLOOR))
    cols = (
        ("Q", "mean_q", ".4f"), ("pen. (mm)", "penetration_mm", ".1f"),
        ("float (mm)", "float_mm", ".1f"), ("skate (mm/s)", "skate_mm_s", ".0f"),
        ("contact P", "contact_precision", ".2f"), ("contact R", "contact_recall", ".2f"),
        ("PhysDiff penetrate (mm)", "physdiff_penetrate_mm", ".1f"),
        ("PhysDiff float (mm)", "physdiff_float_mm", ".1f"),
        ("PhysDiff skate", "physdiff_skate", ".3f"),
        ("self-pen. excess (mm)", "self_pen_excess_mm", ".2f"),
        ("lost touching bones", "lost_contacts", ".1f"),
        ("limit excess (deg)", "limit_excess_deg", ".2f"),
        ("residual force (BW)", "residual_force_bw", ".3f"),
        ("residual force p95 (BW)", "residual_force_bw_p95", ".2f"),
        ("residual torque (N m/kg)", "residual_torque_nm_kg", ".3f"),
        ("joint torque RMS (N m/kg)", "joint_torque_rms_nm_kg", ".3f"),
        ("\\|JT - orig\\| (N m/kg)", "joint_torque_rms_nm_kg_distance", ".3f"),
    )  # fmt: skip
    lines = [
        "| method | W | clips | " + " | ".join(c[0] for c in cols) + " |",
        "|---|---|---|" + "---|" * len(cols),
    ]
    for r in rows:
        vals = [
            r.get(k) if stat == "mean" or k == "mean_q" else r.get(f"{k}_median")
            for _, k, f in cols
        ]
        cells = [
            "-" if v is None else format(v, f) for v, (_, _, f) in zip(vals, cols, strict=True)
        ]
        lines.append(
            f"| {r['method']} | {r['keyframes']} | {r['clips']} | " + " | ".join(cells) + " |"
        )
    return "\n".join(lines)


def simulate_markdown(results: Sequence[dict]) -> str:
    """Markdown table of the forward-simulation means per method and W (``original`` first): the
    torque-limited body tracking each motion's IK fit with no assistance."""
    rows = [r for r in results if r.get("sim_error_mm") is not None]
    rows.sort(key=lambda r: r["method"] != "original")
    lines = [
        "| method | W | clips | error vs tracked (mm), mean / median | root-relative (mm), mean "
        "/ median | error vs original (mm) | fell (share) | fall time (s) | joint torque RMS "
        "(N m/kg) | torque at limit (share) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        fall = "-" if r["sim_fall_s"] is None else f"{r['sim_fall_s']:.2f}"
        local = r.get("sim_error_local_mm")
        local = "-" if local is None else f"{local:.1f} / {r['sim_error_local_mm_median']:.1f}"
        median = r.get("sim_error_mm_median")
        median = "" if median is None else f" / {median:.1f}"
        lines.append(
            f"| {r['method']} | {r['keyframes']} | {r['clips']} | {r['sim_error_mm']:.1f}{median} "
            f"| {local} | {r['sim_error_original_mm']:.1f} | {r['sim_fell']:.2f} | {fall} "
            f"| {r['sim_torque_rms_nm_kg']:.3f} | {r['sim_torque_saturated']:.3f} |"
        )
    return "\n".join(lines)


def floors_markdown(floors: Sequence[dict]) -> str:
    """The trials whose floor does not fit, with how far their planted feet depart from it (their
    float and penetration are not scored), the trials whose support is off the floor and why,
    and the original's residual force over the trials where floor and support are found."""
    bad = [f for f in floors if not f["floor_fits"]]
    if not bad:
        lines = [f"The floor fits every one of the {len(floors)} trials."]
    else:
        lines = [
            f"Floor does not fit {len(bad)} of {len(floors)} trials (float and penetration not "
            "scored there):",
            "",
            "| trial | deviation (mm) | spread (mm) | drift (mm) | below (mm) | footprints |",
            "|---|---|---|---|---|---|",
        ]
        keys = ("floor_deviation_mm", "floor_spread_mm", "floor_drift_mm", "floor_below_mm")
        for f in bad:
            cells = " | ".join("-" if f[k] is None else f"{f[k]:.1f}" for k in keys)
            lines.append(f"| {Path(f['source']).stem} | {cells} | {f['floor_footprints']} |")
    off = [f for f in floors if f.get("support_off_floor")]
    if off:
        lines += ["", f"Support off the floor in {len(off)} of {len(floors)} trials:", "",
                  "| trial | original's residual force (BW) | why |", "|---|---|---|"]  # fmt: skip
        for f in off:
            lines.append(
                f"| {Path(f['source']).stem} | {f['original_residual_force_bw']:.3f} "
                f"| {f['support_why']} |"
            )
    parts = {Path(f["source"]).stem: f["ground_parts"] for f in floors if f.get("ground_parts")}
    if parts:
        lines += ["", "Body points other than the feet on the floor (share of the original's "
                  "frames): " + "; ".join(
                      f"{t}: " + ", ".join(f"{p} {100 * x:.1f} %" for p, x in ps.items())
                      for t, ps in parts.items())]  # fmt: skip
    return "\n".join(lines)
