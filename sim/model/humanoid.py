"""MJCF humanoids generated from ASF skeletons.

One body per ASF bone, named after it; the root is a free joint; one hinge per ASF dof about the
bone's ``axis`` frame, with the ASF limits; capsules sized from bone lengths; a floor plane and two
cameras that track the root.

Frames: body ``b`` sits at the start of bone ``b`` (its parent's end). Its rest orientation in the
file's axes is the bone's axis frame ``C_b``, so relative to its parent the body is rotated by
``C_parent^-1 C_b`` and the bone end lies at ``length * C_b^-1 direction`` in the body frame (site
``<bone>_end``). Acclaim composes a bone's motion as ``Rz Ry Rx`` for ``dof rx ry rz`` (first dof
applied first); MuJoCo composes a body's hinges left to right, so hinges are listed in reverse
dof order. The free joint's orientation carries the y-up to z-up turn of the whole figure.

Names in the XML: bone names must pass :func:`sim.acclaim.asf.check_bone_name` (the reader
refuses others with the line; :func:`build_mjcf` re-checks skeletons built in memory), so they need
no escaping; the free-text model name (the ASF's ``:name``) is XML-escaped.
"""

from __future__ import annotations

import hashlib
import os
from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np

from sim.acclaim.asf import check_bone_name, parse_asf
from sim.acclaim.records import Skeleton
from sim.errors import MotionDataError
from sim.files import MAX_ASF_BYTES, read_regular, write_atomic
from sim.model import quaternion as quat
from sim.model.mass import DEFAULT_BODY_MASS_KG, body_masses, capsule_volume
from sim.model.rotations import euler_matrix
from sim.paths import package_file

#: The canonical CMU skeleton (the mean of CMU's) and the shared humanoid generated from it,
#: shipped inside the package (``models/cmu_humanoid.xml`` in a checkout links to the latter).
CANONICAL_ASF = package_file("sim", "data/canonical.asf")
HUMANOID_XML = package_file("sim", "data/cmu_humanoid.xml")

# Capsule radii [m] for CMU's bone names; other bones get one from their length.
_RADIUS = {
    "lhipjoint": 0.045, "rhipjoint": 0.045, "lfemur": 0.065, "rfemur": 0.065,
    "ltibia": 0.05, "rtibia": 0.05, "lfoot": 0.04, "rfoot": 0.04, "ltoes": 0.03, "rtoes": 0.03,
    "lowerback": 0.09, "upperback": 0.1, "thorax": 0.1, "lowerneck": 0.05, "upperneck": 0.045,
    "head": 0.09, "lclavicle": 0.05, "rclavicle": 0.05, "lhumerus": 0.045, "rhumerus": 0.045,
    "lradius": 0.04, "rradius": 0.04, "lwrist": 0.03, "rwrist": 0.03, "lhand": 0.035,
    "rhand": 0.035, "lfingers": 0.02, "rfingers": 0.02, "lthumb": 0.02, "rthumb": 0.02,
}  # fmt: skip


def capsule_radius(name: str, length: float) -> float:
    """Capsule radius [m] for bone ``name`` of ``length`` [m]."""
    return _RADIUS.get(name, float(np.clip(0.2 * length, 0.015, 0.07)))


def _fmt(v) -> str:
    # Round to 1e-12 first: rounding noise (~1e-18) differs between numpy builds and would make
    # the generated model text machine-dependent; "+ 0.0" turns -0 into 0.
    x = np.round(np.atleast_1d(np.asarray(v, dtype=np.float64)), 12) + 0.0
    return " ".join(f"{a:.9g}" for a in x)


def bone_frames(skeleton: Skeleton) -> dict[str, np.ndarray]:
    """Rest axis frame ``C`` (3, 3) of every bone and of ``"root"``, in the file's axes."""
    frames = {"root": euler_matrix(skeleton.root_orientation, skeleton.root_axis_order)}
    for b in skeleton.bones:
        frames[b.name] = euler_matrix(b.axis, b.axis_order)
    return frames


def bone_end_offsets(skeleton: Skeleton) -> dict[str, np.ndarray]:
    """(3,) bone end in its own body frame [m]: ``length * C^-1 direction``."""
    C = bone_frames(skeleton)
    return {b.name: b.length * (C[b.name].T @ b.direction) for b in skeleton.bones}


ROOT_RADIUS = 0.07  # [m] the pelvis sphere on the root body


