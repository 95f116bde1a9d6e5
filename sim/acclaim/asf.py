"""Acclaim ASF skeletons (the CMU database's format), read into a :class:`~sim.acclaim.records.Skeleton`.

Everything is read in the file's own axes (CMU: y up) with lengths converted to metres (see
:mod:`sim.acclaim.records` for the units and the bounds). Malformed input raises
:class:`~sim.errors.MotionDataError` naming the file, the line and the problem; nothing deeper
leaks out.

Hostile input: every number must be finite and within the bounds of :mod:`sim.acclaim.records`
(joint limits ``lo <= hi``); bone names follow :data:`BONE_NAME_GRAMMAR` (an ASCII identifier: a
letter or ``_``, then letters, digits, ``_ . -``; at most 64 characters), so a name can never break
the generated MJCF XML or be mistaken for a frame number; names the generated model uses itself
(:data:`RESERVED_NAMES`) are refused. Lines are split as ``str.splitlines`` splits them (LF, CRLF,
lone CR, ...); error line numbers count the same way.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

import numpy as np

from sim.acclaim.records import (
    INCH,
    MAX_BONES,
    MAX_DEGREES,
    MAX_DEPTH,
    MAX_METRES,
    ROOT_CHANNELS,
    ROTATION_DOFS,
    UNITS_LENGTH_RANGE,
    Bone,
    Skeleton,
)
from sim.acclaim.tokens import floats, known_names
from sim.errors import MotionDataError
from sim.files import MAX_AMC_BYTES, MAX_ASF_BYTES, excerpt, read_regular

BONE_NAME_GRAMMAR = r"[A-Za-z_][A-Za-z0-9_.\-]{0,63}"
RESERVED_NAMES = ("root", "world", "floor")  # the ASF root; MuJoCo's world body; the model's floor
_BONE_NAME_RE = re.compile(BONE_NAME_GRAMMAR + r"\Z")


def check_bone_name(name: str) -> str | None:
    """Why ``name`` is not an acceptable bone name, or None when it is (see the module docstring)."""
    if not _BONE_NAME_RE.match(name):
        return f"bone name {excerpt(name)} is not of the form {BONE_NAME_GRAMMAR}"
    if name.lower() in RESERVED_NAMES:
        return f"bone name {name!r} is reserved ({', '.join(RESERVED_NAMES)})"
    return None


def _read_lines(path: str, max_bytes: int = MAX_AMC_BYTES) -> list[str]:
    """The file's lines, split as ``str.splitlines`` does (LF, CRLF, lone CR, and the other
    Unicode line breaks); error line numbers count the same way."""
    return _read_text(path, max_bytes).splitlines()


def _read_text(path: str | os.PathLike, max_bytes: int = MAX_AMC_BYTES) -> str:
    data = read_regular(path, max_bytes)  # regular files only, of bounded size
    if not data.strip():
        raise MotionDataError(str(path), None, "empty file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


_LIMIT_RE = re.compile(r"\(\s*([^\s()]+)\s+([^\s()]+)\s*\)")


def parse_asf(path: str | os.PathLike) -> Skeleton:
    """Read an ASF skeleton file (Acclaim 1.10; LF or CRLF line ends).

    Returns:
        The skeleton with lengths in metres, directions unit-normalised, in the file's axes.

    Raises:
        MotionDataError: missing section, duplicate or unknown bone, bad numbers, hierarchy cycle...
    """
    path = str(path)
    asf = _read_sections(_read_lines(path, MAX_ASF_BYTES), path)
    to_m = INCH / asf.units["length"]
    in_deg = asf.units["angle"] == "deg"
    by_name = {b["name"]: b for b in asf.raw_bones}
    parent_of = _hierarchy_parents(asf.hierarchy, by_name, path)
    order = _topological(parent_of, by_name, path)
    bones = [_bone(by_name[b], parent_of[b], to_m, in_deg, path) for b in order]
    root = asf.root
    orientation = root["orientation"] if in_deg else np.rad2deg(root["orientation"])
    return Skeleton(
        path=path,
        name=asf.name,
        length_to_metres=to_m,
        angles_in_degrees=in_deg,
        root_order=root["order"],
        root_axis_order=root["axis"],
        root_orientation=orientation,
        bones=tuple(bones),
    )


@dataclass
class _Sections:
    """What an ASF file's sections say, as read line by line (values in the file's units)."""

    sections: dict[str, int] = field(default_factory=dict)  # section -> its line
    units: dict = field(default_factory=lambda: {"length": 1.0, "angle": "deg"})
    root: dict = field(
        default_factory=lambda: {"order": ROOT_CHANNELS, "axis": "XYZ", "orientation": np.zeros(3)}
    )
    raw_bones: list[dict] = field(default_factory=list)
    hierarchy: list[tuple[int, list[str]]] = field(default_factory=list)
    name: str = ""


def _read_sections(lines: list[str], path: str) -> _Sections:
    """Every line of the file read into its section; checks that the required sections are
    there and every bone block is closed."""
    asf = _Sections()
    section = None
    bone: dict | None = None
    pending_limits = 0
    for ln, raw in enumerate(lines, start=1):
        text = raw.split("#", 1)[0].strip()
        if not text:
            continue
        if text.startswith(":"):
            section = _section_line(text, path, ln, asf, bone)
            continue
        tokens = text.split()
        if section == "units":
            _units_line(tokens, path, ln, asf.units)
        elif section == "root":
            _root_line(tokens, path, ln, asf.root, asf.units)
        elif section == "bonedata":
            pending_limits, bone = _bone_line(
                tokens, path, ln, bone, asf.raw_bones, pending_limits, _angle_bound(asf.units)
            )
        elif section == "hierarchy":
            if tokens[0] in ("begin", "end"):
                continue
            asf.hierarchy.append((ln, tokens))

    for required in ("root", "bonedata", "hierarchy"):
        if required not in asf.sections:
            raise MotionDataError(path, None, f"missing section ':{required}'")
    if bone is not None:
        raise MotionDataError(path, bone["line"], f"bone block {bone.get('name')!r} has no 'end'")
    if not asf.raw_bones:
        raise MotionDataError(path, asf.sections["bonedata"], "no bones in ':bonedata'")
    return asf


def _section_line(text: str, path: str, ln: int, asf: _Sections, bone: dict | None) -> str:
    """A ``:section`` line: records where the section starts; returns its name."""
    key, *rest = text.split()
    section = key[1:].lower()
    if section in asf.sections and section in ("root", "bonedata", "hierarchy", "units"):
        raise MotionDataError(path, ln, f"section ':{section}' appears twice")
    asf.sections[section] = ln
    if section == "name" and rest:
        asf.name = rest[0]
    if section == "bonedata" or section == "hierarchy":
        if bone is not None:
            raise MotionDataError(path, ln, "bone block not closed with 'end'")
    return section


def _units_line(tokens: list[str], path: str, ln: int, units: dict) -> None:
    """One line of ``:units`` (``length L`` or ``angle deg|rad``; others ignored)."""
    if len(tokens) >= 2 and tokens[0] == "length":
        value = floats(tokens[1:2], path, ln, "units length")[0]
        lo, hi = UNITS_LENGTH_RANGE
        if not lo <= value <= hi:
            raise MotionDataError(
                path,
                ln,
                f"units length {excerpt(tokens[1], quote=False)} outside [{lo:g}, {hi:g}]",
            )
        units["length"] = value
    elif len(tokens) >= 2 and tokens[0] == "angle":
        unit = tokens[1].lower()
        if unit not in ("deg", "rad"):
            raise MotionDataError(path, ln, f"angle unit {excerpt(tokens[1])}; expected deg or rad")
        units["angle"] = unit


def _root_line(tokens: list[str], path: str, ln: int, root: dict, units: dict) -> None:
    """One line of ``:root`` (``order``, ``axis``, ``orientation``; others ignored)."""
    key = tokens[0].lower()
    if key == "order":
        order = tuple(t.lower() for t in tokens[1:])
        if sorted(order) != sorted(ROOT_CHANNELS):
            raise MotionDataError(
                path,
                ln,
                f"root order {excerpt(' '.join(tokens[1:]))}; expected TX TY TZ RX RY RZ",
            )
        root["order"] = order
    elif key == "axis":
        root["axis"] = _axis_order(tokens[1:2], path, ln)
    elif key == "orientation":
        if len(tokens) != 4:
            raise MotionDataError(path, ln, "root orientation needs 3 values")
        root["orientation"] = floats(tokens[1:], path, ln, "root orientation", _angle_bound(units))


def _bone(b: dict, parent: str, to_m: float, in_deg: bool, path: str) -> Bone:
    """The :class:`Bone` of a bone block as read (lengths times ``to_m``, angles to degrees)."""
    bname = b["name"]
    d = b["direction"]
    scale = np.abs(d).max()
    if scale < 1e-300:
        raise MotionDataError(path, b["line"], f"bone {bname!r} has a zero direction")
    d = d / scale
    norm = np.linalg.norm(d)
    length = float(b["length"] * to_m)
    if not length <= MAX_METRES:
        raise MotionDataError(
            path,
            b["length_line"],
            f"bone {bname!r} length {length:g} m exceeds {MAX_METRES:g} m",
        )
    axis = b["axis"] if in_deg else np.rad2deg(b["axis"])
    limits = b["limits"] if in_deg else np.rad2deg(b["limits"])
    return Bone(
        name=bname,
        parent=parent,
        direction=d / norm,
        length=length,
        axis=axis,
        axis_order=b["axis_order"],
        dofs=b["dofs"],
        limits=limits,
        line=b["line"],
    )


def _axis_order(tokens: list[str], path: str, ln: int) -> str:
    order = tokens[0].upper() if tokens else ""
    if sorted(order) != ["X", "Y", "Z"]:
        raise MotionDataError(
            path, ln, f"axis order {excerpt(order)}; expected a permutation of XYZ"
        )
    return order


def _angle_bound(units: dict) -> float:
    """:data:`MAX_DEGREES` in the file's angle unit."""
    return MAX_DEGREES if units["angle"] == "deg" else float(np.deg2rad(MAX_DEGREES))


