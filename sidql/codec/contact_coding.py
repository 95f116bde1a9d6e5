"""Encoding a trial with its foot contacts: the ``contacts`` reconstruction and the ``physics``
keyframes in the codec (``sidql encode --contacts`` / ``--physics``).

The sender, who has the whole trial, estimates its floor once
(:func:`sidql.keyframes.contact_pinning.sender_ground` on the trial: a property of the trial,
not of a clip), labels every frame's foot contacts on it
(:func:`sidql.keyframes.contact_pinning.sender_contacts`) and sends both in the stream's
foot-contact section (:mod:`sidql.codec.contact_section`); the decoder pins each foot in contact.
The section's bytes come out of a ``rate`` budget (the keyframes are encoded at the rate left)
and count in every byte figure.

With ``physics`` the position coding's keyframe programme also pays the physical cost of each
segment (:func:`sidql.keyframes.physical_costs.physical_band`: skating in contact, floor and the
residual force of the cubic-Hermite proxy, each over its scale), banded like the programme's own
costs, times :func:`codec_weight`: the keyframe method's one weight
(:data:`~sidql.keyframes.physical_costs.PHYSICS_WEIGHT`, radians of Q per unit) turned into the
programme's unit (summed point displacement [m]) by the mean over bones of how far all points
move per radian of the bone (:func:`sidql.codec.plan.position_weights`). The rule is carried
over, not re-tuned on the codec.

Errors reported (``q``, ``mean_error_mm``, ``p95_error_mm``) are those of the decoded, pinned
points against the trial's chart. Units: metres, seconds, bytes; world axes z up.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sidql.codec import format as sidq
from sidql.codec.contact_section import FootContacts
from sidql.codec.decode import decoded_chart
from sidql.codec.encode import encode_series
from sidql.codec.encoded import Encoded
from sidql.codec.plan import DEFAULT_MAX_GAP, position_weights
from sidql.keyframes.contact_pinning import (
    decode_floor,
    encode_floor,
    pin_feet,
    sender_contacts,
    sender_ground,
)
from sidql.keyframes.metrics import q_from_angles
from sidql.keyframes.physical_costs import PHYSICS_WEIGHT, physical_band, scaled, segment_inputs
from sidql.keyframes.spherical import (
    POINTS,
    SphericalSeries,
    chart,
    chart_arrays,
    protocol_maps,
    split_channels,
)
from sidql.keyframes.unchart import positions_from_chart
from sim.errors import UnmetTargetError, UsageError
from sim.motion.clip import Clip
from sim.physics.feet import SIDES


def trial_contacts(clip: Clip, ground=None) -> FootContacts:
    """The sender's foot-contact side information of a whole trial: its floor (estimated once,
    on the whole trial, unless ``ground`` is given) as float32, and the (N, 2) bits on it."""
    if ground is None:
        ground = sender_ground(clip)
    return FootContacts(sender_contacts(clip, ground), decode_floor(encode_floor(ground)))


def codec_weight(series: SphericalSeries, weight: float = PHYSICS_WEIGHT) -> float:
    """[m per unit of the physical cost] ``weight`` [rad per unit] times the mean over bones of
    the points' displacement per radian of the bone [m/rad] (see the module docstring)."""
    return float(weight * position_weights(series.lengths, series.parents).mean())


def physical_cost_band(
    clip: Clip, series: SphericalSeries, G: int, ground=None, weight: float = PHYSICS_WEIGHT
) -> np.ndarray:
    """(N, G + 1) [m] the physical cost of every segment ``(i, i + g)``, ``g <= G``, in the
    position coding's unit (:func:`codec_weight` of ``weight`` times the scaled terms);
    ``ground``: the trial's floor (default: estimated here)."""
    if ground is None:
        ground = sender_ground(clip)
    terms = physical_band(segment_inputs(clip, ground=ground), G)
    return codec_weight(series, weight) * scaled(terms)


