"""The trials' floors in an evaluation: per trial its floor's fit and where its original's support
was found (:func:`floor_report`), read from the original's rows.

Units: millimetres, body weights (BW), shares of frames.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim.physics.support import support_verdict


def floor_report(setup: dict, originals: Sequence[dict] = ()) -> list[dict]:
    """Per trial its floor (:meth:`sim.physics.ground.Ground.summary`) and whether it fits, and,
    from its original's rows, where its support was found: the original's mean residual force
    (``original_residual_force_bw``), the body points other than feet on the floor
    (``ground_parts``: share of frames), the share of frames whose support was found nowhere
    (``support_missing_share``), the share held by something else (``support_held_share``),
    the frames whose derivatives are not measured (``dynamics_unmeasured_n``, summed over the
    clips) and the verdict (``support_off_floor``, ``support_why``:
    :func:`sim.physics.support.support_verdict`)."""
    out = []
    for src, tp in setup.items():
        row = {"source": src, **tp.ground.summary()}
        rows = [r for r in originals if r["source"] == src]
        if rows:
            n = np.array([r.get("dynamics_n") or 1 for r in rows], dtype=float)

            def mean(k, rows=rows, n=n):
                return float(np.average([r.get(k) or 0.0 for r in rows], weights=n))

            parts: dict[str, float] = {}
            for r, w in zip(rows, n, strict=True):
                for part, share in (r.get("ground_parts") or {}).items():
                    parts[part] = parts.get(part, 0.0) + share * w / n.sum()
            missing, above = mean("support_missing_share"), mean("support_above_floor_share")
            high = [(r["support_above_floor_mm"], w) for r, w in zip(rows, n, strict=True)
                    if r.get("support_above_floor_mm") is not None]  # fmt: skip
            above_mm = (
                float(np.average([h for h, _ in high], weights=[w for _, w in high]))
                if high
                else None
            )
            held = mean("support_held_share")
            flag, why = support_verdict(missing, above, row["floor_fits"], above_mm, held)
            row.update(
                original_residual_force_bw=mean("residual_force_bw"), ground_parts=parts,
                support_missing_share=missing, support_above_floor_share=above,
                support_held_share=held, dynamics_unmeasured_n=int(
                    sum(r.get("dynamics_unmeasured_n") or 0 for r in rows)),
                support_above_floor_mm=above_mm, support_off_floor=flag, support_why=why,
            )  # fmt: skip
        out.append(row)
    return out