def geom_volumes(skeleton: Skeleton) -> dict[str, float]:
    """Volume [m^3] of every body's geom (``"root"``: the pelvis sphere), as ``build_mjcf`` shapes it."""
    out = {"root": capsule_volume(ROOT_RADIUS, 0.0)}
    for b in skeleton.bones:
        r = capsule_radius(b.name, b.length)
        out[b.name] = capsule_volume(r, b.length - r) if b.length > 2 * r else capsule_volume(r, 0)
    return out


def _quoted(value: str) -> str:
    """``value`` as a quoted XML attribute value: what ``xml.sax.saxutils.quoteattr`` writes
    (``&``, ``<``, ``>`` and the line breaks and tab as entities; single quotes around a value
    holding ``"`` but not ``'``, else double quotes, ``"`` then ``&quot;``), without importing
    it (it brings urllib, http and ssl with it: about 13 ms of every start-up)."""
    for char, entity in (("&", "&amp;"), (">", "&gt;"), ("<", "&lt;"), ("\n", "&#10;"),
                         ("\r", "&#13;"), ("\t", "&#9;")):  # fmt: skip
        value = value.replace(char, entity)
    if '"' not in value:
        return f'"{value}"'
    if "'" not in value:
        return f"'{value}'"
    return '"{}"'.format(value.replace('"', "&quot;"))


def build_mjcf(
    skeleton: Skeleton,
    *,
    model_name: str | None = None,
    body_mass_kg: float = DEFAULT_BODY_MASS_KG,
) -> str:
    """MJCF text of a humanoid for ``skeleton``.

    Args:
        skeleton: the ASF skeleton (bone lengths in metres).
        model_name: the model's name (default ``cmu_humanoid_<skeleton name>``).
        body_mass_kg: total body mass [kg], shared among the bodies by de Leva's segment table
            (``sim.model.mass``).

    Returns:
        XML with bodies named after bones, hinge joints ``<bone>_<dof>`` (radians, ASF limits),
        sites ``<bone>_end`` at bone ends, a floor at z = 0 and cameras ``follow`` and ``side``.
        Each body's one geom carries its segment mass; inertia follows from the geom's shape.

    Raises:
        MotionDataError: a bone name outside the grammar (or reserved), or a repeated bone name.
    """
    _check_names(skeleton)
    C = bone_frames(skeleton)
    ends = bone_end_offsets(skeleton)
    mass = body_masses(geom_volumes(skeleton), body_mass_kg)
    children: dict[str, list] = {}
    for b in skeleton.bones:
        children.setdefault(b.parent, []).append(b)
    name = model_name or f"cmu_humanoid_{skeleton.name or 'skeleton'}"
    out = _HEAD.format(name=_quoted(name), root_mass=f"{mass['root']:.6g}").split("\n")
    for b in children.get("root", []):
        _body_xml(b, 3, np.zeros(3), C, ends, mass, children, out)
    out += _TAIL
    return "\n".join(out) + "\n"


def _check_names(skeleton: Skeleton) -> None:
    """Every bone name within the grammar (:func:`sim.acclaim.asf.check_bone_name`), none twice."""
    seen = set()
    for b in skeleton.bones:
        problem = check_bone_name(b.name) or (
            f"duplicate bone {b.name!r}" if b.name in seen else None
        )
        if problem:
            raise MotionDataError(skeleton.path or None, b.line, problem)
        seen.add(b.name)


#: The model's lines before the root's child bodies (``{name}``: the quoted model name,
#: ``{root_mass}``: the pelvis' mass) and after them.
_HEAD = """<mujoco model={name}>
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.002" gravity="0 0 -9.81"/>
  <visual>
    <global offwidth="1280" offheight="720" elevation="-15"/>
    <quality shadowsize="0"/>
    <headlight ambient="0.35 0.35 0.35" diffuse="0.6 0.6 0.6" specular="0.1 0.1 0.1"/>
  </visual>
  <asset>
    <texture name="grid" type="2d" builtin="checker" width="256" height="256" \
rgb1="0.82 0.84 0.86" rgb2="0.7 0.73 0.76" mark="edge" markrgb="0.55 0.58 0.62"/>
    <material name="grid" texture="grid" texrepeat="1 1" texuniform="true" reflectance="0"/>
    <material name="body" rgba="0.85 0.55 0.3 1"/>
  </asset>
  <default>
    <joint type="hinge" damping="0.5" armature="0.01"/>
    <geom type="capsule" material="body" contype="1" conaffinity="1" density="1000"/>
    <site size="0.012" rgba="0.2 0.3 0.9 1" group="3"/>
  </default>
  <worldbody>
    <light name="sun" directional="true" pos="0 0 5" dir="-0.3 0.3 -1" castshadow="false"/>
    <geom name="floor" type="plane" size="0 0 0.05" material="grid"/>
    <body name="root" pos="0 0 1">
      <freejoint name="root"/>
      <camera name="follow" mode="trackcom" pos="0 -3.6 0.4" xyaxes="1 0 0 0 0.15 1"/>
      <camera name="side" mode="trackcom" pos="3.6 0 0.4" xyaxes="0 1 0 -0.15 0 1"/>
      <geom name="root" type="sphere" size="{ROOT_RADIUS}" mass="{root_mass}"/>
      <site name="root_end" pos="0 0 0"/>""".replace("{ROOT_RADIUS}", str(ROOT_RADIUS))
