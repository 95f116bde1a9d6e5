"""Per-trial floor from the original motion's planted feet: a robust tilted plane and how well it fits.

CMU trials do not share a floor level (the soles stand anywhere from about -20 cm to +16 cm in the
files' own frame) and some capture floors are tilted or drift. The estimator, per trial:

1. the sole (:func:`sim.physics.feet.sole`): per foot its lowest surface point in every frame;
2. *footprints*: runs of at least ``run_s`` seconds in which a foot's lowest sole sphere moves
   slower than ``slow_speed``; each footprint is one sample (its median position), so a long
   stand does not outweigh the steps of a walk;
3. the floor ``z = z0 + sx (x - x0) + sy (y - y0)`` plus a height offset per foot (the skeleton's
   feet are not always the same height above the floor) by iteratively reweighted least squares
   (Tukey biweight, scale from the median absolute residual, at least ``min_scale``) over the
   footprints, started from a horizontal plane at the lowest footprints: a foot held still in the
   air (a one-leg balance) or standing on a box is an outlier, not a floor; the plane tilts only
   along directions in which the inlier footprints spread ``min_span`` (a straight walk fixes the
   slope along its path), and never steeper than :data:`MAX_SLOPE` (few footprints);
4. *planted* samples: still frames whose lowest sole point is within ``band`` of the plane.

How far the planted feet sit from the plane: ``spread`` (robust standard deviation of the planted
samples' residuals), ``drift`` (range of their median over the take's quarters), ``tilt`` (how far
the plane departs from horizontal across the planted area) and ``below`` (mean depth of the soles
below it over every frame). The floor *fits* when spread, drift and below are within
:data:`FLAT_TOLERANCE`; where it does not, heights above it (float, penetration) are not to be
trusted and the report and ``eval`` flag the trial with :attr:`Ground.deviation`.

The *gap* of a sole sphere is the height of its lowest surface point above the plane, less its
foot's offset (:meth:`Ground.gaps`): 0 where it rests on the floor.

Units: metres, metres per second; world z up.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from sim.errors import UsageError
from sim.model.kinematics import FOOT_POINTS, SIDES, foot_points
from sim.physics.feet import Sole, sole

__all__ = ["FOOT_POINTS", "FLAT_TOLERANCE", "MAX_SLOPE", "Ground", "estimate_ground", "foot_points"]

#: [m] the floor fits when the planted feet's residual spread, drift and depth stay within this.
FLAT_TOLERANCE = 0.01
#: [m/m] steepest floor fitted (about 3 degrees): a steeper fit comes from too few footprints.
MAX_SLOPE = 0.05
#: [m] largest stance offset of a foot from the plane (skeleton asymmetry, not a raised foot).
MAX_OFFSET = 0.0075


@dataclass(frozen=True)
class Ground:
    """A trial's floor.

    Attributes:
        z: floor height [m] at ``origin``: where the lowest sole surfaces rest in stance.
        sides: the feet (``"l"``, ``"r"``) the offsets belong to.
        offset: (len(sides),) each foot's stance height above the plane [m] (0 for the lower).
        frames: planted (frame, foot) samples behind the fit (0: no foot was planted).
        slope: (2,) the plane's dz/dx and dz/dy (0, 0: horizontal).
        origin: (2,) the horizontal point [m] where the plane has height ``z``.
        spread: robust standard deviation (1.4826 MAD) of the planted samples' residuals [m].
        drift: range of the median planted residual over the take's quarters [m].
        tilt: largest |plane - z| over the planted samples [m]: how far a horizontal floor at
            ``z`` would be off.
        below: mean depth of the soles below the floor over every frame [m]: large when the feet
            stand on a lower floor than the one found.
        footprints: footprints found (still runs of a foot); ``inliers``: those on the plane.
    """

    z: float
    sides: tuple[str, ...] = SIDES
    offset: np.ndarray = field(default_factory=lambda: np.zeros(2))
    frames: int = 0
    slope: tuple[float, float] = (0.0, 0.0)
    origin: tuple[float, float] = (0.0, 0.0)
    spread: float = 0.0
    drift: float = 0.0
    tilt: float = 0.0
    below: float = 0.0
    footprints: int = 0
    inliers: int = 0

    @property
    def floor_z(self) -> float:
        """Height [m] of the floor plane at ``origin`` (for replay and rendering)."""
        return float(self.z)

    @property
    def deviation(self) -> float:
        """How far the feet depart from the fitted floor [m]: max(spread, drift, below); NaN
        when no foot was planted long enough to fit one."""
        if self.frames == 0 or np.isnan(self.spread):
            return float("nan")
        return float(max(self.spread, self.drift, self.below))

    @property
    def fits(self) -> bool:
        """Whether :attr:`deviation` is within :data:`FLAT_TOLERANCE`: float and penetration
        measured against this floor are meaningful."""
        return bool(self.deviation <= FLAT_TOLERANCE)  # NaN: False

    @property
    def noise(self) -> float:
        """[m] how far a planted sole may stand off this floor by the fit's own scatter (its
        spread; 0 when none was measured)."""
        return 0.0 if np.isnan(self.spread) else float(self.spread)

    def offset_of(self, s: str) -> float:
        """Stance height [m] of foot ``s`` above the plane (0 for a foot the fit did not see)."""
        return float(self.offset[self.sides.index(s)]) if s in self.sides else 0.0

    def level(self, xy: np.ndarray) -> np.ndarray:
        """(...,) the floor's height [m] under horizontal points ``xy`` (..., 2) [m]."""
        xy = np.asarray(xy, dtype=np.float64)
        return (
            self.z
            + self.slope[0] * (xy[..., 0] - self.origin[0])
            + self.slope[1] * (xy[..., 1] - self.origin[1])
        )

    def gaps(self, s: Sole) -> np.ndarray:
        """(T, S) gap [m] of each sole sphere of ``s``: its lowest surface point above the floor,
        less its foot's stance offset (0: resting on the floor; negative: below it)."""
        b = s.bottoms
        off = np.array([self.offset_of(x) for x in s.side])
        return b[..., 2] - self.level(b[..., :2]) - off

    def moved(self, floor_z: float) -> Ground:
        """This ground with the whole frame shifted so that the floor at ``origin`` is at height
        ``floor_z`` (e.g. a simulated clip whose floor is known to be z = 0)."""
        return replace(self, z=float(floor_z))

    def summary(self) -> dict[str, float | bool]:
        """JSON-ready floor figures: ``floor_z_m``, ``floor_slope`` (dz/dx, dz/dy),
        ``floor_spread_mm``, ``floor_drift_mm``, ``floor_tilt_mm``, ``floor_below_mm``,
        ``floor_deviation_mm``, ``floor_fits``, ``floor_samples``, ``floor_footprints``
        (NaN figures as None)."""

        def mm(x: float):
            return None if np.isnan(x) else 1e3 * float(x)

        return {
            "floor_z_m": self.floor_z,
            "floor_slope": [float(self.slope[0]), float(self.slope[1])],
            "floor_spread_mm": mm(self.spread),
            "floor_drift_mm": mm(self.drift),
            "floor_tilt_mm": mm(self.tilt),
            "floor_below_mm": mm(self.below),
            "floor_deviation_mm": mm(self.deviation),
            "floor_fits": bool(self.fits),
            "floor_samples": int(self.frames),
            "floor_footprints": int(self.footprints),
        }


