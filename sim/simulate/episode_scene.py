"""The scene, body and reference of a synthetic episode.

A real-motion episode (``track``, ``fall``, ``follow``) tracks a window of a real trial. By
default (``SynthTask.terrain``, ``synth``'s default; ``--flat-floor`` turns it off) it does so
in the scene inferred from the trial, as ``eval --simulate`` does
(``sim.simulate.terrain.find_terrain``: static boxes under feet that stand on raised supports,
CMU's playground climb 01_02): the whole trial, scaled with the body and at its own speed
(120 Hz), is searched, so the scene is the trial's, whatever window and time warp the episode
draws. Where boxes are found the episode's MJCF holds them (``add_terrain``: massless static
geoms ``terrain<k>`` of a last body ``terrain``, the floor's contact parameters), the reference
is set on the trial's ground track (the running floor of its ground-level frames, warped with
the motion) instead of the window's floor track, and the controller, the fall rule and the
contact-consistent reference read the boxes as floor (they take them from the model). Where
none is found, or the scene is not asked for, the episode is the one it was on the empty
floor, bit for bit. Procedural motion has no original to infer a scene from: the empty floor.

The scene is recorded in the episode's parameters (``p["scene"]``: ``inferred``, whether it was
inferred, and ``boxes``, each ``centre`` (3,) [m], ``half`` sizes (3,) [m] and ``yaw`` [rad]
about z; no boxes: the empty floor).
"""

from __future__ import annotations

import numpy as np

from sim.errors import MotionDataError, UsageError
from sim.motion.synthetic import synthetic_qpos
from sim.simulate.episode_body import episode_bodies
from sim.simulate.footlock import foot_locked
from sim.simulate.model import CONTROL_HZ, Gains
from sim.simulate.reference import (
    FLOOR_LIFT,
    contact_consistent,
    flat_soles,
    on_floor,
    time_warp,
    trial_qpos,
)
from sim.simulate.terrain import Box, find_terrain
from sim.simulate.windows import body_points, fastest_window, window_steps

#: windows drawn per clip of a kind, the fastest kept (:func:`fastest_window`; within the
#: kind's :data:`WINDOW_SPEED_BAND` where it has one): the ``track`` kind is velocity-rich on
#: purpose, the others take one window at random
WINDOW_CANDIDATES = {"track": 4}
#: per kind, (floor [m/s], cap [m/s], highest warp): the fastest window whose body points'
#: 95th-percentile speed at the drawn warp (``windows.window_steps``) is within the cap (none
#: is: the slowest), then the warp moved so that speed comes into [floor, cap]: lowered (never
#: below 1 by this) or raised (never above the highest warp nor beyond the trial's length). A
#: kind not named takes the fastest window at its drawn warp
#: An option, off: 8 windows and the band (4.5, 5.5, 2.0) for ``track`` and ``fall`` with
#: ``generate.TRACK_SPEED`` 1-2x made the clips that stay up faster (p95 1.40 / 1.49x the real
#: trials' on 60 clips x 2 seeds, against 1.30 / 1.26) but not 1.5x on both, and skated more on
#: one seed (docs/synthetic.md, "A speed band for the windows")
WINDOW_SPEED_BAND: dict[str, tuple[float, float, float]] = {}
#: a real-motion episode is tracked in the scene inferred from its trial unless its task says
#: otherwise (``synth --flat-floor``), as ``eval --simulate``'s bodies are
#: (``validate.DEFAULT_TERRAIN``)
SYNTH_TERRAIN = True


