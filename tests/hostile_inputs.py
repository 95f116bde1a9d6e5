"""Hostile inputs of every file type the commands read, and the property every reader keeps.

Shared by ``tests/test_fuzz.py`` (hypothesis drives the choices) and
``benchmarks/fuzz_campaign.py`` (a seeded ``random.Random`` drives them, each input in its own
process under a memory and time limit). A source of choices needs only ``randrange(n)``.

File types (:data:`KINDS`): ASF, AMC and BVH (the mutators of ``acclaim_mutations``), ``.sidq``
streams and sequences of them (``tests/hostile_sequences.py``), clip ``.npz`` files, dataset folders (``index.json`` with its clips and skeletons),
policy files and training checkpoints. Each input is a :class:`Case`: a few files (bytes, or a
FIFO, a directory, a symbolic link to ``/dev/zero`` or to a file outside the folder) made from
real seeds (:func:`build_seeds`: CMU trials, their encodings and clips, a trained policy and
checkpoint) by byte-level and format-aware mutations (header fields, counts, decompression
bombs, lying array headers, overlapping zip members, tampered tensors and settings...).

The property (:func:`run_case`): reading a case either raises
:class:`~sim.errors.BadFileError` (MotionDataError, ModelFileError) naming a file inside the case's folder (and, when it gives a
line, one that exists), in one printable line of bounded length that quotes nothing of a file
outside the folder, or returns values that are all finite (decisions that are valid keyframes,
a checkpoint that resumes and trains a step). Anything else raises: :class:`Breach` for a broken
property, the exception itself for a foreign one.
"""

from __future__ import annotations

import copy
import dataclasses
import io
import json
import lzma
import os
import pickle
import struct
import warnings
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from acclaim_mutations import Breach, line_count, mutate, non_finite, read_all, seed_amc

from sim.acclaim.asf import check_bone_name
from sim.errors import BadFileError

KINDS = ("asf", "amc", "bvh", "sidq", "sidm", "npz", "index", "policy", "checkpoint")
CANARY = b"CANARY-7f3a9"  # the content of every file outside a case's folder
MAX_PROBLEM_CHARS = 600  # an error's problem: one short line


# ------------------------------------------------------------------------------------ seeds


@dataclass
class Seeds:
    """Real inputs to mutate (bytes), built once by :func:`build_seeds`."""

    acclaim: list  # (trial, ASF bytes, AMC bytes cut to 30 frames)
    sidq: list  # encoded streams: offline (three reconstructions) and live
    clips: list  # clip files: an ingested trial, a synthetic clip with labels
    dataset: dict  # a dataset folder: relative path -> bytes
    policies: list  # the shipped policy, a small trained one
    checkpoint: bytes
    checkpoint_args: dict  # the Args of the checkpoint's run (out is set per case)
    bvh: list = field(default_factory=list)  # a CMU trial written as BVH, a non-CMU skeleton


