"""Acclaim ASF/AMC (CMU's native format: the skeleton in an ``.asf``, the motion in an ``.amc``)
into the BVH import path.

The ASF (Acclaim Skeleton File 1.10, M. Schafer 1994) gives ``:units`` (``length``: the factor
the file's lengths were multiplied by, ``angle deg|rad``), the ``:root`` (``order``: which
translation and rotation values an AMC frame gives for it and the order its rotations are
applied in, about fixed axes; ``axis`` and ``orientation``: its pre-set orientation;
``position``), each bone of ``:bonedata`` (``direction`` in the world's frame at rest,
``length``, ``axis A B C XYZ``: its local frame, ``dof rx ry rz``: the rotations an AMC frame
gives for it, in the order they apply) and the ``:hierarchy``. A bone starts where its parent
ends (the root's children where the root is) and turns with
``bone2world = parent2world @ C @ M @ C^T``, ``C`` its ``axis`` and ``M`` the frame's rotation
about C's axes, as CMU's own viewer computes it; the root's ``M`` from its values, the same way.

:func:`acclaim_motion` turns the pair into the BVH reader's structure (one joint per bone, at
the bone's start, named after it; a leaf bone's end as ``<bone>.end``), so joint-name presets,
the structural match, units, up axis and contacts are found as for BVH.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, InputError, quoted
from ecs_anim.core.files import read_text
from ecs_anim.core.rotations import quat_from_matrix, rot_axis
from ecs_anim.io.bvh import BvhMotion
from ecs_anim.io.contacts import ContactThresholds
from ecs_anim.io.fbx import bvh_motion_from_transforms
from ecs_anim.io.importing import CanonicalClip, FrameRange, canonical_clip, import_canonical
from ecs_anim.motion.clip import NormalizedMotion

F64 = NDArray[np.float64]

#: CMU captures at 120 Hz (mocap.cs.cmu.edu FAQ); an AMC file stores no rate.
DEFAULT_AMC_FPS = 120.0
_AXES = "XYZ"
_ROTATIONS = {"rx": 0, "ry": 1, "rz": 2}
_TRANSLATIONS = {"tx": 0, "ty": 1, "tz": 2}


@dataclass
class AsfBone:
    """One ASF bone: ``direction`` (3,) unit, world axes at rest; ``length`` in file units;
    ``axis2world`` (3, 3) its local frame C; ``dof`` the AMC values it takes, in order
    (``rx``, ``ry``, ``rz``); ``parent`` an index into the skeleton's bones (-1: the root)."""

    name: str
    direction: F64
    length: float
    axis2world: F64
    dof: list[str] = field(default_factory=list)
    parent: int = -1
    line: int = 0


@dataclass
class AsfSkeleton:
    """An ASF file: its bones in hierarchy order (parents first), the root's set-up and units.

    ``root_order``: the AMC root values' names in order (``tx`` ... ``rz``);
    ``root_position`` (3,) file units; ``root_axis2world`` (3, 3); ``length_unit``: the
    ``:units length`` factor; ``radians``: angles in radians (``angle rad``)."""

    bones: list[AsfBone]
    root_order: list[str]
    root_position: F64
    root_axis2world: F64
    length_unit: float = 1.0
    radians: bool = False
    path: str = "<asf>"


def _fixed_axes_rotation(names: list[str], angles_rad: F64) -> F64:
    """Rotations about fixed axes applied in the order of ``names`` (``rx``, ``rz``, ...):
    ``R_last @ ... @ R_first``; ``angles_rad`` (..., len(names)). Returns (..., 3, 3)."""
    out = np.broadcast_to(np.eye(3), angles_rad.shape[:-1] + (3, 3)).copy()
    for k, name in enumerate(names):
        out = rot_axis(_ROTATIONS[name], angles_rad[..., k]) @ out
    return out