def episode_setup(
    task, p: dict, skeleton, stiff: tuple[Gains, ...], n: int, rng: np.random.Generator,
) -> tuple[tuple, str, Gains, np.ndarray]:  # fmt: skip
    """The models, MJCF and gains of ``task``'s episode (a ``generate.SynthTask``) (``episode_bodies`` of ``skeleton`` with
    ``p``'s scale, gain, actuators and lean and the gain sets ``stiff``, in its scene) and the
    (n, nq) reference it tracks at ``CONTROL_HZ`` (:func:`source_window`,
    :func:`placed_reference`; procedural: :func:`procedural_reference`); records ``scene`` in
    ``p`` (module docstring).

    Raises:
        MotionDataError: the source trial is unreadable or shorter than one clip.
        UsageError: a foot lock asked of a reference that is not contact-consistent.
    """
    actuators = "motor" if p["controller"] == "wholebody" else "position"
    bodies = episode_bodies(skeleton, p["scale"], p["gain"], actuators, task.lean, stiff)
    body = bodies[0][0]
    if task.kind == "procedural":  # no original motion: the empty floor
        p["scene"] = scene_record(False, [])
        return (*bodies, procedural_reference(task, p, body, n))
    window, ground, boxes = source_window(task, p, body, n, rng)
    p["scene"] = scene_record(bool(task.terrain), boxes)
    if boxes:  # the same body, compiled anew with the boxes (the MJCF holds them)
        bodies = episode_bodies(skeleton, p["scale"], p["gain"], actuators, task.lean, stiff,
                                terrain=boxes)  # fmt: skip
    return (*bodies, placed_reference(task, p, body, bodies[0][0], window, ground))


def scene_record(inferred: bool, boxes: list[Box]) -> dict:
    """JSON-ready record of an episode's scene (module docstring)."""
    return {
        "inferred": bool(inferred),
        "boxes": [{"centre": [float(x) for x in b.centre], "half": [float(x) for x in b.half],
                   "yaw": float(b.yaw)} for b in boxes],
    }  # fmt: skip


def procedural_reference(task, p: dict, model, n: int) -> np.ndarray:
    """(n, nq) the procedural motion of ``p`` (``sim.motion.synthetic``) replayed
    ``p["speed"]`` times faster at ``CONTROL_HZ``; records an empty ``source`` in ``p``."""
    slow, _ = synthetic_qpos(
        model, task.seconds * p["speed"] + 0.1, seed=p["motion_seed"], rate=CONTROL_HZ,
        energy=p["energy"],
    )  # fmt: skip
    p["source"] = ""
    return time_warp(model, slow, CONTROL_HZ, p["speed"], CONTROL_HZ)[:n]


def source_window(
    task, p: dict, model, n: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray | None, list[Box]]:
    """A window of ``n`` ticks of the source trial, its root scaled by ``p["scale"]``,
    time-warped by ``p["speed"]`` (lowered to the fastest warp that still fills the clip) at
    ``CONTROL_HZ``, as captured (not yet on the floor); its start drawn from ``rng`` (the
    fastest of ``WINDOW_CANDIDATES`` draws). With ``task.terrain`` also the scene inferred from
    the whole trial on the body ``model`` (``find_terrain``): its boxes and the trial's ground
    track under the window (n,) [m]; else, or where none is found, None and no boxes. Records
    ``source`` and ``start_tick`` in ``p``.

    Raises:
        MotionDataError: the source trial is unreadable or shorter than one clip.
    """
    qpos = trial_qpos(task.asf, task.amc)  # CMU's 120 Hz = the control rate
    qpos[:, :3] *= p["scale"]
    fit = (len(qpos) - 1) / max(n - 1, 1)  # the fastest replay that still fills the clip
    if p["speed"] > fit >= 0.5:
        p["speed"] = fit
    warped, start = _window(task, p, model, qpos, n, rng)
    p["source"] = str(task.amc)
    p["start_tick"] = start
    window = warped[start : start + n]
    boxes, ground = find_terrain(model, qpos, CONTROL_HZ) if task.terrain else ([], None)
    if not boxes:
        return window, None, []
    # the ground under each warped tick: time_warp's source frames, the same interpolation
    source = np.arange(len(warped)) * p["speed"]
    return window, np.interp(source, np.arange(len(qpos)), ground)[start : start + n], boxes


