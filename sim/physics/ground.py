"""Per-trial floor from the original motion's planted feet: a robust tilted plane and how well it fits.

CMU trials do not share a floor level (the soles' markers stand anywhere from about -11 cm to +16 cm
in the files' own frame) and some capture floors are tilted or drift. The estimator, per trial:

1. foot points: :data:`sim.physics.contacts.FOOT_POINTS` (heel, ball, toes per side) present in
   the motion;
2. *still* samples: a sole point (ball or toes) slower than ``slow_speed`` (3-D) for a run of at
   least ``run_s`` seconds;
3. *planted* samples: still samples within ``band`` of the current floor (first the low
   ``percentile`` of still sole heights, then the fitted plane); a foot held still in the air (a
   one-leg balance) is not planted;
4. the floor ``z = z0 + sx (x - x0) + sy (y - y0)`` by iteratively reweighted least squares
   (Tukey biweight, scale from the median absolute residual) over the planted samples, planted
   samples re-selected against each new plane; tilted only along directions in which the planted
   feet spread ``min_span`` (a straight walk fixes the slope along its path);
5. each foot point's *clearance*: its median height above the plane over the frames its foot is
   planted and it is still (the ankle stands ~5-8 cm above the sole markers in stance).

How far the planted feet sit from the plane: ``spread`` (robust standard deviation of the
residuals), ``drift`` (range of the median residual over quarters of the take), ``tilt`` (how far
the plane departs from horizontal across the planted area) and ``below`` (how far the soles go
below it on average). A slope steeper than ``MAX_SLOPE`` is not believed (few footprints):
the floor stays horizontal. The floor *fits* when spread, drift and below are within ``FLAT_TOLERANCE``; where it does not, heights above it (float, penetration) are not to
be trusted and the report and ``eval`` flag the trial with :attr:`Ground.deviation`.
Heights "above ground" of a point are ``z - plane(x, y) - clearance``.

Units: metres, metres per second; world z up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.physics.feet import FOOT_POINTS, SOLE_POINTS, SOLE_RADIUS, foot_points, side

__all__ = ["FOOT_POINTS", "SOLE_POINTS", "SOLE_RADIUS", "Ground", "estimate_ground", "foot_points"]

#: [m] the floor fits when the planted feet's residual spread and drift stay within this.
FLAT_TOLERANCE = 0.01
#: [m/m] steepest floor fitted (about 3 degrees): a steeper fit comes from too few footprints.
MAX_SLOPE = 0.05


@dataclass(frozen=True)
class Ground:
    """A trial's floor.

    Attributes:
        z: floor height [m] at ``origin``: the level of the sole points in stance.
        points: (F,) foot point names the clearances belong to.
        clearance: (F,) each foot point's stance height above the floor [m].
        frames: planted (frame, sole point) samples the fit used.
        slope: (2,) the plane's dz/dx and dz/dy (0, 0: horizontal).
        origin: (2,) the horizontal point [m] where the plane has height ``z``.
        spread: robust standard deviation (1.4826 MAD) of the planted samples' residuals [m].
        drift: range of the median planted residual over the take's quarters [m].
        tilt: largest |plane - z| over the planted samples [m]: how far a horizontal floor at
            ``z`` would be off.
        below: mean depth of the sole points below the floor over every frame [m]: large when the
            feet stand on a lower floor than the one found.
    """

    z: float
    points: tuple[str, ...]
    clearance: np.ndarray
    frames: int
    slope: tuple[float, float] = (0.0, 0.0)
    origin: tuple[float, float] = (0.0, 0.0)
    spread: float = 0.0
    drift: float = 0.0
    tilt: float = 0.0
    below: float = 0.0

    @property
    def floor_z(self) -> float:
        """Height [m] of the plane the replay's foot capsules stand on (for replay and rendering)."""
        return float(self.z - SOLE_RADIUS)

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

    def clearance_of(self, names) -> np.ndarray:
        """(len(names),) clearances [m] of the foot points ``names`` (each must be in ``points``)."""
        return np.array([self.clearance[self.points.index(n)] for n in names])

    def level(self, xy: np.ndarray) -> np.ndarray:
        """(...,) the floor's height [m] under horizontal points ``xy`` (..., 2) [m]."""
        xy = np.asarray(xy, dtype=np.float64)
        return (
            self.z
            + self.slope[0] * (xy[..., 0] - self.origin[0])
            + self.slope[1] * (xy[..., 1] - self.origin[1])
        )

    def heights(self, positions: np.ndarray, names) -> np.ndarray:
        """(T, F) heights [m] of foot points ``positions`` (T, F, 3) named ``names`` (F,) above
        their stance levels on this floor: ``z - level(x, y) - clearance``."""
        p = np.asarray(positions, dtype=np.float64)
        return p[..., 2] - self.level(p[..., :2]) - self.clearance_of(names)

    def summary(self) -> dict[str, float | bool]:
        """JSON-ready floor figures: ``floor_z_m``, ``floor_slope`` (dz/dx, dz/dy),
        ``floor_spread_mm``, ``floor_drift_mm``, ``floor_tilt_mm``, ``floor_deviation_mm``,
        ``floor_fits``, ``floor_samples`` (NaN figures as None)."""

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
        }


