"""The sampler's offset noise scaled per bone (``sim.simulate.noisescale``): the bones named are
the trunk's by their hinges' names, their noise is scaled and nothing else's; a scale of 1 is
the sampler bit for bit, a scale of 0 leaves the trunk's targets uncorrected."""

from __future__ import annotations

import numpy as np
import pytest

from sim.errors import UsageError
from sim.model.humanoid import canonical_skeleton
from sim.simulate.gainchoice import GainChoice, choice_search, common_body
from sim.simulate.model import Gains, sim_model
from sim.simulate.noisescale import TRUNK, NoiseScale, hinge_bone, scaled_sigma

STIFF = Gains(min_deflection=0.1, omega=2 * np.pi * 12.0)


@pytest.fixture(scope="module")
def bodies():
    sk = canonical_skeleton()
    return common_body([sim_model(sk), sim_model(sk, gains=STIFF)])


def test_bones_are_named_without_their_side():
    assert hinge_bone("lfemur_rx") == "femur"
    assert hinge_bone("rtoes_rx") == "toes"
    assert hinge_bone("rradius_rx") == "radius"
    assert hinge_bone("lowerback_rz") == "lowerback"  # its l is no side
    assert hinge_bone("lowerneck_ry") == "lowerneck"
    assert hinge_bone("upperback_ry") == "upperback"
    assert hinge_bone("head_rz") == "head"


def test_only_the_named_bones_noise_is_scaled(bodies):
    model = bodies[0]
    sigma = np.linspace(0.1, 0.2, model.nu)
    got = scaled_sigma(model, sigma, NoiseScale(scale=0.25))
    names = [model.joint(j).name for j in model.actuator_trnid[:, 0]]
    for i, n in enumerate(names):  # hand-computed: a quarter on the trunk, the rest as it was
        trunk = n.split("_")[0] in ("lowerback", "upperback", "thorax")
        assert got[i] == pytest.approx(sigma[i] * (0.25 if trunk else 1.0), abs=0.0)
    assert sum(n.split("_")[0] in TRUNK for n in names) == 9  # three bones, three hinges each
    assert scaled_sigma(model, sigma, None) is sigma
    with pytest.raises(UsageError, match="scale"):
        NoiseScale(scale=-0.5)


def test_scale_one_is_the_sampler_bit_for_bit_and_zero_leaves_the_trunk_alone(
    trial_on_floor, bodies
):
    walk = trial_on_floor(bodies[0], "07_01")[:48]
    kw = {"samples": 6, "keep": 2, "seed": 3, "choice": GainChoice(share=0.5)}
    off, sets, _ = choice_search(bodies, walk, **kw)
    same, same_sets, _ = choice_search(bodies, walk, noise_scale=NoiseScale(scale=1.0), **kw)
    np.testing.assert_array_equal(same, off)
    np.testing.assert_array_equal(same_sets, sets)
    still, _, _ = choice_search(bodies, walk, noise_scale=NoiseScale(scale=0.0), **kw)
    names = [bodies[0].joint(j).name for j in bodies[0].actuator_trnid[:, 0]]
    trunk = np.array([n.split("_")[0] in TRUNK for n in names])
    assert np.all(still[:, trunk] == 0.0)  # no noise, no persistence of a noise: no offset
    assert np.abs(still[:, ~trunk]).max() > 0.0  # the legs still searched
    assert np.abs(off[:, trunk]).max() > 0.0  # as they are by default