def placed_reference(
    task, p: dict, body, scene, window: np.ndarray, ground: np.ndarray | None
) -> np.ndarray:
    """The (n, nq) reference the episode tracks: ``window`` (:func:`source_window`) set on its
    floor (``ground``, the trial's ground track under it, where the scene has boxes; else the
    window's own floor track, ``on_floor``), lifted 1 cm or contact-consistent on ``scene``'s
    supports (the whole-body QP's; the sampler's where ``task.contact_reference``),
    foot-locked where ``task.foot_lock`` (on ``body``'s floor, as ``ForwardValidation`` does);
    records ``reference`` in ``p``.

    Raises:
        UsageError: a foot lock asked of a reference that is not contact-consistent.
    """
    c = p["controller"]
    contact = c == "wholebody" or (c == "sampling" and bool(task.contact_reference))
    p["reference"] = "contact-consistent" if contact else "lifted"
    if task.foot_lock and not contact:
        raise UsageError("a foot lock needs the contact-consistent reference")
    placed = _on_ground(body, window, ground, 0.0 if contact else FLOOR_LIFT)
    if contact:  # feet meet the floor: no lift, stance soles on it (held still: foot_lock)
        ref = contact_consistent(scene, flat_soles(scene, placed))
        if task.foot_lock:
            p["reference"] += ", foot-locked"
            return foot_locked(body, ref, CONTROL_HZ)
        return ref
    # the 1 cm lift, and soles near the floor laid flat
    return flat_soles(body, placed)


def _warped(task, model, qpos: np.ndarray, speed: float, n: int) -> np.ndarray:
    """``qpos`` at ``CONTROL_HZ`` time-warped by ``speed``; at least ``n`` ticks long."""
    warped = time_warp(model, qpos, CONTROL_HZ, speed, CONTROL_HZ)
    if len(warped) < n:
        raise MotionDataError(
            str(task.amc), None, f"{len(warped) / CONTROL_HZ:.2f} s after a {speed:.2f}x"
            f" time warp: shorter than one {task.seconds:g} s clip"
        )  # fmt: skip
    return warped


def _window(task, p: dict, model, qpos: np.ndarray, n: int, rng) -> tuple[np.ndarray, int]:
    """The trial ``qpos`` warped by ``p["speed"]`` and the start of the window ``task``'s kind
    picks (:data:`WINDOW_CANDIDATES`, :data:`WINDOW_SPEED_BAND`: the warp moved towards the
    band, the start kept at the same source time where the trial allows; the band and the
    drawn warp recorded in ``p["window_band"]``)."""
    warped = _warped(task, model, qpos, p["speed"], n)
    starts = rng.integers(0, len(warped) - n + 1, WINDOW_CANDIDATES.get(task.kind, 1))
    band = WINDOW_SPEED_BAND.get(task.kind)
    if len(starts) == 1 and band is None:
        return warped, int(starts[0])
    points = body_points(model, warped)
    start = fastest_window(points, n, starts, None if band is None else band[1] / CONTROL_HZ)
    if band is None:
        return warped, start
    floor, cap, highest = band
    p["window_band"] = {"floor": floor, "cap": cap, "highest": highest, "drawn_speed": p["speed"]}
    fast = float(window_steps(points[start : start + n], n, [0])[0]) * CONTROL_HZ  # this one
    speed = p["speed"]
    if fast > cap and speed > 1.0:
        speed = max(1.0, speed * cap / fast)
    elif 0 < fast < floor:
        fit = (len(qpos) - 1) / max(n - 1, 1)
        speed = max(speed, min(fit, highest, speed * floor / fast))
    if speed == p["speed"]:
        return warped, start
    source = start * p["speed"]  # the window's first source tick
    p["speed"] = speed
    warped = _warped(task, model, qpos, speed, n)
    return warped, min(int(round(source / speed)), len(warped) - n)


def _on_ground(body, window: np.ndarray, ground: np.ndarray | None, lift: float) -> np.ndarray:
    """``window`` (n, nq) shifted down by ``ground`` (n,) [m] (None: by ``body``'s floor track
    of it, ``on_floor``) and up by ``lift`` [m]."""
    if ground is None:
        return on_floor(body, window, lift=lift)
    out = window.copy()
    out[:, 2] -= ground - lift
    return out