def horizontal_speed(positions: np.ndarray, fps: float) -> np.ndarray:
    """(T, ...) horizontal speed [m/s] of ``positions`` (T, ..., 3) [m] (central differences)."""
    p = np.asarray(positions, dtype=np.float64)
    if p.shape[0] < 2:
        return np.zeros(p.shape[:-1])
    return np.linalg.norm(np.gradient(p[..., :2], 1.0 / fps, axis=0), axis=-1)


def _speed(p: np.ndarray, fps: float) -> np.ndarray:
    if p.shape[0] < 2:
        return np.zeros(p.shape[:-1])
    return np.linalg.norm(np.gradient(p, 1.0 / fps, axis=0), axis=-1)


def _long_runs(mask: np.ndarray, n: int) -> np.ndarray:
    """(T, F) ``mask`` (T, F) kept only in runs of at least ``n`` consecutive True frames."""
    out = np.zeros_like(mask)
    for k in range(mask.shape[1]):
        m = np.concatenate([[False], mask[:, k], [False]]).astype(np.int8)
        d = np.diff(m)
        for s, e in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
            if e - s >= n:
                out[s:e, k] = True
    return out


def _fit_plane(xy, z, group, n_groups: int, min_span: float, iters=20, max_slope=MAX_SLOPE):
    """Tukey-biweight IRLS fit of ``z ~ c[group] + s . (xy - origin)``: one plane, an offset per
    foot point (the ball stands higher than the toe tip). The plane tilts only along horizontal
    directions in which the samples spread at least ``min_span`` (standard deviation [m]): a
    straight walk fixes the slope along its path, not across it; a slope steeper than
    ``max_slope`` falls back to a horizontal plane. Returns (c (G,), s (2,),
    origin (2,), residuals (N,))."""
    origin = np.median(xy, axis=0)
    G = n_groups
    onehot = np.eye(G)[group]
    d = xy - origin
    if len(z) > 2:
        var, vec = np.linalg.eigh(np.cov(d.T))
        axes = vec[:, np.sqrt(np.clip(var, 0, None)) >= min_span]  # (2, k), k = 0, 1, 2
    else:
        axes = np.zeros((2, 0))
    k = axes.shape[1]
    A = np.column_stack([onehot, d @ axes])
    if k and max_slope < np.inf:  # a steeper fit is noise over a few footprints: stay level
        c, s, o, r = _fit_plane(xy, z, group, n_groups, np.inf, iters)
        coef_t = _fit_plane(xy, z, group, n_groups, min_span, iters, np.inf)
        return coef_t if np.abs(coef_t[1]).max() <= max_slope else (c, s, o, r)
    w = np.ones(len(z))
    coef = np.zeros(A.shape[1])
    for _ in range(iters):
        sw = np.sqrt(w)
        coef = np.linalg.lstsq(A * sw[:, None], z * sw, rcond=None)[0]
        r = z - A @ coef
        scale = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 1e-3)
        u = r / (4.685 * scale)
        w = np.where(np.abs(u) < 1, (1 - u**2) ** 2, 0.0)
        if w.sum() < A.shape[1] + 1:
            break
    s = axes @ coef[G : G + k] if k else np.zeros(2)
    return coef[:G], s, origin, z - A @ coef


