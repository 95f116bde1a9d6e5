"""The sampler's offset noise scaled per bone: a smaller search where the posture shows most.

The sampler (``sim.simulate.sampling``, ``sim.simulate.gainchoice``) draws each window's offset
of a corrected hinge with a standard deviation ``torque_sigma`` times its peak torque over its
stiffness, the same share for every hinge. Taken apart on eval's default (docs/synthetic.md,
"What the root-relative error is made of"), the trunk's hinges (``lowerback``, ``upperback``,
``thorax``) cost root-relative error out of proportion to their few degrees: the trunk carries
the head and both arms, so a small bend moves 14 of the 23 points. :class:`NoiseScale`
multiplies the noise of the hinges of ``bones`` by ``scale`` and leaves the legs' search, which
keeps the balance and the path, as it is. An option, off: halving the trunk's noise
(``bench_simulate.py``'s ``trunk0.5``) changed nothing beyond chance on 22 clips.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.errors import UsageError

#: the trunk's bones (the sampler's corrected bones above the pelvis)
TRUNK = ("lowerback", "upperback", "thorax")


@dataclass(frozen=True)
class NoiseScale:
    """The noise of the hinges of ``bones`` (bone names without their side, as
    ``sampling.CORRECTED`` names them) times ``scale`` (>= 0; 1: unchanged)."""

    scale: float = 1.0
    bones: tuple[str, ...] = TRUNK

    def __post_init__(self):
        if not self.scale >= 0.0:
            raise UsageError(f"NoiseScale.scale must be >= 0; got {self.scale}")


def hinge_bone(joint: str) -> str:
    """The bone of a hinge joint's name without its side: ``"lfemur_rx"`` -> ``"femur"``,
    ``"lowerback_rz"`` -> ``"lowerback"`` (a leading l or r is a side only before a name
    that is not a bone of its own)."""
    bone = joint.rsplit("_", 1)[0]
    return bone[1:] if bone[:1] in "lr" and bone not in ("lowerback", "lowerneck") else bone


def scaled_sigma(model, sigma: np.ndarray, noise: NoiseScale | None) -> np.ndarray:
    """(nu,) the offset noise [rad] ``sigma`` (nu,) of ``model``'s actuators with the hinges of
    ``noise.bones`` times ``noise.scale`` (a copy; None: ``sigma`` itself)."""
    if noise is None:
        return sigma
    joints = model.actuator_trnid[:, 0]
    bones = [hinge_bone(model.joint(j).name) for j in joints]
    factor = np.array([noise.scale if b in noise.bones else 1.0 for b in bones])
    return sigma * factor