def _axis_frame(values: F64, order: str, radians: bool) -> F64:
    """An ASF ``axis`` (three angles for X, Y, Z, applied in ``order``, e.g. ``XYZ``) as a
    rotation (3, 3)."""
    angles = values if radians else np.deg2rad(values)
    names = [f"r{a.lower()}" for a in order]
    return _fixed_axes_rotation(names, np.array([angles[_AXES.index(a)] for a in order]))


class _Text:
    """An Acclaim file's lines as (line number, tokens), comments and ``,()`` removed."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.lines = [(k, re.sub(r"[,()]", " ", line.split("#", 1)[0]).split())
                      for k, line in enumerate(read_text(path).splitlines(), start=1)]
        self.lines = [(k, tokens) for k, tokens in self.lines if tokens]

    def numbers(self, tokens: list[str], count: int, line: int, what: str) -> F64:
        """``count`` finite numbers from ``tokens``, or :class:`InputError` at ``line``."""
        if len(tokens) < count:
            raise InputError(self.path, f"{what}: expected {count} numbers, found "
                                        f"{quoted(' '.join(tokens), 60)}", line)
        try:
            values = np.array([float(t) for t in tokens[:count]])
        except ValueError:
            raise InputError(self.path, f"{what}: expected numbers, found "
                                        f"{quoted(' '.join(tokens[:count]), 60)}", line) from None
        if not np.all(np.isfinite(values)):
            raise InputError(self.path, f"{what}: values must be finite", line)
        return values


def read_asf(path: str | Path) -> AsfSkeleton:
    """Read an ASF skeleton. Raises :class:`InputError` naming the file and line on any
    malformation (a bone without ``direction`` or ``length``, an unknown ``dof``, a
    hierarchy naming an unknown bone or leaving one out, a unit that is no number)."""
    text = _Text(str(path))
    path = text.path
    section, radians, length_unit = "", False, 1.0
    root_order, root_axis, root_values = ["tx", "ty", "tz", "rx", "ry", "rz"], "XYZ", np.zeros(3)
    root_position = np.zeros(3)
    root_axis_line = 0
    raw: dict[str, dict[str, Any]] = {}
    bone: dict[str, Any] | None = None
    children: dict[str, list[str]] = {}
    for line, tokens in text.lines:
        key = tokens[0].lower()
        if key.startswith(":"):
            section = key
            continue
        if section == ":units":
            if key == "length":
                length_unit = float(text.numbers(tokens[1:], 1, line, "length")[0])
                if length_unit <= 0:
                    raise InputError(path, f"length: expected a positive factor, found {tokens[1]}",
                                     line)
            elif key == "angle":
                unit = tokens[1].lower() if len(tokens) > 1 else ""
                if unit not in ("deg", "rad"):
                    raise InputError(path, f"angle: expected deg or rad, found {quoted(unit)}", line)
                radians = unit == "rad"
        elif section == ":root":
            if key == "order":
                root_order = [t.lower() for t in tokens[1:]]
                bad = [t for t in root_order if t not in _ROTATIONS and t not in _TRANSLATIONS]
                if bad or len(set(root_order)) != len(root_order):
                    raise InputError(path, "order: expected distinct TX TY TZ RX RY RZ, found "
                                           f"{quoted(' '.join(tokens[1:]), 60)}", line)
            elif key == "axis":
                root_axis = tokens[1].upper() if len(tokens) > 1 else ""
                root_axis_line = line
            elif key == "position":
                root_position = text.numbers(tokens[1:], 3, line, "position")
            elif key == "orientation":
                root_values = text.numbers(tokens[1:], 3, line, "orientation")
        elif section == ":bonedata":
            if key == "begin":
                bone = {"line": line, "dof": []}
            elif key == "end":
                if bone is None or "name" not in bone:
                    raise InputError(path, "a bone ends with no name", line)
                missing = [k for k in ("direction", "length", "axis") if k not in bone]
                if missing:
                    raise InputError(path, f"bone {bone['name']!r} has no {', '.join(missing)}",
                                     bone["line"])
                raw[str(bone["name"])] = bone
                bone = None
            elif bone is not None:
                if key == "name" and len(tokens) > 1:
                    bone["name"] = tokens[1]
                elif key == "direction":
                    bone["direction"] = text.numbers(tokens[1:], 3, line, "direction")
                elif key == "length":
                    bone["length"] = float(text.numbers(tokens[1:], 1, line, "length")[0])
                elif key == "axis":
                    order = tokens[4].upper() if len(tokens) > 4 else ""
                    if sorted(order) != list(_AXES):
                        raise InputError(path, f"axis: expected three angles and an order such "
                                               f"as XYZ, found {quoted(' '.join(tokens[1:]), 60)}",
                                         line)
                    bone["axis"] = (text.numbers(tokens[1:], 3, line, "axis"), order)
                elif key == "dof":
                    dof = [t.lower() for t in tokens[1:]]
                    bad = [t for t in dof if t not in _ROTATIONS]
                    if bad:
                        raise InputError(path, f"dof {quoted(bad[0])}: only rotations (rx, ry, "
                                               "rz) are read; a bone's translation or length "
                                               "channel is not", line)
                    bone["dof"] = dof
        elif section == ":hierarchy" and key not in ("begin", "end"):
            for child in tokens[1:]:
                children.setdefault(tokens[0], []).append(child)
    if sorted(root_axis) != list(_AXES):
        raise InputError(path, f"root axis: expected an order such as XYZ, found {quoted(root_axis)}",
                         root_axis_line or None)
    if not raw:
        raise InputError(path, "no bone (the :bonedata section is missing or empty)")
    # Bones in hierarchy order, parents first, from the root.
    bones: list[AsfBone] = []
    index: dict[str, int] = {}
    queue = [("root", child) for child in children.get("root", [])]
    while queue:
        parent, name = queue.pop(0)
        if name not in raw:
            raise InputError(path, f":hierarchy names bone {name!r} (under {parent!r}), which "
                                   ":bonedata does not define")
        if name in index:
            raise InputError(path, f":hierarchy puts bone {name!r} under two parents")
        b = raw[name]
        values, order = b["axis"]
        direction = np.asarray(b["direction"], dtype=np.float64)
        norm = float(np.linalg.norm(direction))
        length = float(b["length"])
        if length < 0 or (norm == 0 and length > 0):
            raise InputError(path, f"bone {name!r}: a length of {length:g} along direction "
                                   f"{direction.tolist()}", b["line"])
        index[name] = len(bones)
        bones.append(AsfBone(name, direction / max(norm, 1e-300), length,
                             _axis_frame(values, order, radians), list(b["dof"]),
                             index.get(parent, -1), b["line"]))
        queue += [(name, child) for child in children.get(name, [])]
    orphans = [n for n in raw if n not in index]
    if orphans:
        raise InputError(path, f":hierarchy does not reach bone(s) {', '.join(orphans[:4])} "
                               "from the root")
    return AsfSkeleton(bones, root_order, root_position, _axis_frame(root_values, root_axis, radians),
                       length_unit, radians, path)


def read_amc(path: str | Path, skeleton: AsfSkeleton) -> tuple[F64, dict[str, F64], list[str]]:
    """Read an AMC motion for ``skeleton``: the root's values (n_frames, len(root_order)) and
    each bone's (n_frames, len(dof)), in the file's units, and warnings. Every frame must give
    every bone that has a dof. Raises :class:`InputError` naming the file and line: no frame, a
    frame lacking a bone (a truncated file), a bone the skeleton has not, a count of values
    that is not the bone's dof."""
    text = _Text(str(path))
    path = text.path
    warnings: list[str] = []
    moving = {b.name: b for b in skeleton.bones if b.dof}
    widths = {"root": len(skeleton.root_order), **{n: len(b.dof) for n, b in moving.items()}}
    frames: list[dict[str, F64]] = []
    frame_lines: list[int] = []
    for line, tokens in text.lines:
        if tokens[0].startswith(":"):
            stated = tokens[0].lower()
            if stated in (":degrees", ":radians") and (stated == ":radians") != skeleton.radians:
                warnings.append(f"{path}:{line}: says {tokens[0]} where the skeleton "
                                f"{skeleton.path} says angle {'rad' if skeleton.radians else 'deg'}; "
                                "read as the skeleton says")
            continue
        if len(tokens) == 1 and tokens[0].isdigit():
            frames.append({})
            frame_lines.append(line)
            continue
        name = tokens[0]
        if not frames:
            raise InputError(path, f"values for {name!r} before the first frame number", line)
        if name not in widths:
            known = "the root" if name == "root" else f"skeleton {Path(skeleton.path).name}"
            raise InputError(path, f"bone {name!r} is not one with a dof in {known}", line)
        frames[-1][name] = text.numbers(tokens[1:], widths[name], line, name)
        if len(tokens) - 1 != widths[name]:
            raise InputError(path, f"{name}: expected {widths[name]} values, found "
                                   f"{len(tokens) - 1}", line)
    if not frames:
        raise InputError(path, "the file holds no frame (no frame number line)")
    for k, (frame, line) in enumerate(zip(frames, frame_lines, strict=True)):
        lacking = [n for n in widths if n not in frame]
        if lacking:
            where = "the file ends there: truncated?" if k == len(frames) - 1 else "a frame must give every bone"
            raise InputError(path, f"frame {k + 1} lacks {', '.join(lacking[:4])}"
                                   f"{f' (+{len(lacking) - 4} more)' if len(lacking) > 4 else ''} "
                                   f"({where})", line)
    root = np.stack([f["root"] for f in frames])
    bones = {n: np.stack([f[n] for f in frames]) for n in moving}
    return root, bones, warnings


