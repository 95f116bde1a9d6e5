"""Synthetic motions with known spherical charts, for the keyframe tests (pure numpy)."""

from __future__ import annotations

import numpy as np

from sidql.keyframes.curves import interpolate
from sidql.keyframes.spherical import M_BONES, split_channels
from sidql.keyframes.unchart import clip_from_chart


def smooth_chart(N: int, fps: float, seed: int, *, M: int = M_BONES):
    """Sums of sines with exact derivatives: theta kept in [0.45, 2.7], phi crossing +-pi."""
    rng = np.random.default_rng(seed)
    t = np.arange(N)[:, None] / fps
    w = rng.uniform(0.5, 4.0, (3, M))
    c = rng.uniform(0, 2 * np.pi, (3, M))
    base = rng.uniform(0.9, 2.2, M)
    theta = base + 0.45 * np.sin(w[0] * t + c[0])
    dtheta = 0.45 * w[0] * np.cos(w[0] * t + c[0])
    phi = rng.uniform(-2.5, 2.5, M) + 1.5 * np.sin(w[1] * t + c[1]) + 0.8 * t
    dphi = 1.5 * w[1] * np.cos(w[1] * t + c[1]) + 0.8
    root = np.concatenate([0.9 * t, 1.0 + 0.05 * np.sin(3 * t), 0.3 * t**2], axis=1)
    root_vel = np.concatenate([0.9 + 0 * t, 0.15 * np.cos(3 * t), 0.6 * t], axis=1)
    lengths = rng.uniform(0.05, 0.45, M)
    return theta, phi, dtheta, dphi, root, root_vel, lengths


def smooth_clip(N: int = 60, fps: float = 30.0, seed: int = 0):
    """A 23-point clip of smooth motion (no bone near a chart pole)."""
    return clip_from_chart(*smooth_chart(N, fps, seed), fps=fps)


def piecewise_clip(keyframes, N: int, fps: float, seed: int, curve: str = "hermite"):
    """A clip whose angles and root position are, between the given keyframes, exactly the
    curve ``curve`` (cubic Hermite or linear) through random keyframe values and rates."""
    rng = np.random.default_rng(seed)
    M = M_BONES
    values = np.zeros((N, 2 * M + 3))
    rates = np.zeros((N, 2 * M + 3))
    k = np.asarray(keyframes)
    values[k, :M] = rng.uniform(0.9, 2.2, (len(k), M))
    values[k, M : 2 * M] = rng.uniform(-2.0, 2.0, M) + np.cumsum(
        rng.uniform(-0.8, 0.8, (len(k), M)), axis=0
    )
    values[k, 2 * M :] = rng.normal(size=(len(k), 3))
    rates[k] = rng.uniform(-1.0, 1.0, (len(k), 2 * M + 3))
    x, xd = interpolate(values, rates, k, 1.0 / fps, curve)
    lengths = rng.uniform(0.05, 0.45, M)
    theta, phi, root = split_channels(x, M)
    dtheta, dphi, root_vel = split_channels(xd, M)
    return clip_from_chart(theta, phi, dtheta, dphi, root, root_vel, lengths, fps=fps)


def assert_velocities_match_differences(rec, keys) -> None:
    """A reconstruction's velocities equal central differences of its positions, away from the
    keyframes (where piecewise curves may have kinks): relative error below 1e-3."""
    N = rec.positions.shape[0]
    fd = (rec.positions[2:] - rec.positions[:-2]) / (2 * rec.dt)
    inner = np.ones(N, bool)
    for k in keys:
        inner[max(k - 1, 0) : k + 2] = False
    err = np.abs(fd - rec.velocities[1:-1])[inner[1:-1]]
    assert err.max() < 1e-3 * np.abs(rec.velocities).max()