def _bone_line(tokens, path, ln, bone, raw_bones, pending_limits, angle_bound):
    """Consume one line of ``:bonedata``; returns (limits still expected, current bone)."""
    key = tokens[0].lower()
    if bone is not None and pending_limits and key.startswith("("):
        bone["limits_raw"].append((ln, " ".join(tokens)))
        return pending_limits - 1, bone
    if key == "begin":
        if bone is not None:
            raise MotionDataError(path, ln, "'begin' inside an open bone block")
        return 0, {"line": ln, "axis_order": "XYZ", "dofs": (), "limits_raw": []}
    if bone is None:
        raise MotionDataError(path, ln, f"{excerpt(tokens[0])} outside a begin/end bone block")
    if key == "end":
        _finish_bone(bone, path, raw_bones)
        return 0, None
    if key == "id":
        pass
    elif key == "name":
        if len(tokens) != 2:
            raise MotionDataError(path, ln, "bone name must be one word")
        problem = check_bone_name(tokens[1])
        if problem:
            raise MotionDataError(path, ln, problem)
        bone["name"] = tokens[1]
    elif key == "direction":
        if len(tokens) != 4:
            raise MotionDataError(path, ln, f"direction needs 3 values, got {len(tokens) - 1}")
        bone["direction"] = floats(tokens[1:], path, ln, "direction")
    elif key == "length":
        if len(tokens) != 2:
            raise MotionDataError(path, ln, "length needs 1 value")
        bone["length"] = floats(tokens[1:], path, ln, "length")[0]
        bone["length_line"] = ln
        if not bone["length"] >= 0:
            raise MotionDataError(
                path, ln, f"negative bone length {excerpt(tokens[1], quote=False)}"
            )
    elif key == "axis":
        if len(tokens) != 5:
            raise MotionDataError(path, ln, "axis needs 3 angles and an order, e.g. '0 0 20 XYZ'")
        bone["axis"] = floats(tokens[1:4], path, ln, "axis", angle_bound)
        bone["axis_order"] = _axis_order(tokens[4:5], path, ln)
    elif key == "dof":
        dofs = tuple(t.lower() for t in tokens[1:])
        for d in dofs:
            if d not in ROTATION_DOFS:
                raise MotionDataError(
                    path, ln, f"unsupported dof {excerpt(d)}; supported: {', '.join(ROTATION_DOFS)}"
                )
        if len(set(dofs)) != len(dofs):
            raise MotionDataError(path, ln, f"repeated dof in {' '.join(dofs)}")
        bone["dofs"] = dofs
    elif key == "limits":
        if bone["limits_raw"]:
            raise MotionDataError(path, ln, "a second 'limits' in one bone block")
        bone["limits_raw"].append((ln, " ".join(tokens[1:])))
        bone["angle_bound"] = angle_bound
        return max(len(bone["dofs"]) - 1, 0), bone
    elif key in ("bodymass", "cofmass"):
        pass
    else:
        raise MotionDataError(path, ln, f"unknown bone field {excerpt(tokens[0])}")
    return pending_limits, bone