def acclaim_motion(skeleton: AsfSkeleton, root: F64, bone_values: dict[str, F64], fps: float,
                   path: str, warnings: list[str] | None = None) -> BvhMotion:
    """The BVH reader's structure for an ASF skeleton and its AMC values (:func:`read_amc`):
    a joint ``root`` at the root's position, one joint per bone at the bone's start, named
    after it, turning as the bone does, and ``<bone>.end`` at each leaf bone's end; lengths
    divided by the ASF's ``length`` factor, so in the unit it was written in (inches for CMU)."""
    scale = 1.0 / skeleton.length_unit
    n_frames = len(root)
    angle = (lambda v: v) if skeleton.radians else np.deg2rad
    order = skeleton.root_order
    rotations = [n for n in order if n in _ROTATIONS]
    root_turn = _fixed_axes_rotation(rotations, angle(root[:, [order.index(n) for n in rotations]]))
    position = np.tile(skeleton.root_position, (n_frames, 1))
    for name, axis in _TRANSLATIONS.items():
        if name in order:
            position[:, axis] += root[:, order.index(name)]
    c_root = skeleton.root_axis2world
    bones = skeleton.bones
    has_child = {b.parent for b in bones}
    leaves = [k for k in range(len(bones)) if k not in has_child]
    names = ["root", *(b.name for b in bones), *(f"{bones[k].name}.end" for k in leaves)]
    # Joint k + 1 is bone k; the root is joint 0; leaf ends follow.
    parents = np.array([-1, *(b.parent + 1 for b in bones), *(k + 1 for k in leaves)])
    n_joints = len(names)
    translation = np.zeros((n_frames, n_joints, 3))
    local = np.broadcast_to(np.eye(3), (n_frames, n_joints, 3, 3)).copy()
    translation[:, 0] = position * scale
    local[:, 0] = c_root @ root_turn @ c_root.T
    for k, b in enumerate(bones):
        if b.parent >= 0:
            above = bones[b.parent]
            translation[:, k + 1] = above.direction * above.length * scale
        if b.dof:
            turn = _fixed_axes_rotation(b.dof, angle(bone_values[b.name]))
            local[:, k + 1] = b.axis2world @ turn @ b.axis2world.T
    for j, k in enumerate(leaves, start=len(bones) + 1):
        translation[:, j] = bones[k].direction * bones[k].length * scale
    ones = np.ones((1, n_joints, 3))
    rest = (translation[:1], np.tile([0.0, 0.0, 0.0, 1.0], (1, n_joints, 1)), ones)
    frames = (translation, quat_from_matrix(local), np.ones((n_frames, n_joints, 3)))
    return bvh_motion_from_transforms(names, parents, rest, frames, 1.0 / fps, path, warnings)