def encode_with_contacts(
    clip: Clip,
    *,
    physics: bool = False,
    weight: float = PHYSICS_WEIGHT,
    rate: float | None = None,
    max_gap: int = DEFAULT_MAX_GAP,
    latency: int = 0,
    **kwargs,
) -> Encoded:
    """:func:`sidql.codec.encode.encode_series` of the trial's chart with its foot-contact
    section (and, with ``physics``, the physical cost times ``weight`` [rad of Q per unit,
    :func:`codec_weight`] in the keyframe programme); ``rate``
    [B/s] is the whole file's, section included. Other arguments as ``encode_series``'.

    Raises:
        UsageError: a latency (the section ends the stream: a live decoder would not have it in
            time); UnmetTargetError: the section alone exceeds the rate.
    """
    if latency:
        raise UsageError("foot contacts need an offline stream (latency 0)")
    series = chart(clip)
    ground = sender_ground(clip)  # once per trial
    side = trial_contacts(clip, ground)
    G = min(max_gap, sidq.MAX_GAP)
    extra = physical_cost_band(clip, series, G, ground, weight) if physics else None
    return encode_chart_with_contacts(
        series, contacts=side, rate=rate, max_gap=max_gap, where=clip.source, extra_cost=extra,
        **kwargs,
    )  # fmt: skip


def encode_chart_with_contacts(
    series: SphericalSeries,
    *,
    contacts: FootContacts,
    rate: float | None = None,
    where: str = "",
    latency: int = 0,
    **kwargs,
) -> Encoded:
    """:func:`sidql.codec.encode.encode_series` of ``series`` with the foot-contact section
    ``contacts`` (its bits: one row per frame of ``series``); ``rate`` [B/s] is the stream's,
    section included. The errors reported are the decoded, pinned points'."""
    if latency:
        raise UsageError("foot contacts need an offline stream (latency 0)")
    duration = series.n_frames * series.dt
    left = None if rate is None else rate - contacts.n_bytes / duration
    if left is not None and left <= 0:
        raise UnmetTargetError(
            f"{where}: the foot contacts alone take {contacts.n_bytes / duration:.1f} B/s "
            f"of the {rate:g} B/s budget"
        )
    enc = encode_series(series, rate=left, where=where, **kwargs)
    stream = replace(enc.stream, contacts=contacts)
    data = sidq.to_bytes(stream)
    q, mean_mm, p95_mm = pinned_errors(series, stream)
    return replace(
        enc, stream=stream, data=data, q=q, bytes_per_second=len(data) / duration,
        mean_error_mm=mean_mm, p95_error_mm=p95_mm,
    )  # fmt: skip


#: The points the floor and the contact labels read: per foot the ankle, ball and toe tip
#: (:func:`sim.physics.feet.sole`, :func:`sim.physics.contacts.motion_contacts`).
FOOT_NAMES: tuple[str, ...] = tuple(s + p for s in SIDES for p in ("tibia", "foot", "toes"))


@dataclass(frozen=True)
class FootTrack:
    """A take's foot points, every frame: what :func:`sender_ground` and
    :func:`sender_contacts` read of a clip (the same floor and labels as on the whole clip).

    Attributes:
        names: (K,) point names (of :data:`FOOT_NAMES`); positions, velocities: (T, K, 3)
            [m, m/s]; fps [1/s]; source: the file read.
    """

    names: tuple[str, ...]
    positions: np.ndarray
    velocities: np.ndarray
    fps: float
    source: str = ""

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]


#: Frames (at the stream rate) of a take whose 23 protocol points the foot pass keeps for the
#: windows, so that a take of up to this length is read once, not twice: 10 minutes at 30 fps,
#: 552 bytes a frame of positions (~10 MB; twice that where the windows need velocities). A longer
#: take's points are dropped when it passes this length and the take is read again.
KEPT_FRAMES = 18000


def foot_track(clips) -> FootTrack:
    """The :class:`FootTrack` of the take ``clips`` (consecutive clips, read one at a time:
    6 points a frame are kept, 288 bytes, not the whole clip)."""
    return foot_pass(clips)[0]


