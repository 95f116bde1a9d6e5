"""Encoding a take of any length in bounded memory: windows of frames, each an ordinary stream.

The take arrives as consecutive clips (:func:`sim.motion.chunks.stream_clips`). Its 23 protocol
points are buffered until :data:`WINDOW_FRAMES` + :data:`OVERLAP_FRAMES` frames are held; then a
cut frame ``b`` is chosen in the last :data:`OVERLAP_FRAMES` frames of the window, frames
``0..b`` are charted (:func:`sidql.keyframes.spherical.chart_arrays`) and encoded by
:func:`sidql.codec.encode.encode_series` as one ordinary stream, and the buffer goes on from
``b`` (the next stream starts at the frame where this one ends; :mod:`sidql.codec.sequence`).
The cut is the frame of the overlap where the points' path bends most (the largest
``sum_j |p_j[b-1] - 2 p_j[b] + p_j[b+1]|``): a keyframe there is one the plan on either side
wants anyway, so forcing it costs least. A take of at most ``WINDOW_FRAMES + OVERLAP_FRAMES``
frames is one window: one ordinary stream, the same bytes as encoding the whole chart at once.

Each window is encoded to the same target: at a rate, the budget of the take up to the window's
cut (``rate`` times its seconds) less the bytes already written and those the sequence adds, so
what one window leaves unspent the next may use; at an error target
(mean position error, Q), every window meets it, so the take does. Memory: one window's
encoding (the planner's tables and searches grow with its frames) plus the buffer, whatever the
take's length.

Units: frames, bytes, seconds; errors in millimetres and radians.
"""

from __future__ import annotations

import os
import queue
import threading
from dataclasses import dataclass, field, replace

import numpy as np

from sidql.codec.encoded import Encoded
from sidql.codec.sequence import SequenceWriter, overhead_bytes
from sidql.keyframes.spherical import chart_arrays, chart_points_of
from sim.errors import UsageError

#: Frames of one window (at the stream rate): 30 s at 30 fps. The encoder's memory grows with
#: it (about 60 KB a frame at the densest rates, measured: ``benchmarks/bench_codec_memory.py``).
WINDOW_FRAMES = 900
#: Frames of look-ahead past a window in which its cut is chosen.
OVERLAP_FRAMES = 60


@dataclass(frozen=True)
class TakeEncoding:
    """A take encoded window by window.

    Attributes:
        n_frames: frames of the take; fps: stream rate [1/s]; keyframes: keyframes of the take
            (a frame shared by two streams counted once).
        n_bytes: bytes of the file (one stream, or the sequence); bytes_per_second: over the
            take's duration.
        q: Q [rad], mean_error_mm: mean joint position error [mm], both the windows' figures
            weighted by their frames; p95_error_mm: the largest of the windows' 95th percentiles.
        streams: streams written (1: an ordinary ``.sidq`` file, else a sequence).
        reconstructions: reconstruction -> number of windows that chose it.
        first: the first window's encoding (the whole take's when ``streams == 1``).
    """

    n_frames: int
    fps: float
    keyframes: int
    n_bytes: int
    bytes_per_second: float
    q: float
    mean_error_mm: float
    p95_error_mm: float
    streams: int
    reconstructions: dict = field(default_factory=dict)
    first: Encoded | None = None


def cut_frame(P: np.ndarray, lo: int, hi: int) -> int:
    """The frame in ``[lo, hi]`` (1 <= lo <= hi < len(P) - 1) where the points bend most.

    Args:
        P: (N, J, 3) point positions [m].
    """
    b = np.arange(lo, hi + 1)
    bend = np.linalg.norm(P[b - 1] - 2.0 * P[b] + P[b + 1], axis=2).sum(axis=1)
    return int(b[int(np.argmax(bend))])


def windows(clips, window: int = WINDOW_FRAMES, overlap: int = OVERLAP_FRAMES):
    """Yield ``(positions, velocities, parents, dt, source, start, last)`` of each window:
    (n, 23, 3) protocol points [m, m/s] of frames ``start .. start + n - 1`` of the take, the
    last frame of each but the last shared with the next (see the module docstring)."""
    if window < 2 or not 0 <= overlap < window:
        raise UsageError(f"window must be >= 2 frames and overlap in 0..window-1; got "
                         f"{window}, {overlap}")  # fmt: skip
    P = V = None
    start = 0
    for clip in clips:
        pos, vel, parents = chart_points_of(clip)
        P = pos if P is None else np.concatenate([P, pos])
        V = vel if V is None else np.concatenate([V, vel])
        dt, source = clip.dt, clip.source
        while len(P) > window + overlap:
            b = cut_frame(P, max(window - overlap, 1), window)
            yield P[: b + 1], V[: b + 1], parents, dt, source, start, False
            P, V = P[b:].copy(), V[b:].copy()
            start += b
    if P is None:
        raise UsageError("a take needs at least one clip")
    yield P, V, parents, dt, source, start, True