def skeleton_for(amc: Path, asf: Path | None = None) -> Path:
    """The ASF skeleton of an AMC file: ``asf`` when given, else beside it the ``.asf`` of the
    same name, CMU's ``<subject>.asf`` (``01.asf`` for ``01_02.amc``), or the folder's only
    ``.asf``. Raises :class:`EcsAnimError` naming what was looked for."""
    if asf is not None:
        return asf
    folder = amc.parent
    candidates = list(dict.fromkeys([folder / f"{amc.stem}.asf",
                                     folder / f"{amc.stem.split('_')[0]}.asf"]))
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    others = sorted(folder.glob("*.asf"))
    if len(others) == 1:
        return others[0]
    found = f"the folder has {len(others)} .asf files" if others else "the folder has none"
    raise EcsAnimError(f"{amc}: no skeleton for this motion: looked for "
                       f"{' and '.join(c.name for c in candidates)} beside it ({found}); give it "
                       "with --body-model SKELETON.asf")


def import_amc(path: str | Path, asf: str | Path | None = None, map_spec: str | None = None,
               unit: str | None = None, thresholds: ContactThresholds = ContactThresholds(),
               up: str | None = None, trim: FrameRange | None = None,
               stature_m: float | None = None, treadmill: bool = True,
               fps: float | None = None) -> NormalizedMotion:
    """Read an AMC motion and its ASF skeleton (``asf``; None: :func:`skeleton_for`) and
    normalize them as :func:`~ecs_anim.io.importing.import_bvh` does a BVH file (same
    arguments; ``unit`` names the unit of the lengths divided by the ASF's ``length``, which
    is detected from the leg where not given). ``fps``: the AMC's frame rate (an AMC stores
    none; default :data:`DEFAULT_AMC_FPS`, CMU's). ``info.acclaim`` records the skeleton file,
    its units and the rate. Raises :class:`EcsAnimError` subclasses on bad input."""
    path = Path(path)
    skeleton_path = skeleton_for(path, None if asf is None else Path(asf))
    skeleton = read_asf(skeleton_path)
    root, bones, warnings = read_amc(path, skeleton)
    rate = DEFAULT_AMC_FPS if fps is None else fps
    if fps is None:
        warnings.append(f"{path}: an AMC stores no frame rate: {DEFAULT_AMC_FPS:g} fps assumed "
                        "(CMU's); --fps F gives another")
    if not (math.isfinite(rate) and rate > 0):
        raise InputError(path, f"frame rate {rate:g}: expected a positive number of frames per second")
    motion = acclaim_motion(skeleton, root, bones, rate, str(path), warnings)

    def make_clip() -> CanonicalClip:
        clip = canonical_clip(motion, map_spec, unit, up, stature_m)
        units = (f"ASF {skeleton_path.name}: lengths / its :units length {skeleton.length_unit:g}, "
                 f"angles in {'radians' if skeleton.radians else 'degrees'}")
        return replace(clip, unit_reason=f"{clip.unit_reason}; {units}")

    normalized = import_canonical(path, make_clip, trim, thresholds, treadmill)
    normalized.info["acclaim"] = {
        "skeleton": str(skeleton_path), "length_factor": skeleton.length_unit,
        "angle": "rad" if skeleton.radians else "deg",
        "fps": rate, "fps_from": "--fps" if fps is not None else "assumed (CMU's)",
    }
    return normalized


__all__ = ["AsfBone", "AsfSkeleton", "acclaim_motion", "import_amc", "read_amc", "read_asf",
           "skeleton_for"]
