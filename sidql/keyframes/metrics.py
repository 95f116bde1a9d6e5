"""Error measures of a reconstruction: the paper's Q (eq. 18) and chart-free errors.

Pure numpy. Units: radians (Q), degrees (geodesic), millimetres (MPJPE), metres per second
(velocity error).
"""

from __future__ import annotations

import numpy as np

from sidql.keyframes.curves import interpolate, validate_keyframes
from sidql.keyframes.spherical import SphericalSeries
from sim.errors import UsageError
from sim.model.angles import wrap_angle


def q_from_angles(series: SphericalSeries, theta: np.ndarray, phi: np.ndarray) -> float:
    """Eq. 18 for given reconstructed angles.

    Args:
        series: the true chart (N frames, M bones).
        theta, phi: (N, M) reconstructed angles [rad] (phi in any branch: differences are wrapped
            to [-pi, pi), :func:`sim.model.angles.wrap_angle`).

    Returns:
        ``(1 / (N M)) sum_{n, m} |wrap(theta~ - theta)| + |wrap(phi~ - phi)|`` [rad].
    """
    e = np.abs(wrap_angle(theta - series.theta)) + np.abs(wrap_angle(phi - series.phi))
    return float(e.sum() / (series.n_frames * series.n_bones))


def q_error(series: SphericalSeries, keyframes, reconstruction: str = "hermite") -> float:
    """The paper's mean angle error Q(S, K) (eq. 18) of reconstructing ``series`` from keyframes.

    Args:
        series: the true chart (N frames, M = 22 bones).
        keyframes: (W,) strictly increasing indices from 0 to N-1 (both ends included).
        reconstruction: a spherical one: "hermite" (paper), "linear" or "catmull_rom" (its curve,
            :data:`sidql.keyframes.curves.CURVES`).

    Returns:
        Q [rad], averaged over the N frames (keyframes included, at zero error) and M bones.
    """
    k = validate_keyframes(keyframes, series.n_frames)
    M = series.n_bones
    values = np.concatenate([series.theta, series.phi], axis=1)
    rates = np.concatenate([series.dtheta, series.dphi], axis=1)
    rec, _ = interpolate(values, rates, k, series.dt, reconstruction)
    return q_from_angles(series, rec[:, :M], rec[:, M:])


def bone_vectors(positions: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(N, J-1, 3) child minus parent position of every non-root point of (N, J, 3) positions."""
    child = np.arange(1, len(parents))
    return positions[:, child] - positions[:, np.asarray(parents)[child]]


def geodesic_deg(true_pos: np.ndarray, rec_pos: np.ndarray, parents: np.ndarray) -> float:
    """Mean angle [deg] between true and reconstructed bone directions.

    Args:
        true_pos, rec_pos: (N, J, 3) positions [m] of the same points; parents: (J,) indices.

    Returns:
        The mean over frames and the J-1 bones of ``atan2(|a x b|, a . b)`` in degrees.
    """
    a = bone_vectors(true_pos, parents)
    b = bone_vectors(rec_pos, parents)
    ang = np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))
    return float(np.degrees(ang).mean())


def mpjpe_mm(true_pos: np.ndarray, rec_pos: np.ndarray) -> float:
    """Mean per-joint position error [mm] of (N, J, 3) positions [m], root included."""
    true_pos, rec_pos = np.asarray(true_pos), np.asarray(rec_pos)
    if true_pos.shape != rec_pos.shape or true_pos.ndim != 3 or true_pos.shape[-1] != 3:
        raise UsageError(
            f"positions must be two (N, J, 3) arrays; got {true_pos.shape}, {rec_pos.shape}"
        )
    return float(1000.0 * np.linalg.norm(rec_pos - true_pos, axis=-1).mean())


def velocity_error_mm_s(true_vel: np.ndarray, rec_vel: np.ndarray) -> float:
    """Mean per-joint velocity error [mm/s] of (N, J, 3) velocities [m/s], root included."""
    return float(1000.0 * np.linalg.norm(rec_vel - true_vel, axis=-1).mean())
