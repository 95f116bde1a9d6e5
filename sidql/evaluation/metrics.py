"""The figures the report knows: one declarative list, and how the best value of a column is chosen.

:data:`METRICS` declares every figure (key, label, unit, which way is better, description,
per-frame series, table group): the page's tables, the best value per column, the plots and the
legend all come from it, so a new figure in the summaries is one line there. :func:`best_rows`
chooses the best of a column as shown, beyond the figure's noise floor on the clip;
:func:`shown_metrics` says which figures a clip's tables carry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sidql.evaluation.validation import ClipValidation


@dataclass(frozen=True)
class Metric:
    """One figure of the page: a table column, a legend line and (with ``per_frame``) a plot.

    Attributes:
        key: key in the summaries (``MethodRun.summary``/``excess``, ``ClipValidation.baseline``).
        label: column heading; unit: shown beside it (``""`` for counts and ratios).
        better: ``"lower"``, ``"higher"``, ``"zero"`` (closest to 0 is best: an excess over the
            original either way), ``"original"`` (closest to the original's own value is best) or
            ``""`` (not ranked).
        description: one sentence for the legend.
        fmt: Python format of a value; ``excess``: method rows show ``MethodRun.excess[key]``.
        per_frame: key of the :func:`sidql.evaluation.validation.per_frame` array plotted per
            frame, if any.
        resolution: differences below this are ties when choosing the best (e.g. bone drift of
            1e-13 mm is rounding, not a better method); 0: compare as shown.
        group: which table of the clip shows it (:data:`GROUPS`).
    """

    key: str
    label: str
    unit: str
    better: str
    description: str
    fmt: str = "{:.1f}"
    excess: bool = False
    per_frame: str | None = None
    resolution: float = 0.0
    group: str = "accuracy"


#: Every figure the page knows, in column order. Keys absent from a run show ``n/a``; keys absent
#: from every row of a clip are left out of its table and plots (the legend still lists them).
METRICS: tuple[Metric, ...] = (
    Metric("mpjpe_mm", "MPJPE", "mm", "lower",
           "mean distance of the reconstruction's points from the original's", "{:.1f}",
           per_frame="mpjpe_mm"),
    Metric("velocity_error_mm_s", "velocity error", "mm/s", "lower",
           "mean |v - v_original| over points", "{:.0f}", per_frame="velocity_error_mm_s"),
    Metric("bone_drift_max_mm", "bone drift", "mm", "lower",
           "largest change of a bone's length against the original", "{:.2g}",
           resolution=0.01),
    # physics: filled by sim.physics where it runs (foot-floor contact and penetration; the
    # body's touching bones and the fitted humanoid's joint limits; dynamics); the kinematic
    # replay's own floor, skating and joint-limit figures are in checks.json only, so each idea
    # has one column
    Metric("penetration_mm", "penetration", "mm", "lower",
           "mean depth of a foot's lowest sole point below the floor", "{:.1f}", group="floor"),
    Metric("float_mm", "float", "mm", "lower",
           "mean height of a foot's lowest sole point while the original's foot is in contact",
           "{:.1f}", group="floor"),
    Metric("skate_mm_s", "skate (contact)", "mm/s", "lower",
           "mean horizontal speed of a foot's lowest sole point while the original's foot is in "
           "contact", "{:.0f}", group="floor"),
    Metric("contact_precision", "contact precision", "", "higher",
           "share of the reconstruction's contacts that the original also has", "{:.2f}", group="floor"),
    Metric("contact_recall", "contact recall", "", "higher",
           "share of the original's contacts that the reconstruction keeps", "{:.2f}", group="floor"),
    Metric("physdiff_penetrate_mm", "PhysDiff penetrate", "mm", "lower",
           "PhysDiff (Yuan et al. 2023): mean depth of the body surface's lowest point below the "
           "floor", "{:.1f}", group="floor"),
    Metric("physdiff_float_mm", "PhysDiff float", "mm", "lower",
           "PhysDiff: mean height of the body surface's lowest point above the floor, beyond 5 mm",
           "{:.1f}", group="floor"),
    Metric("physdiff_skate", "PhysDiff skate", "", "lower",
           "PhysDiff-style skate: share of frames in which a foot in contact in it and the "
           "previous frame moves more than 2.5 cm horizontally", "{:.2f}", group="floor"),
    Metric("self_pen_excess_mm", "self-pen. excess", "mm", "lower",
           "mean per-pair overlap beyond the original's in the same frame", "{:.1f}", group="body"),
    Metric("lost_contacts", "lost touching bones", "", "lower",
           "touching bone pairs of the original that the reconstruction separates", "{:d}", group="body"),
    Metric("limit_excess_deg", "limit excess", "deg", "lower",
           "worst anatomical hinge angle of the fitted humanoid past its ASF limit", "{:.1f}",
           group="body"),
    Metric("residual_force_bw", "residual force", "BW", "lower",
           "mean external force no ground contact can supply (force alone), in body weights",
           "{:.2f}", group="dynamics"),
    Metric("residual_force_bw_p95", "residual force p95", "BW", "lower",
           "95th percentile of the residual force, in body weights", "{:.2f}", group="dynamics"),
    Metric("residual_torque_nm_kg", "residual torque", "N m/kg", "lower",
           "mean torque about the centre of mass that the ground forces supplying the force "
           "leave, per kg of body mass", "{:.2f}", group="dynamics"),
    Metric("joint_torque_rms_nm_kg", "joint torque RMS", "N m/kg", "original",
           "RMS joint torque per kg from inverse dynamics; closest to the original's is best "
           "(over-smoothed motion needs less than the original, not better)", "{:.2f}",
           group="dynamics"),
    # forward simulation (report --simulate): filled by sim.simulate.validate
    Metric("sim_error_mm", "sim. error", "mm", "lower",
           "mean distance of the simulated body's points from the motion it tracked", "{:.0f}",
           group="simulation"),
    Metric("sim_error_local_mm", "sim. error, root-relative", "mm", "lower",
           "the same with each frame's points relative to the root (the pose, not the path)",
           "{:.0f}", group="simulation"),
    Metric("sim_error_original_mm", "sim. error vs original", "mm", "lower",
           "mean distance of the simulated body's points from the original motion", "{:.0f}",
           group="simulation"),
    Metric("sim_fell", "fell", "", "lower",
           "1 if the simulated body fell (sim.simulate.falls: a part other than the feet on the "
           "floor where the reference has none, or the head below half the reference's)", "{:d}",
           group="simulation"),
    Metric("sim_fall_s", "fall time", "s", "higher",
           "when the simulated body fell (n/a: it did not)", "{:.2f}", group="simulation"),
    Metric("sim_steps", "inferred steps", "", "",
           "static boxes under the feet that stand on something in the original motion "
           "(sim.simulate.terrain), the same scene for every method; 0: the empty floor", "{:d}",
           group="simulation"),
    Metric("sim_torque_rms_nm_kg", "sim. joint torque RMS", "N m/kg", "lower",
           "RMS joint torque the simulated body applied, per kg", "{:.2f}", group="simulation"),
    Metric("sim_torque_saturated", "torque at limit", "", "lower",
           "share of joint-torque samples at the joint's human limit", "{:.3f}",
           group="simulation"),
)  # fmt: skip

#: The clip's tables, in order: (group, heading).
GROUPS = (
    ("accuracy", "Accuracy and geometry"),
    (
        "floor",
        "Feet on the floor: foot-floor contact and penetration (sim.physics; against the "
        "original's contacts)",
    ),
    (
        "body",
        "The body itself: touching bones and joint limits (sim.physics, on the fitted humanoid)",
    ),
    (
        "dynamics",
        "Dynamics: forces the motion needs (sim.physics; inverse dynamics on the fitted humanoid)",
    ),
    (
        "simulation",
        "Forward simulation: could a body perform it? The human-strength body tracks each fitted "
        "motion in mj_step with no assistance (sim.simulate)",
    ),
)

#: Which way is better (:attr:`Metric.better`), in words and as the arrow a column heading shows.
BETTER_TEXT = {"lower": "lower is better", "higher": "higher is better",
               "zero": "closest to 0 (the original) is best",
               "original": "closest to the original's value is best", "": "not ranked"}  # fmt: skip
ARROW = {"lower": "\u2193", "higher": "\u2191", "zero": "\u21950", "original": "\u2248o", "": ""}


def _number(value):
    """A finite float, or ``None`` (absent, ``None`` or NaN)."""
    if value is None:
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(x) else x


def metric_value(m: Metric, summary: dict, excess: dict | None = None):
    """The value a table cell shows: ``excess[key]`` for an excess metric of a method row (when
    present), else ``summary[key]``; ``None`` when absent or NaN."""
    if m.excess and excess is not None and m.key in excess:
        return _number(excess[m.key])
    return _number(summary.get(m.key))


def format_value(fmt: str, value) -> str:
    """``value`` as a cell shows it by the metric's format ``fmt`` (``n/a`` when absent)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if "d}" in fmt:
        value = int(round(value))
    return fmt.format(value)


def best_rows(m: Metric, values, *, original=None, noise: float = 0.0) -> set[int]:
    """Indices of the best of ``values`` (``None`` skipped) by ``m.better``, compared as shown
    (formatted); empty when not ranked, fewer than two values, or all show the same.

    ``original``: the original's value (``better == "original"`` scores ``|v - original|``).
    ``noise``: the figure's noise floor (how far capture noise alone moves it): values within it
    of the best tie with it, and none is marked unless some value is worse than the best by more
    than the noise floor (a noise-level difference is no difference)."""
    shown = [(i, v) for i, v in enumerate(values) if v is not None]
    if not m.better or len(shown) < 2 or (m.better == "original" and original is None):
        return set()
    score = {
        "lower": lambda v: v, "higher": lambda v: -v, "zero": abs,
        "original": lambda v: abs(v - original),
    }[m.better]  # fmt: skip
    if m.resolution > 0:
        text = {i: str(round(score(v) / m.resolution)) for i, v in shown}
    else:
        text = {i: format_value(m.fmt.replace("+", ""), abs(score(v))) for i, v in shown}
    if len(set(text.values())) == 1:
        return set()
    top = min(score(v) for _, v in shown)
    if noise > 0:
        if max(score(v) for _, v in shown) - top <= noise:
            return set()
        return {i for i, v in shown if score(v) - top <= noise}
    best = next(text[i] for i, v in shown if score(v) == top)
    return {i for i, _ in shown if text[i] == best}


def best_in_clip(v: ClipValidation, m: Metric, values) -> set[int]:
    """:func:`best_rows` of one clip's column, against the original's value and beyond the
    figure's noise floor on that clip."""
    return best_rows(
        m, values, original=metric_value(m, v.baseline_figures),
        noise=v.noise_floor.get(m.key, 0.0) if not m.excess else 0.0,
    )  # fmt: skip


def shown_metrics(v: ClipValidation) -> list[Metric]:
    """The metrics with a value in at least one row of the clip."""
    rows = [(v.baseline_figures, None)] + [(r.figures, r.excess) for r in v.runs]
    return [m for m in METRICS if any(metric_value(m, s, e) is not None for s, e in rows)]
