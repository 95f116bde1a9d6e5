"""The humanoid's mass model: de Leva's segment fractions, a chosen total body mass."""

import mujoco
import numpy as np
import pytest

from sim.model.humanoid import build_mjcf, canonical_skeleton, humanoid_model
from sim.model.mass import CMU_SEGMENT, SEGMENT_MASS_PERCENT, body_masses, segment_fractions


def _segment_masses(model) -> dict[str, float]:
    out: dict[str, float] = {}
    for b in range(1, model.nbody):
        seg = CMU_SEGMENT[model.body(b).name].removeprefix("l_").removeprefix("r_")
        out[seg] = out.get(seg, 0.0) + float(model.body_mass[b])
    return out


@pytest.mark.parametrize("total", [50.0, 75.0, 110.0])
def test_the_model_weighs_the_chosen_body_mass(total):
    model = mujoco.MjModel.from_xml_string(build_mjcf(canonical_skeleton(), body_mass_kg=total))
    assert model.body_mass.sum() == pytest.approx(total, rel=1e-5)


def test_segments_carry_de_levas_fractions():
    _, model = humanoid_model()
    total = model.body_mass.sum()
    got = _segment_masses(model)
    table = SEGMENT_MASS_PERCENT["male"]
    assert set(got) == set(table)
    for seg, pct in table.items():
        # Table 4 sums to 100.01 %: fractions are renormalised, so compare to 1e-3 relative.
        per_side = 1 if seg in ("head", "upper_trunk", "middle_trunk", "lower_trunk") else 2
        assert got[seg] / total == pytest.approx(per_side * pct / 100.0, rel=1e-3), seg


def test_inertia_is_positive_and_follows_the_geometry():
    _, model = humanoid_model()
    assert np.all(model.body_inertia[1:] > 0)
    # A thigh (long capsule) has a much smaller moment about its own axis than across it.
    thigh = model.body("lfemur").id
    inertia = np.sort(model.body_inertia[thigh])
    assert inertia[0] < 0.5 * inertia[2]


def test_a_skeleton_that_is_not_cmus_shares_mass_by_volume():
    masses = body_masses({"root": 1.0, "a": 2.0, "b": 1.0}, total_kg=40.0)
    assert masses == pytest.approx({"root": 10.0, "a": 20.0, "b": 10.0})
    assert sum(segment_fractions("female").values()) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="positive"):
        body_masses({"root": 1.0}, total_kg=float("nan"))