def horizontal_speed(positions: np.ndarray, fps: float) -> np.ndarray:
    """(T, ...) horizontal speed [m/s] of ``positions`` (T, ..., 3) [m] (central differences)."""
    p = np.asarray(positions, dtype=np.float64)
    if p.shape[0] < 2:
        return np.zeros(p.shape[:-1])
    return np.linalg.norm(np.gradient(p[..., :2], 1.0 / fps, axis=0), axis=-1)


def speed(positions: np.ndarray, fps: float) -> np.ndarray:
    """(T, ...) speed [m/s] of ``positions`` (T, ..., 3) [m] (central differences)."""
    p = np.asarray(positions, dtype=np.float64)
    if p.shape[0] < 2:
        return np.zeros(p.shape[:-1])
    return np.linalg.norm(np.gradient(p, 1.0 / fps, axis=0), axis=-1)


def runs(mask: np.ndarray, n: int) -> list[tuple[int, int]]:
    """``[start, stop)`` of the runs of at least ``n`` consecutive True values of ``mask`` (T,)."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]]).astype(np.int8)
    d = np.diff(m)
    return [
        (int(s), int(e))
        for s, e in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True)
        if e - s >= n
    ]


def lowest_points(s: Sole) -> tuple[np.ndarray, np.ndarray]:
    """Per foot of ``s`` the lowest sole surface point (T, F, 3) [m] and the index (T, F) of its
    sphere (feet in ``s.sides`` order)."""
    b = s.bottoms
    T = b.shape[0]
    pts, idx = [], []
    for x in s.sides:
        ks = s.of(x)
        k = ks[np.argmin(b[:, ks, 2], axis=1)]
        pts.append(b[np.arange(T), k])
        idx.append(k)
    return np.stack(pts, axis=1), np.stack(idx, axis=1)


def _plane_fit(xy, z, group, n_groups, axes, weights):
    """Weighted least squares ``z ~ c[group] + s . (xy @ axes)``; returns (c, s_along_axes)."""
    onehot = np.eye(n_groups)[group]
    A = np.column_stack([onehot, xy @ axes]) if axes.shape[1] else onehot
    sw = np.sqrt(weights)
    coef = np.linalg.lstsq(A * sw[:, None], z * sw, rcond=None)[0]
    return coef[:n_groups], coef[n_groups:], z - A @ coef


def _robust_plane(xy, z, group, n_groups, *, min_span, min_scale, iters=30):
    """Tukey-biweight IRLS of footprints ``z ~ c[group] + slope . xy`` started from a horizontal
    plane through the lowest footprints. Returns (c (G,), slope (2,), weights (N,))."""
    N = len(z)
    # start: horizontal, each group at its low quantile (a raised foot must not pull the floor up)
    c = np.array([np.percentile(z[group == g], 25) if np.any(group == g) else 0.0
                  for g in range(n_groups)])  # fmt: skip
    r = z - c[group]
    slope = np.zeros(2)
    w = np.ones(N)
    for it in range(iters):
        scale = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), min_scale)
        u = r / (4.685 * scale)
        w_prev, w = w, np.where(np.abs(u) < 1, (1 - u**2) ** 2, 0.0)
        if w.sum() < 1e-9:
            break
        if it > 0 and np.array_equal(w, w_prev):  # a fixed point: every later pass repeats it
            break
        inl = w > 0
        axes = np.zeros((2, 0))
        if inl.sum() > 2:
            d = xy[inl] - np.average(xy[inl], axis=0, weights=w[inl])
            var, vec = np.linalg.eigh(np.cov(d.T, aweights=w[inl]))
            axes = vec[:, np.sqrt(np.clip(var, 0, None)) >= min_span]
        c_new, s_ax, r_new = _plane_fit(xy, z, group, n_groups, axes, w)
        s_new = axes @ s_ax if axes.shape[1] else np.zeros(2)
        if np.abs(s_new).max(initial=0.0) > MAX_SLOPE:  # few footprints: stay level
            c_new, _, r_new = _plane_fit(xy, z, group, n_groups, np.zeros((2, 0)), w)
            s_new = np.zeros(2)
        # groups without inliers keep their start
        seen = np.array([np.any(inl & (group == g)) for g in range(n_groups)])
        c = np.where(seen, c_new, c)
        slope = s_new
        r = z - c[group] - xy @ slope
    return c, slope, w


def estimate_ground(
    positions: np.ndarray,
    names,
    fps: float,
    *,
    slow_speed: float = 0.25,
    run_s: float = 0.15,
    band: float = 0.03,
    min_span: float = 0.3,
    min_scale: float = 0.003,
    percentile: float = 5.0,
) -> Ground:
    """The trial's floor (see the module docstring).

    Args:
        positions: (T, J, 3) the original's points [m] over the whole trial (clips concatenated
            are fine: speeds at the seams are off for one frame each).
        names: (J,) point names; at least one foot's ankle and ball must be among them.
        fps: frame rate [1/s].
        slow_speed: a foot whose lowest sole sphere is slower than this [m/s] ...
        run_s: ... for at least this long [s] leaves a footprint.
        band: a still foot within this of the plane [m] is planted.
        min_span: the plane tilts along a horizontal direction only where the inlier footprints
            spread at least this far (standard deviation [m]).
        min_scale: smallest residual scale of the robust fit [m] (mocap-level noise).
        percentile: without any footprint, the floor is this low percentile of the soles'
            lowest points, horizontal, and flagged (``frames`` 0, deviation NaN).
    """
    names = tuple(names)
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim != 3 or p.shape[1:] != (len(names), 3) or p.shape[0] < 1:
        raise UsageError(f"positions must be (T, {len(names)}, 3); got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise UsageError("positions must be finite")
    if not foot_points(names):
        raise UsageError(f"no foot point among {names}; need one of {FOOT_POINTS}")
    s = sole(p, names)
    low, idx = lowest_points(s)  # (T, F, 3), (T, F)
    T, F = low.shape[:2]
    centres = s.centres[np.arange(T)[:, None], idx]  # (T, F, 3) the lowest spheres' centres
    still = speed(centres, fps) < slow_speed
    if F > 1:  # demonstrably planted: not held above the other foot (a one-leg balance)
        still &= low[..., 2] <= low[..., 2].min(axis=1, keepdims=True) + band
    n_run = max(1, int(round(run_s * fps)))
    prints = [(f, a, e) for f in range(F) for a, e in runs(still[:, f], n_run)]
    if not prints:  # no foot ever planted: a floor nobody can vouch for
        z0 = float(np.percentile(low[..., 2], percentile))
        return Ground(z0, s.sides, np.zeros(F), 0, spread=np.nan)
    fp_xy = np.array([np.median(low[a:e, f, :2], axis=0) for f, a, e in prints])
    fp_z = np.array([np.median(low[a:e, f, 2]) for f, a, e in prints])
    fp_g = np.array([f for f, _, _ in prints])
    origin = np.median(fp_xy, axis=0)
    # one plane for both feet (a raised foot is an outlier, not a floor of its own) ...
    c, slope, w = _robust_plane(
        fp_xy - origin, fp_z, np.zeros(len(fp_z), int), 1, min_span=min_span, min_scale=min_scale
    )
    # ... then each foot's stance offset from its footprints on that plane (skeletons put the
    # two feet at slightly different heights), bounded
    r = fp_z - c[0] - (fp_xy - origin) @ slope
    off = np.array([np.median(r[(fp_g == f) & (w > 0)]) if np.any((fp_g == f) & (w > 0)) else 0.0
                    for f in range(F)])  # fmt: skip
    off = np.clip(off, -MAX_OFFSET, MAX_OFFSET)
    z0 = float(c[0] + off.min())
    ground = Ground(z0, s.sides, off - off.min(), 0, (float(slope[0]), float(slope[1])),
                    (float(origin[0]), float(origin[1])))  # fmt: skip
    return _with_fit(ground, low, still, band, len(prints), int((w > 0).sum()))


def _with_fit(
    ground: Ground, low: np.ndarray, still: np.ndarray, band: float, footprints: int, inliers: int
) -> Ground:
    """``ground`` with how well it fits the planted feet: ``low`` (T, F, 3) the feet's lowest
    sole points [m], ``still`` (T, F) bool the still feet, ``band`` [m] (see
    :func:`estimate_ground`); ``footprints`` and ``inliers`` of the plane's fit."""
    T = low.shape[0]
    gap = low[..., 2] - ground.level(low[..., :2]) - ground.offset[None, :]  # (T, F)
    planted = still & (np.abs(gap) < band)
    n = int(planted.sum())
    if n == 0:
        return replace(ground, spread=np.nan, footprints=footprints)
    r = gap[planted]
    spread = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    t_of = np.broadcast_to(np.arange(T)[:, None], planted.shape)[planted]
    quarters = [r[(t_of >= q * T / 4) & (t_of < (q + 1) * T / 4)] for q in range(4)]
    medians = [float(np.median(x)) for x in quarters if len(x) >= 5]
    drift = max(medians) - min(medians) if medians else 0.0
    tilt = float(np.abs(ground.level(low[planted][:, :2]) - ground.z).max())
    below = float(np.maximum(-gap, 0.0).mean())
    return replace(
        ground, frames=n, spread=spread, drift=drift, tilt=tilt, below=below,
        footprints=footprints, inliers=inliers,
    )  # fmt: skip
