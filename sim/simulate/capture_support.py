"""Is a captured motion held up by anything? Its own joint positions against its floor.

Forward validation asks whether a body could perform a motion. Some captures cannot be
performed by any body: where the root decelerates on its way down (or speeds up on its way up)
the floor has to push with more than the body's weight, and something must be there to push on.
A frame is *unsupported* where the root's vertical acceleration asks for more than
:data:`FORCE_SHARE` of the body's weight while no captured joint is within :data:`NEAR_FLOOR`
of the floor, or the nearest such joint is more than :data:`REACH` from the root horizontally
(nothing under the body: the only point on the floor is out in front, where a push large enough
to hold the body up would turn it over instead). The root stands in for the centre of mass.

On the CMU clips of eval (docs/synthetic.md, "The Russian dances' squats"): the squats of
90_30 and 90_31 ask for 2-3 times the body's weight at the bottom of each bounce while the
capture's only points near the floor are a foot's toes 0.7-0.97 m in front of the pelvis.

The original's inverse dynamics asks the same question rigorously
(:func:`sim.physics.support.capture_unsupported`: residual force with nothing on the floor) and,
on eval's clips, flags every clip this check flags and predicts the falls far better (AUC 0.97
against 0.67, docs/results/capture_support.md); the report and the falls' categories read that.
This check is kept as a raw-capture one: it needs only the points, not the subject's skeleton,
an IK fit or contact labels.

Units: metres, seconds; z up.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from sim.simulate.model import G

#: a frame whose root acceleration asks the floor for more than this share of the body's weight
#: needs support (a bounce's bottom, a landing); 1 is standing still
FORCE_SHARE = 1.5
#: [m] a joint centre this close to the floor can bear on it (a toe's end sits 0-5 cm up in stance)
NEAR_FLOOR = 0.08
#: [m] a bearing joint farther than this from the root horizontally is not under the body
REACH = 0.4
#: [frames] the root's height is smoothed by a Gaussian of this scale before differentiating
SMOOTH_FRAMES = 1.0


def support_demand(root_z: np.ndarray, fps: float) -> np.ndarray:
    """(F,) the vertical force the floor must give [share of the body's weight] for the root
    height ``root_z`` (F,) [m] at ``fps`` [Hz]: 1 + its vertical acceleration over g (the root
    standing in for the centre of mass), the height smoothed over :data:`SMOOTH_FRAMES`."""
    z = gaussian_filter1d(np.asarray(root_z, dtype=float), SMOOTH_FRAMES, mode="nearest")
    acc = np.gradient(np.gradient(z, 1.0 / fps), 1.0 / fps)
    return 1.0 + acc / G


def unsupported_frames(
    positions: np.ndarray,
    fps: float,
    root: int = 0,
    *,
    force_share: float = FORCE_SHARE,
    reach: float = REACH,
) -> np.ndarray:
    """(F,) bool: the frames of ``positions`` (F, P, 3) [m], its floor at z = 0, whose root
    (point ``root``) needs the floor to push with more than ``force_share`` of the body's
    weight (:func:`support_demand`) while no other point is within :data:`NEAR_FLOOR` of it or
    the nearest such point is farther than ``reach`` [m] from the root horizontally."""
    pos = np.asarray(positions, dtype=float)
    need = support_demand(pos[:, root, 2], fps) > force_share
    others = np.delete(pos, root, axis=1)
    near = others[..., 2] <= NEAR_FLOOR  # (F, P-1)
    dist = np.linalg.norm(others[..., :2] - pos[:, root : root + 1, :2], axis=-1)
    nearest = np.where(near, dist, np.inf).min(axis=1)  # inf: nothing near the floor
    return need & (nearest > reach)