def _finish_bone(bone: dict, path: str, raw_bones: list[dict]) -> None:
    ln = bone["line"]
    for key in ("name", "direction", "length"):
        if key not in bone:
            raise MotionDataError(path, ln, f"bone block has no '{key}'")
    if bone["name"] == "root":
        raise MotionDataError(path, ln, "a bone may not be called 'root'")
    if len(raw_bones) >= MAX_BONES:  # also bounds the quadratic duplicate check below
        raise MotionDataError(path, ln, f"more than {MAX_BONES} bones")
    if any(b["name"] == bone["name"] for b in raw_bones):
        raise MotionDataError(path, ln, f"duplicate bone {bone['name']!r}")
    bone.setdefault("axis", np.zeros(3))
    limits = []
    for lln, text in bone["limits_raw"]:
        found = _LIMIT_RE.findall(text)
        if not found or _LIMIT_RE.sub("", text).strip():
            raise MotionDataError(
                path, lln, f"cannot read limits {excerpt(text)}; expected '(lo hi)'"
            )
        for lo, hi in found:
            pair = floats([lo, hi], path, lln, "limits", bone["angle_bound"])
            if pair[0] > pair[1]:
                raise MotionDataError(
                    path,
                    lln,
                    f"limits ({excerpt(lo, quote=False)} {excerpt(hi, quote=False)}): lower above upper",
                )
            limits.append(pair)
    if limits and len(limits) != len(bone["dofs"]):
        lln = bone["limits_raw"][0][0]
        raise MotionDataError(
            path,
            lln,
            f"bone {bone['name']!r} has {len(bone['dofs'])} dofs but {len(limits)} limits",
        )
    if not limits:
        limits = [np.array([-180.0, 180.0])] * len(bone["dofs"])
    bone["limits"] = np.array(limits, dtype=np.float64).reshape(len(bone["dofs"]), 2)
    raw_bones.append(bone)


