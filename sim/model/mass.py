"""Segment masses of the humanoid from an anthropometric table (de Leva 1996).

de Leva, P. (1996). Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters.
J. Biomechanics 29(9), 1223-1230, Table 4: segment mass as a percentage of total body mass.

CMU's ASF bones are finer than de Leva's segments, so each segment's mass is shared among the
bones that make it up in proportion to their capsule volumes (``sim.model.humanoid``'s geometry);
the pelvis sphere at the root belongs to the lower trunk. Bones of a skeleton that are not CMU's
get the mass their capsule volume implies at a uniform body density, scaled so that the total is
the requested body mass. Masses in kilograms; the total body mass is a parameter (default 75 kg).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from sim.errors import UnknownNameError, UsageError

DEFAULT_BODY_MASS_KG = 75.0

# de Leva (1996), Table 4: segment mass [% of body mass]; limb segments are per side.
SEGMENT_MASS_PERCENT: dict[str, dict[str, float]] = {
    "male": {
        "head": 6.94, "upper_trunk": 15.96, "middle_trunk": 16.33, "lower_trunk": 11.17,
        "upper_arm": 2.71, "forearm": 1.62, "hand": 0.61,
        "thigh": 14.16, "shank": 4.33, "foot": 1.37,
    },
    "female": {
        "head": 6.68, "upper_trunk": 15.45, "middle_trunk": 14.65, "lower_trunk": 12.47,
        "upper_arm": 2.55, "forearm": 1.38, "hand": 0.56,
        "thigh": 14.78, "shank": 4.81, "foot": 1.29,
    },
}  # fmt: skip

# Which de Leva segment each CMU bone (and the root's pelvis geom) belongs to.
CMU_SEGMENT: dict[str, str] = {
    "root": "lower_trunk", "lhipjoint": "lower_trunk", "rhipjoint": "lower_trunk",
    "lowerback": "lower_trunk", "upperback": "middle_trunk",
    "thorax": "upper_trunk", "lclavicle": "upper_trunk", "rclavicle": "upper_trunk",
    "lowerneck": "head", "upperneck": "head", "head": "head",
    "lhumerus": "l_upper_arm", "rhumerus": "r_upper_arm",
    "lradius": "l_forearm", "rradius": "r_forearm",
    "lwrist": "l_hand", "lhand": "l_hand", "lfingers": "l_hand", "lthumb": "l_hand",
    "rwrist": "r_hand", "rhand": "r_hand", "rfingers": "r_hand", "rthumb": "r_hand",
    "lfemur": "l_thigh", "rfemur": "r_thigh", "ltibia": "l_shank", "rtibia": "r_shank",
    "lfoot": "l_foot", "ltoes": "l_foot", "rfoot": "r_foot", "rtoes": "r_foot",
}  # fmt: skip


def segment_fractions(sex: str = "male") -> dict[str, float]:
    """Mass fraction of every segment, one per side for limbs (``l_thigh``, ...); sums to 1."""
    if sex not in SEGMENT_MASS_PERCENT:
        raise UnknownNameError("sex", sex, SEGMENT_MASS_PERCENT)
    out = {}
    for seg, pct in SEGMENT_MASS_PERCENT[sex].items():
        if seg in ("head", "upper_trunk", "middle_trunk", "lower_trunk"):
            out[seg] = pct / 100.0
        else:
            out[f"l_{seg}"] = out[f"r_{seg}"] = pct / 100.0
    total = sum(out.values())
    return {k: v / total for k, v in out.items()}  # the table's rounding sums to 100 +- 0.01


def capsule_volume(radius: float, length: float) -> float:
    """Volume [m^3] of a capsule of ``radius`` [m] and cylinder ``length`` [m] (sphere if 0)."""
    return math.pi * radius**2 * max(length, 0.0) + 4.0 / 3.0 * math.pi * radius**3


def body_masses(
    volumes: Mapping[str, float], total_kg: float = DEFAULT_BODY_MASS_KG, sex: str = "male"
) -> dict[str, float]:
    """Mass [kg] of every body from its geom volume [m^3].

    Args:
        volumes: body name -> geom volume (``"root"`` for the pelvis); CMU bone names are
            mapped to de Leva segments, others share the remaining mass by volume.
        total_kg: total body mass [kg].
        sex: ``"male"`` or ``"female"`` column of the table.

    Returns:
        body name -> mass [kg]; the masses sum to ``total_kg``.
    """
    if not (math.isfinite(total_kg) and total_kg > 0):
        raise UsageError(f"total body mass must be positive and finite, got {total_kg!r}")
    fractions = segment_fractions(sex)
    segment_of = {b: CMU_SEGMENT[b] for b in volumes if b in CMU_SEGMENT}
    present = set(segment_of.values())
    if present != set(fractions):
        # Not a (complete) CMU skeleton: uniform density, which keeps relative sizes honest.
        vol = sum(volumes.values())
        return {b: total_kg * v / vol for b, v in volumes.items()}
    seg_volume: dict[str, float] = {}
    for b, seg in segment_of.items():
        seg_volume[seg] = seg_volume.get(seg, 0.0) + volumes[b]
    out = {
        b: total_kg * fractions[seg] * volumes[b] / seg_volume[seg] for b, seg in segment_of.items()
    }
    # Bones beyond CMU's set (none in CMU files) get a share at the table-weighted density.
    extra = {b: v for b, v in volumes.items() if b not in segment_of}
    if extra:
        density = total_kg / sum(volumes[b] for b in segment_of)
        out.update({b: density * v for b, v in extra.items()})
        scale = total_kg / sum(out.values())
        out = {b: m * scale for b, m in out.items()}
    return out