_TAIL = ["    </body>", "  </worldbody>", "</mujoco>"]


def _body_xml(b, depth: int, pos: np.ndarray, C, ends, mass, children, out: list[str]) -> None:
    """Append the lines of bone ``b``'s body (its hinges, geom and end site) and, nested in it,
    its children's to ``out``; ``pos``: its origin in its parent's frame [m]."""
    w = out.append
    ind = "  " * depth
    q = quat.from_matrix(C[b.parent].T @ C[b.name])
    w(f'{ind}<body name="{b.name}" pos="{_fmt(pos)}" quat="{_fmt(q)}">')
    for dof, (lo, hi) in reversed(list(zip(b.dofs, b.limits, strict=True))):
        axis = {"rx": "1 0 0", "ry": "0 1 0", "rz": "0 0 1"}[dof]
        rng = _fmt(np.deg2rad([lo, hi]))
        w(f'{ind}  <joint name="{b.name}_{dof}" axis="{axis}" range="{rng}"/>')
    end = ends[b.name]
    r = capsule_radius(b.name, b.length)
    if b.length > 2 * r:
        # Shorten the capsule by its radius at both ends so neighbours touch, not overlap.
        u = end / b.length
        w(f'{ind}  <geom name="{b.name}" fromto="{_fmt(u * r * 0.5)} {_fmt(end - u * r * 0.5)}"'
          f' size="{r:.4g}" mass="{mass[b.name]:.6g}"/>')  # fmt: skip
    else:
        w(f'{ind}  <geom name="{b.name}" type="sphere" pos="{_fmt(end / 2)}" size="{r:.4g}"'
          f' mass="{mass[b.name]:.6g}"/>')  # fmt: skip
    w(f'{ind}  <site name="{b.name}_end" pos="{_fmt(end)}"/>')
    for c in children.get(b.name, []):
        _body_xml(c, depth + 1, end, C, ends, mass, children, out)
    w(f"{ind}</body>")


@lru_cache(maxsize=64)
def _model_for_asf(path: str, digest: str):
    skeleton = parse_asf(path)
    try:
        return skeleton, mujoco.MjModel.from_xml_string(build_mjcf(skeleton))
    except ValueError as e:  # MuJoCo's compiler; MotionDataError (also a ValueError) passes
        if isinstance(e, MotionDataError):
            raise
        raise MotionDataError(path, None, f"cannot build a model: {e}") from e


def subject_model(asf_path: str | os.PathLike):
    """(skeleton, MjModel) of a subject's own humanoid, cached per file content.

    The cache key is the file's path and a hash of its bytes (not its mtime, which has coarse
    resolution on some file systems, so a quick rewrite of the same size could hit a stale entry).

    Raises:
        MotionDataError: unreadable or malformed ASF, or a skeleton MuJoCo refuses.
    """
    path = str(Path(asf_path).resolve())
    data = read_regular(asf_path, MAX_ASF_BYTES)  # a regular file of bounded size, never a device
    return _model_for_asf(path, hashlib.sha256(data).hexdigest())


@lru_cache(maxsize=1)
def canonical_skeleton() -> Skeleton:
    """The canonical CMU skeleton behind the shared humanoid (:data:`CANONICAL_ASF`)."""
    return parse_asf(CANONICAL_ASF)


@lru_cache(maxsize=1)
def humanoid_model():
    """(skeleton, MjModel) of the shared humanoid (:data:`HUMANOID_XML`)."""
    return canonical_skeleton(), mujoco.MjModel.from_xml_path(str(HUMANOID_XML))


def write_humanoid_xml(path: str | os.PathLike = HUMANOID_XML) -> Path:
    """Regenerate the shared humanoid (:data:`HUMANOID_XML`) from the canonical skeleton."""
    text = build_mjcf(canonical_skeleton(), model_name="cmu_humanoid")
    path = Path(path)
    write_atomic(path, lambda f: f.write(text.encode()))
    return path