def _hierarchy_parents(hierarchy, by_name, path) -> dict[str, str]:
    parent_of: dict[str, str] = {}
    known = set(by_name) | {"root"}
    for ln, tokens in hierarchy:
        parent, children = tokens[0], tokens[1:]
        for n in (parent, *children):
            if n not in known:
                raise MotionDataError(
                    path,
                    ln,
                    f"unknown bone {excerpt(n)} in hierarchy; known: {known_names(['root', *by_name])}",
                )
        for c in children:
            if c == "root":
                raise MotionDataError(path, ln, "the root cannot be a child")
            if c in parent_of:
                raise MotionDataError(
                    path, ln, f"bone {c!r} has two parents ({parent_of[c]!r} and {parent!r})"
                )
            parent_of[c] = parent
    missing = [n for n in by_name if n not in parent_of]
    if missing:
        raise MotionDataError(
            path, by_name[missing[0]]["line"], f"bones not in ':hierarchy': {known_names(missing)}"
        )
    return parent_of


def _topological(parent_of: dict[str, str], by_name: dict, path: str) -> list[str]:
    """Bones ordered parents-first (file order among siblings); detects cycles."""
    children: dict[str, list[str]] = {}
    for b in by_name:  # file order
        children.setdefault(parent_of[b], []).append(b)
    order, stack = [], [(b, 1) for b in reversed(children.get("root", []))]
    while stack:
        b, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise MotionDataError(
                path, by_name[b]["line"], f"bone {b!r} is more than {MAX_DEPTH} bones deep"
            )
        order.append(b)
        stack.extend((c, depth + 1) for c in reversed(children.get(b, [])))
    if len(order) != len(by_name):
        seen = set(order)
        cyclic = [b for b in by_name if b not in seen]
        raise MotionDataError(
            path,
            by_name[cyclic[0]]["line"],
            f"hierarchy cycle: bones not reachable from root: {known_names(sorted(cyclic))}",
        )
    return order
