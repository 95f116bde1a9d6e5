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
from sim.files import MAX_AMC_BYTES, MAX_ASF_BYTES, excerpt, open_regular, read_regular, text_lines

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
            Bones with dofs that the file never mentions are zeros (read-only).
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


def _known(names, chars: int = 300) -> str:
    """``names`` for an error message: as many as fit in about ``chars`` characters, then how
    many there are in all (a hostile skeleton may have a thousand names of 64 characters)."""
    names = list(names)
    shown, size = [], 0
    for name in names:
        if size + len(name) > chars:
            return ", ".join(shown) + f", ... ({len(names)} in all)"
        shown.append(name)
        size += len(name) + 2
    return ", ".join(shown)


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


def _float_list(
    tokens: list[str], path: str, line: int, what: str, bound: float | list | None = None
) -> list[float]:
    """Finite numbers of ``tokens``, each at most ``bound`` (one for all, or one per token) in
    magnitude. Plain Python: this runs once per line on the checked AMC path."""
    try:
        values = [float(t) for t in tokens]
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        raise MotionDataError(path, line, f"non-numeric value {excerpt(bad)} in {what}") from None
    bounds = [bound] * len(values) if bound is None or isinstance(bound, (int, float)) else bound
    for t, v, b in zip(tokens, values, bounds, strict=True):
        if not math.isfinite(v):
            raise MotionDataError(path, line, f"non-finite value {excerpt(t)} in {what}")
        if b is not None and abs(v) > b:
            raise MotionDataError(
                path, line, f"value {excerpt(t, quote=False)} in {what} exceeds {b:g} in magnitude"
            )
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
                        path,
                        ln,
                        f"units length {excerpt(tokens[1], quote=False)} outside [{lo:g}, {hi:g}]",
                    )
                units["length"] = value
            elif len(tokens) >= 2 and tokens[0] == "angle":
                unit = tokens[1].lower()
                if unit not in ("deg", "rad"):
                    raise MotionDataError(
                        path, ln, f"angle unit {excerpt(tokens[1])}; expected deg or rad"
                    )
                units["angle"] = unit
        elif section == "root":
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
        bone["direction"] = _floats(tokens[1:], path, ln, "direction")
    elif key == "length":
        if len(tokens) != 2:
            raise MotionDataError(path, ln, "length needs 1 value")
        bone["length"] = _floats(tokens[1:], path, ln, "length")[0]
        bone["length_line"] = ln
        if not bone["length"] >= 0:
            raise MotionDataError(
                path, ln, f"negative bone length {excerpt(tokens[1], quote=False)}"
            )
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
            pair = _floats([lo, hi], path, lln, "limits", bone["angle_bound"])
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
                    f"unknown bone {excerpt(n)} in hierarchy; known: {_known(['root', *by_name])}",
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
            path, by_name[missing[0]]["line"], f"bones not in ':hierarchy': {_known(missing)}"
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
            f"hierarchy cycle: bones not reachable from root: {_known(sorted(cyclic))}",
        )
    return order


# ----------------------------------------------------------------------------------------- AMC


def parse_amc(path: str | os.PathLike, skeleton: Skeleton, *, strict: bool = False) -> Motion:
    """Read an AMC motion for ``skeleton`` (``:FULLY-SPECIFIED``, ``:DEGREES``; LF or CRLF).

    A file that ends part-way through its final frame (whole lines missing, as in CMU's own
    07_12.amc) loses that frame with a :class:`MotionDataWarning` and a note in ``Motion.notes``,
    unless ``strict``, where it is an error like any other truncated frame.

    Bounded memory: the file is read a chunk at a time (:func:`sim.files.text_lines`) and each
    chunk's values go straight into arrays, so the peak is the motion's own arrays (8 bytes per
    value the file spells out, at least 2 characters each, so at most 4x the file's size) plus a
    chunk. Bones the file never mentions share one read-only row of zeros.

    Returns:
        The motion with root translations in metres and rotations in degrees.

    Raises:
        MotionDataError: truncated frame, unknown bone, wrong number of values, non-numeric token,
            no frames...
    """
    path = str(path)
    parser = _AmcParser(path, skeleton, strict)
    with open_regular(path, MAX_AMC_BYTES) as f:  # regular files only, of bounded size
        for first_line, lines in text_lines(f, path, MAX_AMC_BYTES):
            parser.feed(first_line, lines)
    motion = parser.finish()
    for note in motion.notes:
        warnings.warn(note, MotionDataWarning, stacklevel=2)
    return motion