def estimate_ground(
    positions: np.ndarray,
    names,
    fps: float,
    *,
    percentile: float = 5.0,
    slow_speed: float = 0.25,
    run_s: float = 0.15,
    band: float = 0.03,
    min_span: float = 0.3,
    min_frames: int = 10,
) -> Ground:
    """The trial's floor and foot-point clearances (see the module docstring).

    Args:
        positions: (T, J, 3) the original's points [m] over the whole trial (clips concatenated
            are fine: speeds at the seams are off for one frame each).
        names: (J,) point names; at least one foot point must be among them.
        fps: frame rate [1/s].
        percentile: the low percentile of still sole heights that starts the fit [%].
        slow_speed: a point slower than this (3-D) [m/s] ...
        run_s: ... for at least this long [s] is still.
        band: a still sole point within this of the floor [m] is planted.
        min_span: the plane tilts along a horizontal direction only where the planted feet
            spread at least this far (standard deviation [m]).
        min_frames: below this many planted samples, the floor is the low percentile of all sole
            heights, horizontal.

    Returns:
        The :class:`Ground`.
    """
    names = tuple(names)
    feet = foot_points(names)
    if not feet:
        raise ValueError(f"no foot point among {names}; need one of {FOOT_POINTS}")
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim != 3 or p.shape[1:] != (len(names), 3) or p.shape[0] < 1:
        raise ValueError(f"positions must be (T, {len(names)}, 3); got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("positions must be finite")
    pf = p[:, [names.index(n) for n in feet]]  # (T, F, 3)
    T = len(pf)
    still = _long_runs(_speed(pf, fps) < slow_speed, max(1, int(round(run_s * fps))))
    sole = np.array([n in SOLE_POINTS for n in feet])
    if not sole.any():
        sole[:] = True
    zs = pf[:, sole, 2]
    pool = zs[still[:, sole]] if still[:, sole].sum() >= min_frames else zs.ravel()
    z0 = float(np.percentile(pool, percentile))
    ground = Ground(z0, feet, np.zeros(len(feet)), 0)
    planted = np.zeros((T, len(feet)), dtype=bool)
    col = np.broadcast_to(np.arange(len(feet))[None, :], planted.shape)
    r = np.zeros(0)
    for _ in range(3):
        resid = pf[..., 2] - ground.level(pf[..., :2]) - ground.clearance
        planted = still & sole[None, :] & (np.abs(resid) < band)
        if planted.sum() < min_frames:
            break
        xy, z = pf[planted][:, :2], pf[planted][:, 2]
        c, s, origin, r = _fit_plane(xy, z, col[planted], len(feet), min_span)
        has = np.isin(np.arange(len(feet)), col[planted])
        z_floor = float(c[has & sole].min())
        clear = np.where(has, c - z_floor, 0.0)
        ground = Ground(z_floor, feet, clear, int(planted.sum()), (s[0], s[1]), tuple(origin))
    if planted.sum() < min_frames:  # no foot ever planted: a floor nobody can vouch for
        return Ground(z0, feet, np.zeros(len(feet)), 0, spread=np.nan)
    resid = pf[..., 2] - ground.level(pf[..., :2])  # (T, F) above the floor, clearance not taken
    spread = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    sole_h = (resid - ground.clearance)[:, sole]
    below = float(np.maximum(-sole_h, 0.0).mean())
    t_of = np.broadcast_to(np.arange(T)[:, None], planted.shape)[planted]
    quarters = [r[(t_of >= q * T / 4) & (t_of < (q + 1) * T / 4)] for q in range(4)]
    medians = [float(np.median(x)) for x in quarters if len(x) >= min_frames]
    drift = max(medians) - min(medians) if medians else 0.0
    tilt = float(np.abs(ground.level(pf[planted][:, :2]) - ground.z).max())
    foot_planted = {s_: planted[:, [side(n) == s_ for n in feet]].any(axis=1) for s_ in "lr"}
    clearance = np.array(ground.clearance, dtype=np.float64)
    for k, n in enumerate(feet):
        if sole[k]:
            continue  # fitted with the plane
        use = foot_planted[side(n)] & still[:, k]
        clearance[k] = float(np.median(resid[use, k])) if use.sum() >= min_frames else 0.0
    return Ground(
        ground.z, feet, clearance, int(planted.sum()), ground.slope, ground.origin,
        spread, drift, tilt, below,
    )  # fmt: skip