def build_seeds(cmu_dir: Path, work: Path, trials=(("02", "02_01"), ("07", "07_12"))) -> Seeds:
    """Seeds from the real CMU files under ``cmu_dir`` (scratch files go to ``work``)."""
    import torch

    from sidql.codec.encode import encode_clip
    from sidql.codec.format import to_bytes
    from sidql.learning.dqn import train
    from sidql.learning.policy import DEFAULT_POLICY
    from sidql.learning.settings import Args
    from sim.motion.clip import save_npz
    from sim.motion.ingest import load_motion

    work.mkdir(parents=True, exist_ok=True)
    acclaim = []
    for subject, trial in trials:
        asf = (cmu_dir / subject / f"{subject}.asf").read_bytes()
        amc = seed_amc((cmu_dir / subject / f"{trial}.amc").read_bytes())
        acclaim.append((trial, asf, amc))
    clip = load_motion(cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc")
    short = clip.slice(0, 40)
    sidq = [encode_clip(short, rate=4000, reconstruction=r).data for r in ("hermite", "linear")]
    sidq.append(encode_clip(short, max_q=0.02, reconstruction="catmull_rom").data)
    live = encode_clip(short, rate=40000, reconstruction="hermite", latency=8).stream
    sidq.append(to_bytes(live))
    clips = []
    for c, extra in ((short, None), (clip.slice(0, 20), {"sim_actions": np.ones((20, 4))})):
        save_npz(c, work / "seed.npz", extra=extra)
        clips.append((work / "seed.npz").read_bytes())
    save_npz(clip, work / "seed.npz")
    dataset = {
        "index.json": json.dumps(
            {
                "source": "/nowhere",
                "skeleton": "subject",
                "fps": 30.0,
                "trials": [
                    {
                        "subject": "02",
                        "trial": "02_01",
                        "asf": "02/skeleton-0.asf",
                        "amc": "02/02_01.amc",
                        "file": "02/02_01.npz",
                        "frames": clip.n_frames,
                        "fps": 30.0,
                        "notes": [],
                    }
                ],
                "skipped": [],
            }
        ).encode(),  # fmt: skip
        "02/02_01.npz": (work / "seed.npz").read_bytes(),
        "02/skeleton-0.asf": (cmu_dir / "02" / "02.asf").read_bytes(),
    }
    args = Args(
        out=str(work / "run" / "p.pt"), steps=24, synthetic_tasks=8, keyframe_counts=(4,),
        batch_size=8, buffer_size=40, learning_starts=8, n_envs=2, demo_episodes=2,
        eval_every=24, progress=False, hidden=8, seed=3,
    )  # fmt: skip
    torch.set_num_threads(1)
    train(args)
    policies = [Path(DEFAULT_POLICY).read_bytes(), (work / "run" / "p.pt").read_bytes()]
    checkpoint = (work / "run" / "p.pt.ckpt").read_bytes()
    return Seeds(
        acclaim,
        sidq,
        clips,
        dataset,
        policies,
        checkpoint,
        dataclasses.asdict(args),
        bvh_seeds(cmu_dir),
    )


def bvh_seeds(cmu_dir: Path) -> list[bytes]:
    """Subject 02's walk cut to 30 frames, written as BVH; a figure of non-CMU names, channel
    counts and orders (``tests/bvh_files.py``)."""
    from bvh_files import bvh_text, creature, motion

    from sim.bvh.writer import bvh_text as write_text
    from sim.motion.trial import read_trial

    skeleton, take, _ = read_trial(cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc")
    take = dataclasses.replace(
        take, root=take.root[:30], angles={k: v[:30] for k, v in take.angles.items()}
    )
    nodes = creature()
    return [
        write_text(skeleton, take, 120.0).encode(),
        bvh_text(nodes, motion(nodes, 30, 60.0), 60.0).encode(),
    ]


# ------------------------------------------------------------------------------------ cases


@dataclass
class Case:
    """One hostile input: ``files`` (relative path -> bytes, or ``("fifo",)``, ``("dir",)``,
    ``("link", target)`` with target ``"/dev/zero"`` or ``"@outside"``, a file outside the
    folder holding :data:`CANARY`), the file under test ``target``, the mutations ``ops``."""

    kind: str
    files: dict
    target: str
    ops: list = field(default_factory=list)
    full: bool = False  # ASF/AMC: also model build, retargeting and velocities
    skeleton: str = "subject"


def _pick(rng, seq):
    return seq[rng.randrange(len(seq))]


SPECIAL_FILES = (("fifo",), ("dir",), ("link", "/dev/zero"), ("link", "@outside"))


def make_case(kind: str, seeds: Seeds, rng) -> Case:
    """A random hostile input of ``kind`` (deterministic in the choices of ``rng``)."""
    return _MAKERS[kind](seeds, rng)


def seed_case(kind: str, seeds: Seeds) -> Case:
    """The first seed of ``kind``, unchanged (a good file: it must read)."""
    trial, asf, amc = seeds.acclaim[0]
    files = {
        "asf": {"t.asf": asf, "t.amc": amc},
        "amc": {"t.asf": asf, "t.amc": amc},
        "bvh": {"t.bvh": seeds.bvh[0]},
        "sidq": {"s.sidq": seeds.sidq[0]},
        "sidm": {"s.sidq": _sidm().sidm_seeds(seeds)[0]},
        "npz": {"c.npz": seeds.clips[0]},
        "index": {f"d/{k}": v for k, v in seeds.dataset.items()},
        "policy": {"p.pt": seeds.policies[0]},
        "checkpoint": {"run/p.pt.ckpt": seeds.checkpoint},
    }[kind]
    target = {"asf": "t.asf", "amc": "t.amc", "index": "d"}.get(kind, next(iter(files)))
    return Case(kind, files, target, ["seed"], full=kind in ("asf", "amc"))


def _sidm():
    """``tests/hostile_sequences.py`` (sequences of streams), imported when first needed."""
    import hostile_sequences

    return hostile_sequences


def _special(rng) -> tuple | None:
    """One time in 25: the file is no regular file at all (or a link leaving the folder)."""
    return _pick(rng, SPECIAL_FILES) if rng.randrange(25) == 0 else None


def _acclaim_case(kind: str):
    def make(seeds: Seeds, rng) -> Case:
        trial, asf, amc = _pick(rng, seeds.acclaim)
        ops = []
        both = rng.randrange(8) == 0
        if kind == "asf" or both:
            asf, m = mutate(asf, rng)
            ops += [f"asf:{x}" for x in m]
        if kind == "amc" or both:
            amc, m = mutate(amc, rng)
            ops += [f"amc:{x}" for x in m]
        files = {"t.asf": asf, "t.amc": amc}
        special = _special(rng)
        if special:
            files[f"t.{kind}"] = special
            ops.append(f"{kind}:{special[0]}:{special[-1]}")
        full = rng.randrange(4) == 0
        skeleton = "humanoid" if full and rng.randrange(2) else "subject"
        return Case(kind, files, f"t.{kind}", ops, full, skeleton)

    return make


def _bvh_case(seeds: Seeds, rng) -> Case:
    data, ops = mutate(_pick(rng, seeds.bvh), rng)
    files = {"t.bvh": data}
    special = _special(rng)
    if special:
        files["t.bvh"] = special
        ops.append(f"special:{special[-1]}")
    return Case("bvh", files, "t.bvh", ops, full=rng.randrange(4) == 0)


# --- .sidq -------------------------------------------------------------------------------------

F32_SPECIALS = (float("nan"), float("inf"), -float("inf"), 0.0, -1.0, 1e-45, 1e30, 3.4e38,
                999.9, 1000.1, 1e4, 1e5)  # fmt: skip
U32_SPECIALS = (0, 1, 2, 3, 255, 256, 1 << 15, (1 << 15) + 1, 1 << 16, 10**7, (1 << 32) - 1)


def _sidq_layout(data: bytes) -> dict:
    """Offsets of a valid stream's fields: header fields, lengths, origin, steps, body."""
    from sidql.codec.format import from_bytes

    s = from_bytes(data)
    J, M = len(s.names), len(s.names) - 1
    standard = data[22] == 0
    pos = 23 if standard else 23 + sum(1 + len(n) for n in s.names) + J
    out = {"lengths": (pos, M), "origin": (pos + 4 * M, 3), "step": (pos + 4 * M + 12, 3)}
    pos += 4 * M + 24
    if s.reconstruction == "hermite":
        out["rate_step"] = (pos, 2 * M + 3)
        pos += 4 * (2 * M + 3)
    out["body"] = pos
    out["coding"] = s.coding
    return out


def _fix_crc(data: bytes) -> bytes:
    body = data[:-4]
    return body + struct.pack("<I", zlib.crc32(body))


def _long_stream(data: bytes, rng) -> bytes:
    """``data``'s stream stretched to the frame limit (one keyframe a frame or gaps of up to
    255) with smooth codes, so that it packs small; or one frame past the limit."""
    from sidql.codec import format as sidq

    s = sidq.from_bytes(data)
    limit = sidq.frame_limit(len(s.names))
    gap = _pick(rng, (1, 1, 7, 255))
    frames = limit + (1 if rng.randrange(4) == 0 else 0)
    keys = np.unique(np.r_[np.arange(0, frames - 1, gap), frames - 1])
    W, D = len(keys), s.pose_codes.shape[1]
    walk = np.cumsum(np.random.default_rng(rng.randrange(1 << 30)).integers(-3, 4, (W, D)), 0)
    top = (1 << s.quantiser.bits) - 1
    pose = np.clip(walk + top // 2, 0, top).astype(np.uint16)
    rate = np.zeros((W, D), np.int16) if s.rate_codes is not None else None
    stream = dataclasses.replace(s, keyframes=keys, pose_codes=pose, rate_codes=rate)
    if frames > limit:  # to_bytes refuses it: write it as the encoder of another program might
        body = sidq.header_bytes(stream) + (
            sidq.packed_bytes(stream) if s.coding == 1 else sidq.record_bytes(stream)
        )
        return body + struct.pack("<I", zlib.crc32(body))
    return sidq.to_bytes(stream)


def _sidq_case(seeds: Seeds, rng) -> Case:
    data = _pick(rng, seeds.sidq)
    lay = _sidq_layout(data)
    op = _pick(rng, ("bytes", "bytes", "field", "floats", "count", "payload", "bomb", "long"))
    b = bytearray(data)
    if op == "long":  # a valid stream as long as the limit allows (or one frame more)
        new, ops = _long_stream(data, rng), ["long"]
    elif op == "bytes":
        new, ops = mutate(data, rng)
        ops = [f"bytes:{x}" for x in ops]
    elif op == "field":
        which = _pick(rng, ("version", "recon", "coding", "bits", "latency", "fps", "J"))
        if which == "fps":
            b[10:14] = struct.pack("<f", _pick(rng, F32_SPECIALS))
        elif which == "latency":
            b[8:10] = struct.pack("<H", _pick(rng, (0, 1, 255, 65535)))
        else:
            at = {"version": 4, "recon": 5, "coding": 6, "bits": 7, "J": 22}[which]
            b[at] = _pick(rng, (0, 1, 2, 3, 7, 8, 16, 17, 23, 24, 127, 128, 255))
        new, ops = bytes(b), [f"field:{which}"]
    elif op == "floats":
        which = _pick(rng, [k for k in ("lengths", "origin", "step", "rate_step") if k in lay])
        pos, n = lay[which]
        i = rng.randrange(n)
        b[pos + 4 * i : pos + 4 * i + 4] = struct.pack("<f", _pick(rng, F32_SPECIALS))
        new, ops = bytes(b), [f"floats:{which}"]
    elif op == "count" and lay["coding"] == 1:
        at = lay["body"]
        b[at : at + 4] = struct.pack("<I", _pick(rng, U32_SPECIALS))
        new, ops = bytes(b), ["count"]
    elif op == "count":  # live records: bytes added or dropped inside the records
        cut = lay["body"] + rng.randrange(max(1, len(data) - 4 - lay["body"]))
        if rng.randrange(2):
            new = data[:cut] + bytes(_pick(rng, (1, 2, 95, 189))) + data[cut:]
        else:
            new = data[:cut] + data[cut + _pick(rng, (1, 95, 189)) :]
        ops = ["records"]
    else:  # payload / bomb: replace the packed keyframes
        at = lay["body"]
        if op == "payload" and lay["coding"] == 1:
            raw = bytearray(lzma.decompress(data[at + 4 : -4], format=lzma.FORMAT_ALONE))
            for _ in range(1 + rng.randrange(4)):
                if raw:
                    raw[rng.randrange(len(raw))] = _pick(rng, (0, 1, 255, 0x80))
            if rng.randrange(3) == 0:
                raw = raw[: rng.randrange(len(raw) + 1)]
            w = struct.unpack("<I", data[at : at + 4])[0]
        else:  # zeros: a stream that inflates far beyond what it declares (or declares a lot)
            n = 1 << (10 + rng.randrange(15))
            raw = bytes(n)
            w = _pick(rng, (2, 1 << 15, n, (1 << 32) - 1))
        filt = [{"id": lzma.FILTER_LZMA1, "preset": 1,
                 "dict_size": _pick(rng, (1 << 12, 1 << 20, 1 << 26))}]  # fmt: skip
        packed = lzma.compress(bytes(raw), format=lzma.FORMAT_ALONE, filters=filt)
        new = data[:at] + struct.pack("<I", w) + packed + data[-4:]
        ops = [f"{op}:{len(raw)}:{w}"]
    return _stream_case(rng, "sidq", new, ops)


def _stream_case(rng, kind: str, new: bytes, ops: list, fixable: bool = True) -> Case:
    """The case of a damaged stream ``new`` as ``s.sidq``: its CRC made right again in 8 of 10
    (where ``fixable``), or the file swapped for a special one (a link, a folder, ...)."""
    if rng.randrange(10) < 8 and fixable:
        new = _fix_crc(new)
        ops.append("crc")
    files = {"s.sidq": new}
    special = _special(rng)
    if special:
        files["s.sidq"] = special
        ops.append(f"special:{special[-1]}")
    return Case(kind, files, "s.sidq", ops)


# --- clip .npz -----------------------------------------------------------------------------------


def _npz_bytes(arrays: dict, compress: bool, rng=None) -> bytes:
    buf = io.BytesIO()
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    with zipfile.ZipFile(buf, "w", method) as z:
        for k, v in arrays.items():
            member = io.BytesIO()
            np.save(member, v, allow_pickle=True)
            z.writestr(k + ".npy", member.getvalue())
    return buf.getvalue()


def _arrays(data: bytes) -> dict:
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _array_mutation(a: dict, rng) -> str:
    """Change one array of a clip's arrays in place; returns what was done."""
    key = _pick(rng, sorted(a))
    v = a[key]
    op = _pick(rng, ("drop", "dtype", "shape", "values", "parents", "scalar", "strings",
                     "object", "junk"))  # fmt: skip
    if op == "drop":
        del a[key]
    elif op == "dtype":
        dtype = _pick(rng, (np.float32, np.int64, np.bool_, np.uint8, "<U3", ">f8", np.complex64,
                            np.float16))  # fmt: skip
        try:
            a[key] = v.astype(dtype)
        except (ValueError, TypeError):  # text that is no number: zeros of that type
            a[key] = np.zeros(v.shape, dtype)
    elif op == "shape":
        how = rng.randrange(5)
        if how == 0 and v.ndim:
            a[key] = v[: rng.randrange(v.shape[0] + 1)]
        elif how == 1:
            a[key] = v[None]
        elif how == 2 and v.ndim > 1:
            a[key] = np.ascontiguousarray(np.swapaxes(v, 0, 1))
        elif how == 3:
            a[key] = v.reshape(-1)
        else:
            a[key] = np.asfortranarray(v) if v.ndim > 1 else np.zeros((0,) + v.shape[1:], v.dtype)
    elif op == "values" and v.dtype.kind == "f" and v.size:
        flat = v.reshape(-1).copy()
        flat[rng.randrange(flat.size)] = _pick(rng, (np.nan, np.inf, -np.inf, 1e308, -0.0))
        a[key] = flat.reshape(v.shape)
    elif op == "parents" and "parents" in a:
        p = a["parents"].copy()
        if p.size:
            p.flat[rng.randrange(p.size)] = _pick(rng, (-5, -1, 0, p.size, 10**9, 1))  # any shape
        a["parents"] = p
    elif op == "scalar":
        which = _pick(rng, ("fps", "source_fps", "start_frame"))
        a[which] = np.array(_pick(rng, (0, -1, np.nan, np.inf, 1e30, 2**62, 30)))
    elif op == "strings":
        which = _pick(rng, ("names", "joint_names", "source"))
        if which in a:
            a[which] = np.array(a[which]).astype(f"<U{_pick(rng, (1, 300, 5000))}")
            if a[which].ndim:
                a[which] = np.array(["\x1b[31m" + "x" * 200] * len(a[which]))
    elif op == "object":
        a[key] = np.array([{"a": 1}, None], dtype=object)
    else:
        a[_pick(rng, ("extra", "sim_x", "0"))] = np.zeros(rng.randrange(1, 10**5))
    return f"{op}:{key}"


def _lying_header(data: bytes, rng) -> bytes:
    """Rewrite one stored member's npy header to another shape, keeping its data."""
    src = zipfile.ZipFile(io.BytesIO(data))
    names = src.namelist()
    victim = _pick(rng, names)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as z:
        for n in names:
            raw = src.read(n)
            if n == victim and raw[:6] == b"\x93NUMPY":
                hlen = struct.unpack("<H", raw[8:10])[0]
                shape = _pick(rng, ("(1000000000, 31, 3)", "(2, 2)", "()", "(-1,)", "(5,)",
                                    "(1 << 40,)", "(3, 3, 3, 3, 3)", "(0,)"))  # fmt: skip
                header = "{'descr': '" + _pick(rng, ("<f8", "|O", "<U9999999", "V8", "<i8"))
                header += f"', 'fortran_order': False, 'shape': {shape}, }}"
                header = header.ljust(hlen - 1) + "\n" if len(header) < hlen else header + "\n"
                raw = raw[:8] + struct.pack("<H", len(header)) + header.encode() + raw[10 + hlen :]
            z.writestr(n, raw)
    return buf.getvalue()


def _deflate_bomb(data: bytes, rng) -> bytes:
    """The clip's arrays plus one member of zeros, deflated (inflates ~1000x its size)."""
    n = 1 << (16 + rng.randrange(12))  # up to 128 MB of zeros
    buf = io.BytesIO(data)
    with zipfile.ZipFile(buf, "a", zipfile.ZIP_DEFLATED) as z, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "Duplicate name": on purpose
        name = _pick(rng, ("positions.npy", "bomb.npy", "sim_bomb.npy"))
        header = io.BytesIO()
        np.lib.format.write_array_header_1_0(
            header, {"descr": "<f8", "fortran_order": False, "shape": (n // 8,)}
        )
        info = zipfile.ZipInfo(name)
        info.compress_type = zipfile.ZIP_DEFLATED
        with z.open(info, "w", force_zip64=True) as f:
            f.write(header.getvalue())
            chunk = bytes(1 << 20)
            for _ in range(n >> 20):
                f.write(chunk)
            f.write(bytes(n & ((1 << 20) - 1)))
    return buf.getvalue()


def _zip_structure(data: bytes, rng) -> tuple[bytes, str]:
    """Zip-level damage: overlapping or repeated members, encrypted flag, other compression."""
    op = _pick(rng, ("overlap", "repeat", "encrypted", "method", "nonnpy"))
    if op in ("overlap", "repeat"):  # the central directory's first entry, twice
        src = zipfile.ZipFile(io.BytesIO(data))
        info = src.infolist()[0]
        eocd = data.rfind(b"PK\x05\x06")
        cd_size, cd_off = struct.unpack("<II", data[eocd + 12 : eocd + 20])
        first = data[cd_off : cd_off + 46 + len(info.filename) + len(info.extra)]
        entry = bytearray(first)
        if op == "overlap":
            entry[46 : 46 + 1] = b"z"  # another name, the same data
        count = struct.unpack("<H", data[eocd + 10 : eocd + 12])[0] + 1
        cd = data[cd_off : cd_off + cd_size] + bytes(entry)
        tail = bytearray(data[eocd:])
        tail[8:10] = struct.pack("<H", count)
        tail[10:12] = struct.pack("<H", count)
        tail[12:16] = struct.pack("<I", len(cd))
        return data[:cd_off] + cd + bytes(tail), op
    if op == "encrypted":
        b = bytearray(data)
        cd = data.find(b"PK\x01\x02")
        b[cd + 8] |= 1
        return bytes(b), op
    if op == "method":
        b = bytearray(data)
        cd = data.find(b"PK\x01\x02")
        b[cd + 10 : cd + 12] = struct.pack("<H", _pick(rng, (12, 14, 99, 8)))
        return bytes(b), op
    buf = io.BytesIO(data)
    with zipfile.ZipFile(buf, "a") as z:
        z.writestr(_pick(rng, ("readme.txt", "../x.npy", "a/b.npy", ".npy")), b"x" * 10)
    return buf.getvalue(), op


def _npz_case(seeds: Seeds, rng) -> Case:
    data = _pick(rng, seeds.clips)
    op = _pick(rng, ("bytes", "arrays", "arrays", "arrays", "header", "bomb", "zip"))
    if op == "bytes":
        new, m = mutate(data, rng)
        ops = [f"bytes:{x}" for x in m]
    elif op == "arrays":
        a = _arrays(data)
        ops = [_array_mutation(a, rng) for _ in range(1 + rng.randrange(2))]
        new = _npz_bytes(a, compress=rng.randrange(2) == 0)
    elif op == "header":
        new, ops = _lying_header(_npz_bytes(_arrays(data), False), rng), ["header"]
    elif op == "bomb":
        new, ops = _deflate_bomb(data, rng), ["bomb"]
    else:
        new, what = _zip_structure(data, rng)
        ops = [f"zip:{what}"]
    files = {"c.npz": new}
    special = _special(rng)
    if special:
        files["c.npz"] = special
        ops.append(f"special:{special[-1]}")
    return Case("npz", files, "c.npz", ops)


# --- dataset folders (index.json) -------------------------------------------------------------

ENTRY_NAMES = ("/etc/passwd", "../outside/secret.npz", "../../outside/secret.npz", "02/../../x",
               "02/link-out.npz", "02/missing.npz", "", "02", "02/02_01.npz/..", "a" * 5000,
               "02/\x00.npz", "\x1b[2J.npz", "02/fifo.npz", "C:\\x.npz", "//server/x.npz")  # fmt: skip


def _index_case(seeds: Seeds, rng) -> Case:
    files = {f"d/{k}": v for k, v in seeds.dataset.items()}
    index = json.loads(seeds.dataset["index.json"])
    op = _pick(rng, ("bytes", "entry", "entry", "shape", "fs", "clip"))
    ops = [op]
    if op == "bytes":
        new, m = mutate(files["d/index.json"], rng)
        files["d/index.json"] = new
        ops += m
    elif op == "entry":
        entry = index["trials"][0]
        key = _pick(rng, ("file", "asf", "subject", "amc", "frames", "task"))
        entry[key] = _pick(rng, (*ENTRY_NAMES, None, 5, 1e308, [], {"a": 1}, True))
        if rng.randrange(3) == 0:
            index["trials"].append(copy.deepcopy(entry))
        files["d/02/link-out.npz"] = ("link", "@outside")
        files["d/02/fifo.npz"] = ("fifo",)
        files["d/index.json"] = json.dumps(index).encode()
        ops.append(f"{key}={str(entry[key])[:40]!r}")
    elif op == "shape":
        how = _pick(rng, ("trials-dict", "trials-str", "entry-list", "deep", "wide", "root-list",
                          "huge-number", "nan", "skeleton"))  # fmt: skip
        text = {
            "trials-dict": '{"trials": {"a": 1}}',
            "trials-str": '{"trials": "x"}',
            "entry-list": '{"trials": [[1, 2], 3]}',
            "deep": '{"trials": ' + "[" * 100_000 + "]" * 100_000 + "}",
            "wide": '{"trials": [' + ",".join(["[]"] * 300_000) + "]}",
            "root-list": "[1, 2, 3]",
            "huge-number": '{"trials": [], "fps": 1' + "0" * 5000 + "}",
            "nan": '{"trials": [{"file": NaN}]}',
            "skeleton": json.dumps({**index, "skeleton": {"x": [1] * 1000}}),
        }[how]
        files["d/index.json"] = text.encode()
        ops.append(how)
    elif op == "fs":
        which = _pick(rng, ("d/index.json", "d/02/02_01.npz", "d/02/skeleton-0.asf", "d"))
        special = _pick(rng, SPECIAL_FILES)
        if which == "d":
            files = {"d": special}
        else:
            files[which] = special
        ops.append(f"{which}:{special[-1]}")
    else:  # the clip or the skeleton inside the folder is itself hostile
        if rng.randrange(2):
            files["d/02/02_01.npz"] = _npz_case(seeds, rng).files["c.npz"]
        else:
            trial, asf, amc = _pick(rng, seeds.acclaim)
            files["d/02/skeleton-0.asf"] = mutate(asf, rng)[0]
    return Case("index", files, "d", ops)


# --- policy and checkpoint files ----------------------------------------------------------------


def _torch_bytes(payload) -> bytes:
    import torch

    buf = io.BytesIO()
    torch.save(payload, buf)
    return buf.getvalue()


def _load_payload(data: bytes) -> dict:
    import torch

    return torch.load(io.BytesIO(data), weights_only=True)


def _rezip(data: bytes, rng) -> tuple[bytes, str]:
    """Archive-level damage to a torch file: deflated members (and a deflate bomb), members
    overlapping, a second pickle, a large pickle."""
    op = _pick(rng, ("deflate", "bomb", "overlap", "extra", "bigpickle"))
    if op == "overlap":
        return _zip_structure(data, rng)[0], op
    src = zipfile.ZipFile(io.BytesIO(data))
    buf = io.BytesIO()
    method = zipfile.ZIP_DEFLATED if op in ("deflate", "bomb") else zipfile.ZIP_STORED
    with zipfile.ZipFile(buf, "w", method) as z:
        for info in src.infolist():
            raw = src.read(info.filename)
            if op == "bomb" and info.filename.endswith("data.pkl"):
                raw = raw + bytes(1 << 24)  # 16 MB of zeros after the pickle's STOP
            if op == "bigpickle" and info.filename.endswith("data.pkl"):
                raw = raw + b"." + bytes(5 << 20)
            z.writestr(info.filename, raw)
        if op == "extra":
            prefix = src.namelist()[0].split("/")[0]
            z.writestr(f"{prefix}/data.pkl2", b"x")
            z.writestr(f"{prefix}/data/999", bytes(64))
    return buf.getvalue(), op


class _Harmless:
    """A pickled call of a function outside the safe loader's list (harmless if it ran)."""

    def __reduce__(self):
        return (os.getcwd, ())


def _policy_case(seeds: Seeds, rng) -> Case:
    import torch

    data = _pick(rng, seeds.policies)
    op = _pick(rng, ("config", "config", "weights", "weights", "payload", "archive", "bytes",
                     "pickle"))  # fmt: skip
    ops = [op]
    if op in ("config", "weights", "payload"):
        p = _load_payload(data)
        if op == "config":
            key = _pick(rng, ("hidden", "n_features", "dilations", "prior"))
            p["config"][key] = _pick(rng, (0, -1, 12000, 1025, 1024, 2**62, 1.5, True, "32",
                                           None, [1] * 17, [0], [4097], [1, 2], (8, 8), "rollout",
                                           "greedy", "x"))  # fmt: skip
            ops.append(f"{key}={str(p['config'][key])[:20]}")
        elif op == "weights":
            sd = p["state_dict"]
            key = _pick(rng, sorted(sd))
            how = _pick(rng, ("drop", "extra", "shape", "dtype", "nan", "zero-std", "object"))
            if how == "drop":
                del sd[key]
            elif how == "extra":
                sd["extra.weight"] = torch.zeros(3)
            elif how == "shape":
                sd[key] = torch.zeros(_pick(rng, ((1,), (0,), (4096, 4096 // 64), (3, 3, 3))))
            elif how == "dtype":
                sd[key] = sd[key].to(_pick(rng, (torch.int64, torch.float64, torch.bool)))
            elif how == "nan":
                sd[key] = sd[key].clone().reshape(-1)
                sd[key][0] = float("nan")
                sd[key] = sd[key].reshape(p["state_dict"][key].shape)
            elif how == "zero-std":
                sd["feature_std"] = torch.zeros_like(sd["feature_std"])
            else:
                sd[key] = [1, 2, 3]
            ops.append(f"{how}:{key}")
        else:
            key = _pick(rng, ("format", "keyframes", "config", "state_dict", "whole"))
            value = _pick(rng, ("sidql-dqn-policy/1", None, "abc", [3, -1, 10**30], [],
                                list(range(10**5)), {"a": 1}, 7))  # fmt: skip
            if key == "whole":
                p = value
            else:
                p[key] = value
            ops.append(key)
        new = _torch_bytes(p)
    elif op == "archive":
        new, what = _rezip(data, rng)
        ops.append(what)
    elif op == "bytes":
        new, m = mutate(data, rng)
        ops += m
    else:
        new = (
            pickle.dumps(_Harmless())
            if rng.randrange(2)
            else _torch_bytes({"format": "sidql-dqn-policy/2", "x": _Harmless()})
        )
    files = {"p.pt": new}
    special = _special(rng)
    if special:
        files["p.pt"] = special
        ops.append(f"special:{special[-1]}")
    return Case("policy", files, "p.pt", ops)


def _tamper_checkpoint(p: dict, rng) -> str:
    """Change one entry of a checkpoint payload (settings untouched); returns what."""
    import torch

    key = _pick(rng, ("net", "target", "opt", "memory", "demos", "log", "rng", "torch_rng",
                      "step", "updates", "episodes", "split", "n_tasks", "format"))  # fmt: skip
    v = p.get(key)
    how = rng.randrange(6)
    if how == 0:
        p.pop(key, None)
        return f"drop:{key}"
    if how == 1:
        p[key] = _pick(rng, (None, "x", -1, 2**70, [], {}, 1.5, torch.zeros(2), True))
        return f"replace:{key}"
    if isinstance(v, dict) and v:
        sub = _pick(rng, sorted(v, key=str))
        inner = v[sub]
        if isinstance(inner, torch.Tensor):
            v[sub] = _pick(rng, (torch.zeros(1), inner.to(torch.float64), inner.reshape(-1)[:1],
                                 torch.full_like(inner, float("nan")) if inner.is_floating_point()
                                 else torch.full_like(inner, 10**6), inner[:0]))  # fmt: skip
        elif isinstance(inner, dict) and inner:
            k2 = _pick(rng, sorted(inner, key=str))
            inner[k2] = _pick(rng, (None, "x", -1, 10**12, torch.zeros(3)))
        elif isinstance(inner, list) and inner:
            inner[rng.randrange(len(inner))] = _pick(rng, (None, "x", -1, {"lr": "x"}))
        else:
            v[sub] = _pick(rng, (None, "x", -1, 10**12, 0, True))
        return f"inner:{key}.{sub}"
    if isinstance(v, torch.Tensor):
        p[key] = _pick(rng, (v[:10], v.to(torch.int64), torch.zeros_like(v)))
        return f"tensor:{key}"
    if isinstance(v, list) and v:
        row = v[rng.randrange(len(v))]
        if isinstance(row, dict):
            row[_pick(rng, sorted(row))] = _pick(rng, ("x", None, float("inf"), -1.0))
        return f"row:{key}"
    p[key] = _pick(rng, (-1, 2**60, "7", 7.5))
    return f"value:{key}"


def _checkpoint_case(seeds: Seeds, rng) -> Case:
    op = _pick(rng, ("tamper", "tamper", "tamper", "tamper", "archive", "bytes"))
    ops = [op]
    if op == "tamper":
        p = _load_payload(seeds.checkpoint)
        for _ in range(1 + rng.randrange(2)):
            ops.append(_tamper_checkpoint(p, rng))
        new = _torch_bytes(p)
    elif op == "archive":
        new, what = _rezip(seeds.checkpoint, rng)
        ops.append(what)
    else:
        new, m = mutate(seeds.checkpoint, rng)
        ops += m
    files = {"run/p.pt.ckpt": new}
    special = _special(rng)
    if special:
        files["run/p.pt.ckpt"] = special
        ops.append(f"special:{special[-1]}")
    return Case("checkpoint", files, "run/p.pt.ckpt", ops)


_MAKERS = {
    "asf": _acclaim_case("asf"),
    "amc": _acclaim_case("amc"),
    "bvh": _bvh_case,
    "sidq": _sidq_case,
    "sidm": lambda seeds, rng: _sidm().sidm_case(seeds, rng),
    "npz": _npz_case,
    "index": _index_case,
    "policy": _policy_case,
    "checkpoint": _checkpoint_case,
}


# ------------------------------------------------------------------------------------ running


def materialise(case: Case, folder: Path) -> Path:
    """Write ``case`` under ``folder`` (plus ``folder/../outside/secret.*``, the file outside
    the folder that links may point at); returns the path of the file under test."""
    outside = folder.parent / "outside"
    outside.mkdir(exist_ok=True)
    for suffix in (".npz", ".amc", ".asf", ".sidq", ".pt", ".ckpt", ".json"):
        name = "secret" + suffix
        (outside / name).write_bytes(b"root " + CANARY + b" 1 2 3\n")
    for rel, content in case.files.items():
        path = folder / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            path.write_bytes(content)
        elif content[0] == "fifo":
            os.mkfifo(path)
        elif content[0] == "dir":
            path.mkdir(exist_ok=True)
        else:
            target = content[1]
            if target == "@outside":
                target = str(outside / ("secret" + (Path(rel).suffix or ".npz")))
            os.symlink(target, path)
    return folder / case.target


def run_case(case: Case, folder: Path, checkpoint_args: dict | None = None) -> str:
    """Materialise ``case`` in the empty ``folder`` and read it as the commands do: ``"error"``
    (a clean BadFileError: MotionDataError or ModelFileError) or ``"ok"`` (finite values); :class:`Breach` when the property
    fails; any other exception propagates (a foreign error)."""
    target = materialise(case, folder)
    try:
        if case.kind in ("asf", "amc"):
            values = read_all(
                folder / "t.asf", folder / "t.amc", full=case.full, skeleton=case.skeleton
            )
            names = [p for b in values[0].bones if (p := check_bone_name(b.name))]
            if names:
                raise Breach("bad-name", "; ".join(names))
        else:
            values = _READERS[case.kind](target, folder, checkpoint_args)
    except BadFileError as e:  # MotionDataError, or ModelFileError for policies and checkpoints
        _check_error(e, folder, target, confined=case.kind == "index")
        return "error"
    bad = [n for v in values for n in non_finite(v)] + [
        f"array {i}" for i, v in enumerate(values)
        if isinstance(v, np.ndarray) and v.dtype.kind == "f" and not np.isfinite(v).all()
    ]  # fmt: skip
    if bad:
        raise Breach("non-finite", f"non-finite values in {', '.join(bad)}")
    return "ok"


def _check_error(e: BadFileError, folder: Path, target: Path, confined: bool) -> None:
    """A clean error: names a file inside ``folder`` as given (or what the file under test
    ``target`` resolves to), an existing line if any, in one printable line of bounded length;
    with ``confined`` (a folder's files, not a path the user named, which may lead anywhere),
    quoting nothing of a file outside the folder."""
    text = str(e)
    if e.path is None:
        raise Breach("bad-error", f"names no file: {text[:200]}")
    named, base = os.path.abspath(e.path), os.path.abspath(folder)  # as named: links allowed
    resolved = os.path.realpath(e.path) == os.path.realpath(target)
    if os.path.commonpath([named, base]) != base and not resolved:
        raise Breach("bad-error", f"names a file outside the folder: {text[:200]}")
    if e.line is not None:
        if not (os.path.isfile(e.path) and 1 <= e.line <= line_count(Path(e.path))):
            raise Breach("bad-error", f"line out of range: {text[:200]}")
    if any(ch < " " or ch == "\x7f" for ch in text):
        raise Breach("bad-error", f"control characters in the message: {text[:200]!r}")
    if len(e.problem) > MAX_PROBLEM_CHARS:
        raise Breach("bad-error", f"a problem of {len(e.problem)} characters: {text[:200]}")
    if confined and CANARY.decode() in text:
        raise Breach("read-outside", f"quotes a file outside the folder: {text[:200]}")


def _read_sidq(path: Path, folder: Path, _args) -> list:
    from sidql.codec import format as sidq
    from sidql.codec.decode import reconstruct_stream, stream_to_clip
    from sidql.keyframes.spherical import POINTS

    stream = sidq.read(path)
    if tuple(stream.names) == POINTS:
        clip = stream_to_clip(stream, str(path))
        return [clip]
    rec = reconstruct_stream(stream)
    return [rec.positions, rec.velocities]


def _read_npz(path: Path, folder: Path, _args) -> list:
    from sim.motion.clip import load_extra, load_npz

    clip = load_npz(path)
    extra = load_extra(path)
    return [clip, *(v for v in extra.values() if v.dtype.kind == "f")]


def _read_index(path: Path, folder: Path, _args) -> list:
    from sim.acclaim.asf import parse_asf
    from sim.motion.dataset import load_dataset_clips

    clips, _, asfs = load_dataset_clips(path, skeletons=True)
    base = os.path.realpath(path)
    skeletons = []
    for asf in asfs:
        if asf:
            if os.path.commonpath([os.path.realpath(asf), base]) != base:
                raise Breach("read-outside", f"a skeleton outside the folder: {asf}")
            skeletons.append(parse_asf(asf))
    return [*clips, *skeletons]


def _read_policy(path: Path, folder: Path, _args) -> list:
    from sidql.learning import policy as P
    from sidql.learning.tasks import linear_cost_matrix

    P._load.cache_clear()
    pol = P.load_policy(path)
    c = int(pol.net.config["n_features"])
    rng = np.random.default_rng(0)
    feats = rng.normal(size=(1, 30, c)).astype(np.float32)
    costs = linear_cost_matrix(np.cumsum(rng.normal(size=(30, 3)), axis=0))[None]
    keys = pol.decide(feats, costs, 5)[0]
    if not (len(keys) == 5 and keys[0] == 0 and keys[-1] == 29 and np.all(np.diff(keys) > 0)):
        raise Breach("non-finite", f"decisions are not 5 keyframes of 30 frames: {keys}")
    return [keys.astype(float)]


def _read_checkpoint(path: Path, folder: Path, args_dict) -> list:
    """``--resume`` up to its first gradient step: load and check the checkpoint, build the
    run's objects, restore them, sample a minibatch and compute the TD loss."""
    import torch

    from sidql.learning import checkpoint, dqn, replay
    from sidql.learning.files import ModelFileError
    from sidql.learning.settings import Args

    args = Args(**{**args_dict, "out": str(folder / "run" / "p.pt"), "resume": True})
    if not path.exists():  # as train() does: no checkpoint (a dangling link), a fresh start
        return []
    ck = checkpoint.load_checkpoint(path, args)
    train_tasks, _, split = dqn.make_tasks(args)
    if ck.get("split") != split or ck.get("n_tasks") != len(train_tasks):  # as train() does
        raise ModelFileError(str(path), None, "written for another data split")
    n = train_tasks[0].n_frames
    feats = torch.as_tensor(np.stack([t.features for t in train_tasks]))
    costs_np = np.ascontiguousarray(np.stack([t.cost for t in train_tasks]), dtype=np.float64)
    net, target, opt = dqn.make_networks(args, feats)
    memory = replay.ReplayMemory(args.buffer_size, n)
    demos = replay.ReplayMemory(max(1, args.demo_episodes * (max(args.keyframe_counts) - 2)), n)
    rng = np.random.default_rng(args.seed)
    counters, log = checkpoint.restore(
        ck, net, target, opt, memory, demos, rng, path=str(path), keyframe_counts=args.keyframe_counts,
        n_tasks=len(train_tasks),
    )  # fmt: skip
    if not len(memory):  # as train() does: no gradient step before there is a transition
        return [np.array(list(counters.values()), dtype=float)]
    batch, _ = dqn.sample_batch(memory, demos, rng, args)
    loss, q = dqn.td_loss(
        net, target, feats, torch.as_tensor(costs_np.astype(np.float32)), costs_np, batch, args
    )
    return [np.array([loss.item(), q.item(), *counters.values()])]


def _read_bvh(path: Path, folder: Path, _args) -> list:
    """The skeleton and motion; then (always: the file is small) the clip on its humanoid."""
    from sim.bvh.convert import to_acclaim
    from sim.bvh.reader import parse_bvh
    from sim.motion.ingest import load_motion

    take = to_acclaim(parse_bvh(path))
    names = [p for b in take.skeleton.bones if (p := check_bone_name(b.name))]
    if names:
        raise Breach("bad-name", "; ".join(names))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        clip = load_motion(path, fps=take.fps, derivatives=False)
    return [take.skeleton, take.motion, clip]


_READERS = {
    "bvh": _read_bvh,
    "sidq": _read_sidq,
    "sidm": lambda path, folder, args: _sidm().read_sidm(path, folder, args),
    "npz": _read_npz,
    "index": _read_index,
    "policy": _read_policy,
    "checkpoint": _read_checkpoint,
}