def read_ahead(items, depth: int = 1):
    """The items of the iterator ``items``, each made by a thread of its own while the caller
    works on the one before (reading and charting the next window overlap the encoding of this
    one: the encoder's compiled kernels release the GIL). At most ``depth`` items wait; an
    exception of ``items`` is raised where its item would have come; a caller that stops early
    stops (and closes) ``items``. Without a second core, ``items`` itself."""
    if (os.cpu_count() or 1) < 2:
        yield from items
        return
    done, stop = object(), threading.Event()
    box: queue.Queue = queue.Queue(maxsize=depth)

    def put(item) -> bool:
        while not stop.is_set():
            try:
                box.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce():
        try:
            for item in items:
                if not put((item, None)):
                    break
            else:
                put((done, None))
        except BaseException as e:  # handed to the caller, raised there
            put((None, e))
        finally:
            close = getattr(items, "close", None)  # a generator: its files closed now
            if close is not None:
                close()

    worker = threading.Thread(target=produce, name="read-ahead", daemon=True)
    worker.start()
    try:
        while True:
            item, error = box.get()
            if error is not None:
                raise error
            if item is done:
                return
            yield item
    finally:
        stop.set()
        worker.join()


def encode_windows(f, clips, encode, *, rate=None, window=WINDOW_FRAMES,
                   overlap=OVERLAP_FRAMES, contacts=None, **kwargs) -> TakeEncoding:  # fmt: skip
    """Encode the take ``clips`` window by window into the binary file object ``f``: one
    ordinary stream when it is one window, else a sequence (:mod:`sidql.codec.sequence`).

    Args:
        encode: the encoder of one chart, :func:`sidql.codec.encode.encode_series`.
        rate: byte budget of the whole file [B/s], or None with ``max_q`` / ``max_error`` in
            ``kwargs``; every other keyword as ``encode`` takes it.
        contacts: the whole take's foot-contact side information
            (:class:`sidql.codec.contact_section.FootContacts`, a row of bits per frame) or
            None; each window's encoder is given its frames' rows (``contacts=``).
    """
    writer, parts, reconstructions, first = None, [], {}, None
    overlap = min(overlap, window // 2)
    for P, V, parents, dt, source, start, last in read_ahead(windows(clips, window, overlap)):
        n = len(P)
        fps = 1.0 / dt
        single = last and writer is None
        where = source if single else f"{source} (frames {start}..{start + n - 1})"
        r = rate
        if rate is not None and not single:  # the budget up to this window's end, less the
            owned = start + (n if last else n - 1)  # bytes already written and the container's
            spent = writer.size if writer is not None else overhead_bytes(0) - 12
            budget = rate * owned / fps - spent - 4 - (12 if last else 0)
            r = max(budget, 1.0) * fps / n
        if contacts is not None:
            kwargs["contacts"] = replace(contacts, bits=contacts.bits[start : start + n])
        enc = encode(chart_arrays(P, V, parents, dt), rate=r, where=where, **kwargs)
        del P, V
        first = enc if first is None else first
        rec = enc.stream.reconstruction
        reconstructions[rec] = reconstructions.get(rec, 0) + 1
        parts.append((n, len(enc.stream.keyframes), enc.q, enc.mean_error_mm, enc.p95_error_mm))
        if single:
            f.write(enc.data)
            return _summary(parts, len(enc.data), fps, reconstructions, first)
        writer = SequenceWriter(f) if writer is None else writer
        writer.add(enc.data)
    writer.close()
    return _summary(parts, writer.size, fps, reconstructions, first)


def one_stream(enc: Encoded) -> TakeEncoding:
    """The :class:`TakeEncoding` of a take encoded whole as the one stream ``enc``."""
    s = enc.stream
    part = (s.n_frames, len(s.keyframes), enc.q, enc.mean_error_mm, enc.p95_error_mm)
    return _summary([part], len(enc.data), s.fps, {s.reconstruction: 1}, enc)


def _summary(parts, n_bytes: int, fps: float, reconstructions: dict, first) -> TakeEncoding:
    n = np.array([p[0] for p in parts], dtype=np.float64)
    frames = int(n.sum()) - (len(parts) - 1)
    weights = n / n.sum()
    return TakeEncoding(
        n_frames=frames,
        fps=float(fps),
        keyframes=int(sum(p[1] for p in parts)) - (len(parts) - 1),
        n_bytes=int(n_bytes),
        bytes_per_second=n_bytes * fps / frames,
        q=float(weights @ np.array([p[2] for p in parts])),
        mean_error_mm=float(weights @ np.array([p[3] for p in parts])),
        p95_error_mm=float(max(p[4] for p in parts)),
        streams=len(parts),
        reconstructions=reconstructions,
        first=first,
    )
