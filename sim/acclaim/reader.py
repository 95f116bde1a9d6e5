"""Acclaim motion-capture files: ASF skeletons and AMC motions (the CMU database's format).

Everything is read into typed values in the file's own axes (CMU: y up) with lengths converted to
metres. Malformed input raises :class:`~sim.errors.MotionDataError` naming the file, the line and the
problem; nothing deeper leaks out.

Length units: Acclaim writes ``:units length L``; CMU's convention is
``metres = value * 0.0254 / L`` (values are inches scaled by L = 0.45).

Hostile input: every number must be finite and within generous physical bounds (lengths and root
translations at most :data:`MAX_METRES`, angles at most :data:`MAX_DEGREES` in magnitude, joint
limits ``lo <= hi``); frame numbers are ASCII digits (at most 12); bone names follow
:data:`BONE_NAME_GRAMMAR` (an ASCII identifier: a letter or ``_``, then letters, digits, ``_ . -``;
at most 64 characters), so a name can never break the generated MJCF XML or be mistaken for a
frame number; names the generated model uses itself (:data:`RESERVED_NAMES`) are refused.
Lines are split as ``str.splitlines`` splits them (LF, CRLF, lone CR, ...); error line numbers
count the same way.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from dataclasses import dataclass, field

import numpy as np

from sim.errors import MotionDataError, MotionDataWarning, UnknownNameError
from sim.files import MAX_AMC_BYTES, MAX_ASF_BYTES, read_regular

INCH = 0.0254  # [m]
ROTATION_DOFS = ("rx", "ry", "rz")
ROOT_CHANNELS = ("tx", "ty", "tz", "rx", "ry", "rz")

MAX_METRES = 1e4  # bound on a bone length or root translation [m]
MAX_DEGREES = 1e5  # bound on any angle [deg] (real CMU motions reach ~1,500)
MAX_BONES = 1000
MAX_DEPTH = 200  # bones on the longest root-to-leaf chain (the MJCF nests one body per bone)
UNITS_LENGTH_RANGE = (1e-6, 1e6)  # accepted ``:units length`` values
BONE_NAME_GRAMMAR = r"[A-Za-z_][A-Za-z0-9_.\-]{0,63}"
RESERVED_NAMES = ("root", "world", "floor")  # the ASF root; MuJoCo's world body; the model's floor
_BONE_NAME_RE = re.compile(BONE_NAME_GRAMMAR + r"\Z")
_FRAME_NUMBER_RE = re.compile(r"[0-9]{1,12}\Z")


@dataclass(frozen=True)
class Bone:
    """One ASF bone.

    Attributes:
        name: bone name.
        parent: parent bone name (``"root"`` for the root's children).
        direction: (3,) unit vector of the bone in the rest pose, file axes (CMU: y up).
        length: bone length [m].
        axis: (3,) Euler angles [deg] of the bone's local frame C, applied in ``axis_order``.
        axis_order: rotation order of ``axis``, e.g. ``"XYZ"`` (X applied first).
        dofs: rotational degrees of freedom in AMC value order, e.g. ``("rx", "ry", "rz")``.
        limits: (len(dofs), 2) joint limits [deg].
        line: the line of the bone's ``begin`` in its file (None if built in memory).
    """

    name: str
    parent: str
    direction: np.ndarray
    length: float
    axis: np.ndarray
    axis_order: str
    dofs: tuple[str, ...]
    limits: np.ndarray
    line: int | None = field(default=None, compare=False)


@dataclass(frozen=True)
class Skeleton:
    """An ASF skeleton.

    Attributes:
        path: source file ("" if built in memory).
        name: the file's ``:name``.
        length_to_metres: factor taking the file's length values to metres.
        angles_in_degrees: whether the file's angles are degrees (else radians).
        root_order: AMC channel order of the root, e.g. ``("tx","ty","tz","rx","ry","rz")``.
        root_axis_order: rotation order of the root, e.g. ``"XYZ"``.
        root_orientation: (3,) Euler angles [deg] of the root's frame.
        bones: bones in topological order (every parent before its children).
    """

    path: str
    name: str
    length_to_metres: float
    angles_in_degrees: bool
    root_order: tuple[str, ...]
    root_axis_order: str
    root_orientation: np.ndarray
    bones: tuple[Bone, ...]
    _index: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        self._index.update({b.name: i for i, b in enumerate(self.bones)})

    @property
    def bone_names(self) -> tuple[str, ...]:
        return tuple(b.name for b in self.bones)

    def bone(self, name: str) -> Bone:
        """The bone called ``name``; the error lists the valid names."""
        try:
            return self.bones[self._index[name]]
        except KeyError:
            raise UnknownNameError("bone", name, self.bone_names) from None

    def has_bone(self, name: str) -> bool:
        return name in self._index


@dataclass(frozen=True)
class Motion:
    """An AMC motion in the file's units, one row per frame.

    Attributes:
        path: source file.
        root: (T, 6) root channels reordered to (tx, ty, tz, rx, ry, rz); translations [m],
            rotations [deg].
        angles: dict bone name -> (T, len(bone.dofs)) rotations [deg] in the bone's dof order.
            Bones with dofs that the file never mentions are zeros.
        first_frame: the file's number of its first frame (usually 1).
        notes: repairs made while reading (e.g. an incomplete final frame dropped), each naming
            the file and line.
    """

    path: str
    root: np.ndarray
    angles: dict
    first_frame: int = 1
    notes: tuple[str, ...] = ()

    @property
    def n_frames(self) -> int:
        return int(self.root.shape[0])


# ----------------------------------------------------------------------------------------- ASF


def check_bone_name(name: str) -> str | None:
    """Why ``name`` is not an acceptable bone name, or None when it is (see the module docstring)."""
    if not _BONE_NAME_RE.match(name):
        return f"bone name {name!r} is not of the form {BONE_NAME_GRAMMAR}"
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


def _float_list(
    tokens: list[str], path: str, line: int, what: str, bound: float | list | None = None
) -> list[float]:
    """Finite numbers of ``tokens``, each at most ``bound`` (one for all, or one per token) in
    magnitude. Plain Python: this runs once per line on the checked AMC path."""
    try:
        values = [float(t) for t in tokens]
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        raise MotionDataError(path, line, f"non-numeric value {bad!r} in {what}") from None
    bounds = [bound] * len(values) if bound is None or isinstance(bound, (int, float)) else bound
    for t, v, b in zip(tokens, values, bounds, strict=True):
        if not math.isfinite(v):
            raise MotionDataError(path, line, f"non-finite value {t!r} in {what}")
        if b is not None and abs(v) > b:
            raise MotionDataError(path, line, f"value {t} in {what} exceeds {b:g} in magnitude")
    return values


def _floats(
    tokens: list[str], path: str, line: int, what: str, bound: float | None = None
) -> np.ndarray:
    """:func:`_float_list` as an array."""
    return np.array(_float_list(tokens, path, line, what, bound), dtype=np.float64)


def _is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


_LIMIT_RE = re.compile(r"\(\s*([^\s()]+)\s+([^\s()]+)\s*\)")


def parse_asf(path: str | os.PathLike) -> Skeleton:
    """Read an ASF skeleton file (Acclaim 1.10; LF or CRLF line ends).

    Returns:
        The skeleton with lengths in metres, directions unit-normalised, in the file's axes.

    Raises:
        MotionDataError: missing section, duplicate or unknown bone, bad numbers, hierarchy cycle...
    """
    path = str(path)
    lines = _read_lines(path, MAX_ASF_BYTES)
    sections: dict[str, int] = {}
    units = {"length": 1.0, "angle": "deg"}
    root = {"order": ROOT_CHANNELS, "axis": "XYZ", "orientation": np.zeros(3)}
    raw_bones: list[dict] = []
    hierarchy: list[tuple[int, list[str]]] = []
    name = ""
    section = None
    bone: dict | None = None
    pending_limits = 0

    for ln, raw in enumerate(lines, start=1):
        text = raw.split("#", 1)[0].strip()
        if not text:
            continue
        if text.startswith(":"):
            key, *rest = text.split()
            section = key[1:].lower()
            if section in sections and section in ("root", "bonedata", "hierarchy", "units"):
                raise MotionDataError(path, ln, f"section ':{section}' appears twice")
            sections[section] = ln
            if section == "name" and rest:
                name = rest[0]
            if section == "bonedata" or section == "hierarchy":
                if bone is not None:
                    raise MotionDataError(path, ln, "bone block not closed with 'end'")
            continue
        tokens = text.split()
        if section == "units":
            if len(tokens) >= 2 and tokens[0] == "length":
                value = _floats(tokens[1:2], path, ln, "units length")[0]
                lo, hi = UNITS_LENGTH_RANGE
                if not lo <= value <= hi:
                    raise MotionDataError(
                        path, ln, f"units length {tokens[1]} outside [{lo:g}, {hi:g}]"
                    )
                units["length"] = value
            elif len(tokens) >= 2 and tokens[0] == "angle":
                unit = tokens[1].lower()
                if unit not in ("deg", "rad"):
                    raise MotionDataError(
                        path, ln, f"angle unit {tokens[1]!r}; expected deg or rad"
                    )
                units["angle"] = unit
        elif section == "root":
            key = tokens[0].lower()
            if key == "order":
                order = tuple(t.lower() for t in tokens[1:])
                if sorted(order) != sorted(ROOT_CHANNELS):
                    raise MotionDataError(
                        path, ln, f"root order {' '.join(tokens[1:])!r}; expected TX TY TZ RX RY RZ"
                    )
                root["order"] = order
            elif key == "axis":
                root["axis"] = _axis_order(tokens[1:2], path, ln)
            elif key == "orientation":
                if len(tokens) != 4:
                    raise MotionDataError(path, ln, "root orientation needs 3 values")
                root["orientation"] = _floats(
                    tokens[1:], path, ln, "root orientation", _angle_bound(units)
                )
        elif section == "bonedata":
            pending_limits, bone = _bone_line(
                tokens, path, ln, bone, raw_bones, pending_limits, _angle_bound(units)
            )
        elif section == "hierarchy":
            if tokens[0] in ("begin", "end"):
                continue
            hierarchy.append((ln, tokens))

    for required in ("root", "bonedata", "hierarchy"):
        if required not in sections:
            raise MotionDataError(path, None, f"missing section ':{required}'")
    if bone is not None:
        raise MotionDataError(path, bone["line"], f"bone block {bone.get('name')!r} has no 'end'")
    if not raw_bones:
        raise MotionDataError(path, sections["bonedata"], "no bones in ':bonedata'")

    to_m = INCH / units["length"]
    in_deg = units["angle"] == "deg"
    by_name = {b["name"]: b for b in raw_bones}
    parent_of = _hierarchy_parents(hierarchy, by_name, path)
    order = _topological(parent_of, by_name, path)

    bones = []
    for bname in order:
        b = by_name[bname]
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
        bones.append(
            Bone(
                name=bname,
                parent=parent_of[bname],
                direction=d / norm,
                length=length,
                axis=axis,
                axis_order=b["axis_order"],
                dofs=b["dofs"],
                limits=limits,
                line=b["line"],
            )
        )
    orientation = root["orientation"] if in_deg else np.rad2deg(root["orientation"])
    return Skeleton(
        path=path,
        name=name,
        length_to_metres=to_m,
        angles_in_degrees=in_deg,
        root_order=root["order"],
        root_axis_order=root["axis"],
        root_orientation=orientation,
        bones=tuple(bones),
    )


def _axis_order(tokens: list[str], path: str, ln: int) -> str:
    order = tokens[0].upper() if tokens else ""
    if sorted(order) != ["X", "Y", "Z"]:
        raise MotionDataError(path, ln, f"axis order {order!r}; expected a permutation of XYZ")
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
        raise MotionDataError(path, ln, f"{tokens[0]!r} outside a begin/end bone block")
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
        bone["direction"] = _floats(tokens[1:], path, ln, "direction")
    elif key == "length":
        if len(tokens) != 2:
            raise MotionDataError(path, ln, "length needs 1 value")
        bone["length"] = _floats(tokens[1:], path, ln, "length")[0]
        bone["length_line"] = ln
        if not bone["length"] >= 0:
            raise MotionDataError(path, ln, f"negative bone length {tokens[1]}")
    elif key == "axis":
        if len(tokens) != 5:
            raise MotionDataError(path, ln, "axis needs 3 angles and an order, e.g. '0 0 20 XYZ'")
        bone["axis"] = _floats(tokens[1:4], path, ln, "axis", angle_bound)
        bone["axis_order"] = _axis_order(tokens[4:5], path, ln)
    elif key == "dof":
        dofs = tuple(t.lower() for t in tokens[1:])
        for d in dofs:
            if d not in ROTATION_DOFS:
                raise MotionDataError(
                    path, ln, f"unsupported dof {d!r}; supported: {', '.join(ROTATION_DOFS)}"
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
        raise MotionDataError(path, ln, f"unknown bone field {tokens[0]!r}")
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
            raise MotionDataError(path, lln, f"cannot read limits {text!r}; expected '(lo hi)'")
        for lo, hi in found:
            pair = _floats([lo, hi], path, lln, "limits", bone["angle_bound"])
            if pair[0] > pair[1]:
                raise MotionDataError(path, lln, f"limits ({lo} {hi}): lower above upper")
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
                    path, ln, f"unknown bone {n!r} in hierarchy; known: root, {', '.join(by_name)}"
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
            path, by_name[missing[0]]["line"], f"bones not in ':hierarchy': {', '.join(missing)}"
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
            f"hierarchy cycle: bones not reachable from root: {', '.join(sorted(cyclic))}",
        )
    return order


# ----------------------------------------------------------------------------------------- AMC


def parse_amc(path: str | os.PathLike, skeleton: Skeleton, *, strict: bool = False) -> Motion:
    """Read an AMC motion for ``skeleton`` (``:FULLY-SPECIFIED``, ``:DEGREES``; LF or CRLF).

    A file that ends part-way through its final frame (whole lines missing, as in CMU's own
    07_12.amc) loses that frame with a :class:`MotionDataWarning` and a note in ``Motion.notes``,
    unless ``strict``, where it is an error like any other truncated frame.

    Returns:
        The motion with root translations in metres and rotations in degrees.

    Raises:
        MotionDataError: truncated frame, unknown bone, wrong number of values, non-numeric token,
            no frames...
    """
    path = str(path)
    lines = _read_lines(path)
    in_deg = skeleton.angles_in_degrees
    body_start = None
    for i, raw in enumerate(lines):
        text = raw.strip()
        if not text or text.startswith("#"):
            continue
        if text.startswith(":"):
            flag = text.split()[0].upper()
            if flag == ":DEGREES":
                in_deg = True
            elif flag == ":RADIANS":
                in_deg = False
            continue
        body_start = i
        break
    if body_start is None:
        raise MotionDataError(path, None, "no frames")
    layout = {b.name: len(b.dofs) for b in skeleton.bones}
    layout["root"] = 6
    # Bounds in the file's units: |translation| <= MAX_METRES, |angle| <= MAX_DEGREES.
    bounds = {
        n: np.full(k, MAX_DEGREES if in_deg else np.deg2rad(MAX_DEGREES)) for n, k in layout.items()
    }
    for c in ("tx", "ty", "tz"):
        bounds["root"][skeleton.root_order.index(c)] = MAX_METRES / skeleton.length_to_metres
    parsed = _parse_frames_fast(lines, body_start, layout)
    if parsed is not None and not _within(parsed[1], bounds):
        parsed = None  # the checked parser names the offending line
    if parsed is None:
        parsed = _parse_frames_checked(lines, body_start, layout, path, strict, bounds)
    first, columns, notes = parsed if len(parsed) == 3 else (*parsed, ())
    if "root" not in columns:  # unreachable: both parsers check
        raise MotionDataError(path, None, "no root line")
    for note in notes:
        warnings.warn(note, MotionDataWarning, stacklevel=2)
    T = len(columns["root"])
    root = np.asarray(columns.pop("root"), dtype=np.float64).reshape(T, 6)
    root = root[:, [skeleton.root_order.index(c) for c in ROOT_CHANNELS]]
    root[:, :3] *= skeleton.length_to_metres
    angles = {}
    for b in skeleton.bones:
        if not b.dofs:
            continue
        v = columns.get(b.name)
        a = np.zeros((T, len(b.dofs))) if v is None else np.asarray(v, np.float64)
        angles[b.name] = a.reshape(T, len(b.dofs))
    if not in_deg:
        root[:, 3:] = np.rad2deg(root[:, 3:])
        angles = {k: np.rad2deg(v) for k, v in angles.items()}
    # Finite: every parsed value passed _within (finite, bounded), and rad2deg of a bounded value
    # is finite; the zeros filled in for unmentioned bones are too.
    return Motion(path=path, root=root, angles=angles, first_frame=first, notes=tuple(notes))


def _within(columns: dict, bounds: dict) -> bool:
    """Every value finite and within its channel's bound."""
    for name, v in columns.items():  # min/max reduce without temporaries; nan propagates
        if not len(v):
            continue
        b = bounds[name]
        if name == "root":  # per channel: translations and angles differ
            if not ((v.max(axis=0) <= b).all() and (v.min(axis=0) >= -b).all()):
                return False
        elif not (v.max() <= b[0] and v.min() >= -b[0]):
            return False
    return True


def _is_frame_number(token: str) -> bool:
    return _FRAME_NUMBER_RE.match(token) is not None


def _parse_frames_fast(lines: list[str], start: int, layout: dict[str, int]):
    """Vectorised parse when every frame has the first frame's exact layout; None otherwise.

    Any irregularity (blank lines, a different bone order, a bad token) returns None so the
    line-by-line parser can report it precisely.
    """
    body = lines[start:]
    while body and not body[-1].strip():
        body.pop()
    if not body or not _is_frame_number(body[0].strip()):
        return None
    frame_layout = []
    for raw in body[1:]:
        tokens = raw.split()
        if not tokens or tokens[0].isdigit():
            break
        frame_layout.append((tokens[0], len(tokens) - 1))
    L = 1 + len(frame_layout)
    names = [n for n, _ in frame_layout]
    if (
        not frame_layout
        or len(body) % L
        or len(set(names)) != len(names)
        or "root" not in names
        or any(layout.get(n) != k for n, k in frame_layout)
    ):
        return None
    T = len(body) // L
    first = int(body[0])
    number_lines = body[0::L]
    digits = "".join(number_lines)
    if not (digits.isascii() and digits.replace(" ", "").replace("\t", "").isdigit()):
        return None  # signs, underscores, unicode digits: the checked parser decides
    try:
        numbers = np.array(number_lines, dtype=np.int64)
    except (ValueError, OverflowError):
        return None
    if not np.array_equal(numbers, np.arange(first, first + T)):
        return None
    columns = {}
    for k, (name, count) in enumerate(frame_layout, start=1):
        slot = body[k::L]
        prefix = name + " " if count else name
        # Every line of the slot starts with the bone's name: T - 1 line starts after the first.
        joined = "\n".join(slot)
        if not joined.startswith(prefix) or joined.count("\n" + prefix) != T - 1:
            return None
        if count == 0:
            continue
        n = len(prefix)
        try:  # numpy's C reader; a wrong count or a bad token raises
            values = np.loadtxt([line[n:] for line in slot], dtype=np.float64, ndmin=2)
        except (ValueError, IndexError):
            return None
        if values.shape != (T, count):
            return None
        columns[name] = values
    return first, columns


def _parse_frames_checked(lines, start, layout, path, strict, bounds):
    """Line-by-line parse with precise errors (the slow path)."""
    frames: list[dict[str, list[float]]] = []
    frame_lines: list[int] = []
    expected_names = None
    first = None
    current: dict | None = None

    def close(ln_next):
        if current is None:
            return
        nonlocal expected_names
        if expected_names is None:
            expected_names = set(current)
        missing = expected_names - set(current)
        if missing:
            raise MotionDataError(
                path,
                frame_lines[-1],
                f"truncated frame {first + len(frames) - 1}: missing {', '.join(sorted(missing))}",
            )
        extra = set(current) - expected_names
        if extra:
            raise MotionDataError(
                path, frame_lines[-1], f"frame has bones the first frame lacks: {sorted(extra)}"
            )

    for ln, raw in enumerate(lines[start:], start=start + 1):
        tokens = raw.split()
        if not tokens:
            continue
        if len(tokens) == 1 and tokens[0].isdigit() and not _is_frame_number(tokens[0]):
            raise MotionDataError(
                path, ln, f"frame number {tokens[0][:20]!r} is not 1 to 12 ASCII digits"
            )
        if len(tokens) == 1 and _is_frame_number(tokens[0]):
            close(ln)
            number = int(tokens[0])
            if first is None:
                first = number
            elif number != first + len(frames):
                raise MotionDataError(
                    path, ln, f"frame number {number}; expected {first + len(frames)}"
                )
            current = {}
            frames.append(current)
            frame_lines.append(ln)
            continue
        if current is None:
            raise MotionDataError(path, ln, f"expected a frame number, got {tokens[0]!r}")
        name = tokens[0]
        if name not in layout:
            raise MotionDataError(
                path, ln, f"unknown bone {name!r}; known: {', '.join(sorted(layout))}"
            )
        if name in current:
            raise MotionDataError(path, ln, f"bone {name!r} appears twice in one frame")
        if len(tokens) - 1 != layout[name]:
            raise MotionDataError(
                path, ln, f"bone {name!r} needs {layout[name]} values, got {len(tokens) - 1}"
            )
        try:  # bounds are checked on the whole arrays at the end (per line would cost ~40 %)
            current[name] = [float(t) for t in tokens[1:]]
        except ValueError:
            _float_list(tokens[1:], path, ln, f"bone {name!r}")  # raises, naming the token
    if not frames:
        raise MotionDataError(path, None, "no frames")
    notes = []
    try:
        close(None)
    except MotionDataError as e:
        if strict or len(frames) < 2 or not e.problem.startswith("truncated frame"):
            raise
        frames.pop()
        notes.append(f"{e}; dropped the incomplete final frame")
    if "root" not in expected_names:
        raise MotionDataError(path, frame_lines[0], "frame has no 'root' line")
    columns = {n: np.array([f[n] for f in frames], dtype=np.float64) for n in expected_names}
    if not _within(columns, bounds):
        _raise_out_of_bounds(lines, start, layout, path, bounds)
    return first, columns, notes


def _raise_out_of_bounds(lines, start, layout, path, bounds):
    """Raise for the first line holding a non-finite or out-of-bounds value."""
    for ln, raw in enumerate(lines[start:], start=start + 1):
        tokens = raw.split()
        if tokens and tokens[0] in layout and len(tokens) - 1 == layout[tokens[0]]:
            bound = [float(b) for b in bounds[tokens[0]]]
            _float_list(tokens[1:], path, ln, f"bone {tokens[0]!r}", bound)
    raise MotionDataError(path, None, "non-finite or out-of-bounds value")  # unreachable