def _is_frame_number(token: str) -> bool:
    return _FRAME_NUMBER_RE.match(token) is not None


def _frame_number_line(raw: str) -> bool:
    """Whether ``raw`` is a line holding one token of digits (a frame number, valid or not)."""
    tokens = raw.split()
    return len(tokens) == 1 and tokens[0].isdigit()


class _AmcParser:
    """The AMC body as a state machine fed a chunk of lines at a time.

    Frames go to per-bone arrays: runs of frames laid out exactly like the first frame are
    converted by numpy a chunk at a time (the fast path); anything else goes line by line (the
    checked path), which names the offending line. Both accept the same files and give the same
    values: the fast path only takes what it can verify, and hands any doubt to the checked path.
    """

    ROWS = 256  # frames of the checked path held as Python lists before they become arrays

    def __init__(self, path: str, skeleton: Skeleton, strict: bool):
        self.path, self.skeleton, self.strict = path, skeleton, strict
        self.layout = {b.name: len(b.dofs) for b in skeleton.bones}
        self.layout["root"] = 6
        self.in_deg = skeleton.angles_in_degrees
        self.in_header, self.seen_text = True, False
        self.bounds: dict[str, list[float]] = {}
        self.first: int | None = None  # the file's number of its first frame
        self.n = 0  # frames closed
        self.names: tuple[str, ...] | None = None  # the first frame's bones, in file order
        self.current: dict | None = None  # the frame being read (checked path)
        self.current_line = 0
        self.rows: list[list] = []  # closed frames of the checked path, not yet arrays
        self.columns: dict[str, list[np.ndarray]] = {}  # bone -> (frames, dofs) pieces
        self.notes: list[str] = []

    # -- feeding ---------------------------------------------------------------------------------

    def feed(self, first_line: int, lines: list[str]) -> None:
        """Read the next chunk of lines; ``first_line``: the number of ``lines[0]``."""
        i = 0
        if self.in_header:
            i = self._header(lines)
            if self.in_header:
                return
        last = len(lines) - 1  # the chunk's last frame may go on in the next chunk: not fast
        while last > i and not _frame_number_line(lines[last]):
            last -= 1
        fast = True
        while i < len(lines):
            if fast and self.names is not None and i < last and _frame_number_line(lines[i]):
                self._close(None)
                done = self._fast(lines, i, last)
                if done > i:
                    i = done
                    continue
                fast = False  # irregular: the rest of this chunk goes line by line
            self._line(first_line + i, lines[i])
            i += 1

    def _header(self, lines: list[str]) -> int:
        """Skip blank lines, comments and ``:`` flags; returns the index of the first body line
        (the header ends there) or ``len(lines)``."""
        for i, raw in enumerate(lines):
            text = raw.strip()
            if text:
                self.seen_text = True
            if not text or text.startswith("#"):
                continue
            if text.startswith(":"):
                flag = text.split()[0].upper()
                if flag == ":DEGREES":
                    self.in_deg = True
                elif flag == ":RADIANS":
                    self.in_deg = False
                continue
            self.in_header = False
            self._set_bounds()
            return i
        return len(lines)

    def _set_bounds(self) -> None:
        """Bounds in the file's units: |translation| <= MAX_METRES, |angle| <= MAX_DEGREES."""
        angle = MAX_DEGREES if self.in_deg else float(np.deg2rad(MAX_DEGREES))
        self.bounds = {n: [angle] * k for n, k in self.layout.items()}
        for c in ("tx", "ty", "tz"):
            self.bounds["root"][self.skeleton.root_order.index(c)] = (
                MAX_METRES / self.skeleton.length_to_metres
            )

    # -- the checked path ------------------------------------------------------------------------

    def _line(self, ln: int, raw: str) -> None:
        path = self.path
        tokens = raw.split()
        if not tokens:
            return
        if len(tokens) == 1 and tokens[0].isdigit():
            if not _is_frame_number(tokens[0]):
                raise MotionDataError(
                    path, ln, f"frame number {excerpt(tokens[0], 20)} is not 1 to 12 ASCII digits"
                )
            self._close(None)
            number = int(tokens[0])
            if self.first is None:
                self.first = number
            elif number != self.first + self.n:
                raise MotionDataError(
                    path, ln, f"frame number {number}; expected {self.first + self.n}"
                )
            self.current, self.current_line = {}, ln
            return
        if self.current is None:
            raise MotionDataError(path, ln, f"expected a frame number, got {excerpt(tokens[0])}")
        name = tokens[0]
        if name not in self.layout:
            raise MotionDataError(
                path, ln, f"unknown bone {excerpt(name)}; known: {_known(sorted(self.layout))}"
            )
        if name in self.current:
            raise MotionDataError(path, ln, f"bone {name!r} appears twice in one frame")
        if len(tokens) - 1 != self.layout[name]:
            raise MotionDataError(
                path, ln, f"bone {name!r} needs {self.layout[name]} values, got {len(tokens) - 1}"
            )
        self.current[name] = _float_list(tokens[1:], path, ln, f"bone {name!r}", self.bounds[name])

    def _close(self, at_end: int | None) -> None:
        """Close the frame being read: check it has the first frame's bones, queue its values.

        ``at_end``: the file's last line when this is its final frame (an incomplete final frame
        is dropped with a note unless ``strict``)."""
        current = self.current
        if current is None:
            return
        self.current = None
        if self.names is None:
            if "root" not in current:
                raise MotionDataError(self.path, self.current_line, "frame has no 'root' line")
            self.names = tuple(current)
            self.columns = {name: [] for name in self.names}
        missing = set(self.names) - set(current)
        if missing:
            problem = f"truncated frame {self.first + self.n}: missing {_known(sorted(missing))}"
            if at_end is not None and not self.strict and self.n >= 1:
                where = f"{self.path}:{self.current_line}"
                self.notes.append(f"{where}: {problem}; dropped the incomplete final frame")
                return
            raise MotionDataError(self.path, self.current_line, problem)
        extra = set(current) - set(self.names)
        if extra:
            raise MotionDataError(
                self.path, self.current_line,
                f"frame has bones the first frame lacks: {_known(sorted(extra))}",
            )  # fmt: skip
        self.rows.append([current[name] for name in self.names])
        self.n += 1
        if len(self.rows) >= self.ROWS:
            self._flush()

    def _flush(self) -> None:
        """The checked path's queued frames as arrays, one per bone."""
        if not self.rows:
            return
        for k, name in enumerate(self.names):
            values = np.array([row[k] for row in self.rows], dtype=np.float64)
            self.columns[name].append(values.reshape(len(self.rows), self.layout[name]))
        self.rows = []

    # -- the fast path ---------------------------------------------------------------------------

    def _fast(self, lines: list[str], start: int, stop: int) -> int:
        """Convert the frames of ``lines[start:stop]`` (``start`` and ``stop`` frame-number
        lines) in one go when every one is laid out exactly like the first frame, their numbers
        follow on and every value is finite and within bounds; returns ``stop``, or ``start``
        (nothing done) so that the checked path reads them and names any problem."""
        names = self.names
        L = len(names) + 1
        if (stop - start) % L:
            return start
        T = (stop - start) // L
        number_lines = lines[start:stop:L]
        digits = "".join(number_lines)
        if not (digits.isascii() and digits.replace(" ", "").replace("\t", "").isdigit()):
            return start  # signs, underscores, unicode digits, other blanks: the checked path
        try:
            numbers = [int(x) for x in number_lines]
        except ValueError:
            return start
        expected = self.first + self.n
        if numbers != list(range(expected, expected + T)) or any(
            len(x.strip()) > 12 for x in number_lines
        ):
            return start
        block = {}
        for k, name in enumerate(names, start=1):
            count = self.layout[name]
            slot = lines[start + k : stop : L]
            prefix = name + " " if count else name
            joined = "\n".join(slot)
            if not joined.startswith(prefix) or joined.count("\n" + prefix) != T - 1:
                return start
            if count == 0:
                if any(line != name for line in slot):
                    return start
                continue
            n = len(prefix)
            try:  # numpy's C reader; a wrong count or a bad token raises
                values = np.loadtxt(
                    [line[n:] for line in slot], dtype=np.float64, ndmin=2, comments=None
                )
            except (ValueError, IndexError):
                return start
            if values.shape != (T, count) or not _within(values, self.bounds[name]):
                return start
            block[name] = values
        self._flush()
        for name, values in block.items():
            self.columns[name].append(values)
        self.n += T
        return stop

    # -- the result ------------------------------------------------------------------------------

    def finish(self) -> Motion:
        path = self.path
        if not self.seen_text:
            raise MotionDataError(path, None, "empty file")
        if self.in_header:
            raise MotionDataError(path, None, "no frames")
        had_frame = self.current is not None or self.n > 0
        self._close(at_end=True)
        if not had_frame:
            raise MotionDataError(path, None, "no frames")
        self._flush()
        T = self.n
        skeleton = self.skeleton
        columns = self.columns
        order = [skeleton.root_order.index(c) for c in ROOT_CHANNELS]
        root = _concatenate(columns.pop("root"), T, 6, order)
        root[:, :3] *= skeleton.length_to_metres
        if not self.in_deg:
            np.rad2deg(root[:, 3:], out=root[:, 3:])
        angles = {}
        for b in skeleton.bones:
            if not b.dofs:
                continue
            pieces = columns.pop(b.name, None)
            if pieces is None:  # never mentioned: zeros, one shared read-only row
                angles[b.name] = np.broadcast_to(np.zeros(len(b.dofs)), (T, len(b.dofs)))
                continue
            a = _concatenate(pieces, T, len(b.dofs))
            del pieces
            if not self.in_deg:
                np.rad2deg(a, out=a)
            angles[b.name] = a
        # Finite: every value passed its bound (finite, bounded), and rad2deg of a bounded value
        # is finite; the zeros of unmentioned bones are too.
        return Motion(
            path=path, root=root, angles=angles, first_frame=self.first, notes=tuple(self.notes)
        )


def _concatenate(pieces: list[np.ndarray], T: int, k: int, order=None) -> np.ndarray:
    """(T, k) float64 of ``pieces`` stacked (columns in ``order`` when given), emptying the list
    as they are copied, so that at most one piece is held twice."""
    out = np.empty((T, k))
    row = 0
    pieces.reverse()
    while pieces:
        piece = pieces.pop()
        out[row : row + len(piece)] = piece if order is None else piece[:, order]
        row += len(piece)
    return out


def _within(values: np.ndarray, bound: list[float]) -> bool:
    """Every value of ``values`` (frames, channels) finite and within its channel's bound."""
    if not len(values):
        return True
    b = np.asarray(bound)
    # min/max reduce without temporaries; nan propagates
    return bool((values.max(axis=0) <= b).all() and (values.min(axis=0) >= -b).all())