def foot_pass(clips, *, keep: int = 0, velocities: bool = False):
    """``(track, kept)``: the :class:`FootTrack` of the take ``clips`` (as :func:`foot_track`)
    and, when the take has at most ``keep`` frames, its clips on the 23 protocol points alone
    (:func:`protocol_only`; velocities kept when ``velocities``, else zero), else None."""
    P, V, names, fps, source = [], [], (), 30.0, ""
    kept, frames = [], 0
    for clip in clips:
        idx = [i for i, n in enumerate(clip.names) if n in FOOT_NAMES]
        names, fps, source = tuple(clip.names[i] for i in idx), clip.fps, clip.source
        P.append(np.ascontiguousarray(clip.positions[:, idx]))
        V.append(np.ascontiguousarray(clip.velocities[:, idx]))
        frames += clip.n_frames
        if kept is not None and frames <= keep:
            kept.append(protocol_only(clip, velocities))
        else:
            kept = None  # too long to keep: read again
    if not P:
        raise UsageError("a take needs at least one clip")
    return FootTrack(names, np.concatenate(P), np.concatenate(V), fps, source), kept


def protocol_only(clip: Clip, velocities: bool = False) -> Clip:
    """``clip`` on its 23 protocol points (:data:`~sidql.keyframes.spherical.POINTS`): their
    positions [m] (a copy), their velocities [m/s] when ``velocities`` (else zero, as a read
    without velocities gives them); no joint angles (``qpos``, ``qvel`` of width 0) and
    identity rotations: what :func:`sidql.codec.windows.windows` reads of a clip, in 552 bytes
    a frame (1104 with velocities)."""
    idx, parents = protocol_maps(clip)
    T = clip.n_frames
    pos = clip.positions[:, idx]
    vel = clip.velocities[:, idx] if velocities else np.broadcast_to(0.0, pos.shape)
    return Clip(
        names=POINTS, parents=np.array(parents, dtype=np.int64), positions=pos, velocities=vel,
        qpos=np.empty((T, 0)), qvel=np.empty((T, 0)),
        rotations=np.broadcast_to(np.array([1.0, 0.0, 0.0, 0.0]), (T, len(POINTS), 4)),
        fps=clip.fps, source=clip.source, start_frame=clip.start_frame,
        source_fps=clip.source_fps,
    )  # fmt: skip


def streamed_contacts(clips, again=None, *, velocities: bool = False, keep: int = KEPT_FRAMES):
    """``(contacts, encode, windows)`` of the take ``clips`` (a read of its own, with
    velocities): the whole take's :class:`FootContacts` (floor estimated once on every frame,
    bits labelled on it: the same as :func:`trial_contacts` of the whole clip), the encoder of
    one window's chart with its slice of them (:func:`encode_chart_with_contacts`), for
    :func:`sidql.codec.windows.encode_windows`, and the take's clips for the windows: those of
    this read on the protocol points (:func:`protocol_only`) for a take of at most ``keep``
    frames, else ``again`` (a second read of the take, ``velocities`` as the windows need)."""
    track, kept = foot_pass(clips, keep=keep, velocities=velocities)
    return trial_contacts(track), encode_chart_with_contacts, again if kept is None else kept


def pinned_errors(series: SphericalSeries, stream: sidq.Stream) -> tuple[float, float, float]:
    """Q [rad] (eq. 18) and the mean and 95th-percentile Euclidean point error [mm] of the
    decoded (pinned) stream against the true chart ``series``.

    The decoded positions are :func:`sidql.codec.decode.reconstruct_stream`'s (the same
    operations: its chart, its points, :func:`pin_feet` on the stream's bits, keyframes and
    floor), without the velocities and accelerations neither figure reads (Q reads the angles,
    which the chart takes from positions alone)."""
    chart = decoded_chart(stream)
    theta, phi, root = split_channels(chart["values"], stream.quantiser.n_bones)
    dtheta, dphi, root_vel = split_channels(chart["rates"], stream.quantiser.n_bones)
    del chart
    P = positions_from_chart(root, root_vel, theta, phi, dtheta, dphi, stream.lengths,
                             stream.parents)[0]  # fmt: skip
    c = stream.contacts
    P = pin_feet(P, c.bits, stream.keyframes, stream.fps, floor=c.floor)
    truth, _ = positions_from_chart(
        series.root_pos, series.root_vel, series.theta, series.phi, series.dtheta, series.dphi,
        series.lengths, series.parents,
    )  # fmt: skip
    E = 1e3 * np.linalg.norm(P - truth, axis=-1)
    s = chart_arrays(P, np.zeros_like(P), series.parents, series.dt)
    return q_from_angles(series, s.theta, s.phi), float(E.mean()), float(np.percentile(E, 95))
