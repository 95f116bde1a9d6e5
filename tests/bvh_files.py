"""BVH files the tests make, and an independent BVH forward kinematics (test-only).

Shares no code with ``sim.bvh``: the text is written here by hand, and the kinematics use scipy's
``Rotation`` (intrinsic Euler angles, upper-case axis strings: ``"ZXY"`` is ``Rz Rx Ry``, BVH's
meaning of ``Zrotation Xrotation Yrotation``). BVH's rule: a joint's global rotation is its
parent's times its own channels' rotation; it sits at its parent's position plus the parent's
global rotation applied to its OFFSET; the ROOT sits at its position channels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

METRES = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}


@dataclass
class Node:
    name: str
    parent: int  # -1: the ROOT
    offset: tuple  # metres, y up
    channels: tuple  # e.g. ("Zrotation", "Xrotation", "Yrotation"); () for an End Site
    end_site: bool = False


def creature() -> list[Node]:
    """A 1.8 m figure of non-CMU names (a colon, a space), 1- to 6-channel joints in several
    Euler orders, children of the ROOT and of the chest at different OFFSETs, End Sites."""
    zxy, xyz, zyx, yxz = (tuple(f"{a}rotation" for a in o) for o in ("ZXY", "XYZ", "ZYX", "YXZ"))
    root = ("Xposition", "Yposition", "Zposition") + zxy
    return [
        Node("mixamorig:Hips", -1, (0.0, 0.95, 0.0), root),
        Node("Left Thigh", 0, (0.1, -0.05, 0.0), zxy),
        Node("LeftKnee", 1, (0.0, -0.45, 0.01), ("Xrotation",)),
        Node("LeftAnkle", 2, (0.0, -0.42, -0.02), yxz),
        Node("", 3, (0.0, -0.05, 0.12), (), True),
        Node("RightThigh", 0, (-0.1, -0.05, 0.0), zyx),
        Node("RightKnee", 5, (0.0, -0.45, 0.01), ("Zrotation", "Xrotation")),
        Node("RightAnkle", 6, (0.0, -0.42, -0.02), xyz),
        Node("", 7, (0.0, -0.05, 0.12), (), True),
        Node("Spine", 0, (0.0, 0.1, 0.0), xyz),
        Node("Chest", 9, (0.0, 0.25, 0.0), zyx),
        Node("Neck", 10, (0.0, 0.2, 0.0), zxy),
        Node("Head", 11, (0.0, 0.1, 0.02), zxy),
        Node("", 12, (0.0, 0.18, 0.0), (), True),
        Node("LeftArm", 10, (0.18, 0.17, 0.0), zxy),
        Node("LeftElbow", 14, (0.28, 0.0, 0.0), ("Yrotation",)),
        Node("", 15, (0.25, 0.0, 0.0), (), True),
        Node("RightArm", 10, (-0.18, 0.17, 0.0), yxz),
        Node("RightElbow", 17, (-0.28, 0.0, 0.0), zxy),
        Node("", 18, (-0.25, 0.0, 0.0), (), True),
    ]


def motion(nodes: list[Node], frames: int, fps: float, seed: int = 0) -> np.ndarray:
    """(T, C) smooth channel values: positions [m, y up] and angles [deg] of at most 50 deg."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / fps
    columns = []
    for n in nodes:
        for c in n.channels:
            f, phase = rng.uniform(0.3, 1.2), rng.uniform(0, 2 * np.pi)
            if c == "Xposition":
                columns.append(0.8 * t + 0.05 * np.sin(2 * np.pi * f * t))
            elif c == "Yposition":
                columns.append(0.95 + 0.03 * np.sin(2 * np.pi * f * t + phase))
            elif c == "Zposition":
                columns.append(0.2 * np.sin(2 * np.pi * f * t + phase))
            else:
                columns.append(rng.uniform(10, 50) * np.sin(2 * np.pi * f * t + phase))
    return np.column_stack(columns)


def _file_axes(v: np.ndarray, up: str) -> np.ndarray:
    """y-up vectors in the file's axes: unchanged, or (x, y, z) -> (x, -z, y) for z up."""
    v = np.asarray(v, dtype=float)
    return v if up == "y" else np.stack([v[..., 0], -v[..., 2], v[..., 1]], axis=-1)


def bvh_text(nodes, values, fps, *, unit="cm", up="y", root_name=None) -> str:
    """The BVH text: OFFSETs and positions in ``unit`` and the file's axes (the angles are
    written as given, so a z-up file holds another motion: the oracle reads it as it is)."""
    scale = 1.0 / METRES[unit]
    values = values.copy()
    cols = [c for n in nodes for c in n.channels]
    pos = [i for i, c in enumerate(cols) if c.endswith("position")]
    if pos:
        values[:, pos] = _file_axes(values[:, pos], up) * scale
    out = ["HIERARCHY"]

    def block(i, depth):
        n, ind = nodes[i], "\t" * depth
        if n.end_site:
            out.append(f"{ind}End Site")
        else:
            out.append(
                f"{ind}{'ROOT' if n.parent < 0 else 'JOINT'} {root_name or n.name if n.parent < 0 else n.name}"
            )
        out.append(f"{ind}{{")
        offset = _file_axes(np.array(n.offset), up) * scale
        out.append(f"{ind}\tOFFSET {' '.join(f'{x:.6f}' for x in offset)}")
        if not n.end_site:
            out.append(f"{ind}\tCHANNELS {len(n.channels)} {' '.join(n.channels)}")
        for k, m in enumerate(nodes):
            if m.parent == i:
                block(k, depth + 1)
        out.append(f"{ind}}}")

    block(0, 0)
    out += ["MOTION", f"Frames: {len(values)}", f"Frame Time: {1.0 / fps:.8f}"]
    out += [" ".join(f"{x:.6f}" for x in row) for row in values]
    return "\n".join(out) + "\n"


def forward_kinematics(nodes, values, *, unit="cm", up="y") -> np.ndarray:
    """(T, J, 3) world positions [m, z up] of every node, read back from the file's numbers as
    :func:`bvh_text` writes them (so rounding is the file's)."""
    text = bvh_text(nodes, values, 1.0, unit=unit, up=up)
    table = np.array(
        [[float(x) for x in line.split()] for line in text.splitlines()[-len(values) :]]
    )
    T = len(values)
    R = [None] * len(nodes)
    p = np.zeros((T, len(nodes), 3))
    col = 0
    for i, n in enumerate(nodes):
        ch = n.channels
        block = table[:, col : col + len(ch)]
        col += len(ch)
        offset = _file_axes(np.array(n.offset), up) / METRES[unit]
        offset = np.array([float(f"{x:.6f}") for x in offset])
        rot = [k for k, c in enumerate(ch) if c.endswith("rotation")]
        local = (
            Rotation.from_euler(
                "".join(ch[k][0] for k in rot), block[:, rot], degrees=True
            ).as_matrix()
            if rot
            else np.broadcast_to(np.eye(3), (T, 3, 3))
        )
        if n.parent < 0:
            here = np.tile(offset, (T, 1))
            for k, c in enumerate(ch):
                if c.endswith("position"):
                    here[:, "XYZ".index(c[0])] = block[:, k]
            p[:, i] = here
            R[i] = local
        else:
            p[:, i] = p[:, n.parent] + np.einsum("tij,j->ti", R[n.parent], offset)
            R[i] = R[n.parent] @ local
    p *= METRES[unit]
    if up == "y":
        p = np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)
    return p
