"""FBX reading through ``ufbx`` (the optional extra ``ecs_anim[fbx]``): a scene's skeleton and one
animation stack (take), sampled at the scene's frame rate, as the BVH reader's structure.

:func:`read_fbx` gives a :class:`~ecs_anim.io.bvh.BvhMotion`: the skeleton's joints in
topological order with their rest-pose OFFSETs (the scene's static node transforms, in the file's
axes and units), and per frame each joint's rotation *from its rest orientation* as three Euler
channels (ZXY), plus position channels on the root and on any joint whose translation is
animated. So the BVH path's forward kinematics gives back the FBX joints' positions (to float
precision), and its orientations are the rest pose's axes carried by the motion, exactly what
a BVH's rest pose means; :func:`import_fbx` then maps, scales, turns and normalizes it as
:func:`~ecs_anim.io.importing.import_bvh` does (presets, structure, ``--map``; unit and up-axis
detection; rest and glitch frames; contacts). FBX rigs give their bones rest orientations of
their own (joint orients, pre-rotations, bones along X): those are taken out here, so nothing
downstream sees them.

Which nodes are the skeleton: the nodes with a bone attribute (``LimbNode``) and the nodes above
them (a ``Armature`` or ``Reference`` null), under the top node with the most bones (a second
skeleton or a prop hierarchy is left out, with a warning); with no bone at all, every null node.
A leaf named as a chain's end (``HeadTop_End``, ``Head_end``, ``Bip01 HeadNub``, ``Head.end``)
that does not move against its parent is an End Site, as a BVH converter writes it.
"""

from __future__ import annotations

import ctypes
import math
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, InputError, did_you_mean, listed, quoted
from ecs_anim.core.rotations import matrix_from_quat, matrix_to_euler
from ecs_anim.io.bvh import BvhJoint, BvhMotion, BvhSkeleton, rest_positions
from ecs_anim.io.contacts import ContactThresholds
from ecs_anim.io.importing import (
    PLAUSIBLE_LEG_M,
    UNITS,
    CanonicalClip,
    FrameRange,
    canonical_clip,
    import_canonical,
)
from ecs_anim.motion.clip import NormalizedMotion

F64 = NDArray[np.float64]

#: What to install when ufbx is missing (said in the one-line error).
INSTALL_HINT = "pip install 'ecs_anim[fbx]'"
#: The longest take read, in frames (a day at 120 Hz is about 1e7): beyond it the file's times
#: or frame rate are wrong.
MAX_FRAMES = 10_000_000
#: A leaf node named as a chain's end (read as an End Site when it does not move).
_END_NAME = re.compile(r"(end|nub)[\d_.\-\s]*$", re.IGNORECASE)
#: ufbx's element types (``ufbx.ElementType``) of a bone and of a null node.
_BONE, _EMPTY = 5, 6
#: ufbx's ``CoordinateAxis``: POSITIVE_X, NEGATIVE_X, POSITIVE_Y, ... as our axis names.
_AXES = ("x", "-x", "y", "-y", "z", "-z")


def _ufbx() -> Any:
    """The ufbx module, or an :class:`EcsAnimError` saying how to install it."""
    try:
        import ufbx  # type: ignore[import-untyped, import-not-found, unused-ignore]
    except ImportError:
        raise EcsAnimError(f"reading FBX files needs the ufbx package: {INSTALL_HINT}") from None
    return ufbx


class _Elements:
    """Keeps every ufbx scene element (node, take) this module touches, each object once.

    ufbx 0.0.5's wrappers are cached per element without a reference of the cache's own: an
    element asked for a second time comes back one reference short, and one whose wrapper died
    comes back freed (a crash, not an error). So each element is asked for as few times as
    possible, its wrapper is kept here until the scene is done, and a wrapper handed back again
    gets the reference it lacks. :meth:`release` drops them all before the scene goes.
    """

    def __init__(self) -> None:
        self._kept: dict[int, Any] = {}

    def __call__(self, obj: Any) -> Any:
        if obj is None:
            return None
        if id(obj) in self._kept:
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))
        else:
            self._kept[id(obj)] = obj
        return obj

    def release(self) -> None:
        self._kept.clear()


@dataclass
class FbxMotion:
    """An FBX scene's skeleton and one take, as the BVH reader gives a file (:func:`read_fbx`).

    ``motion``: joints, rest OFFSETs and per-frame channels in the file's axes and units;
    ``take``: the take read; ``takes``: every take of the file, in its order;
    ``unit_m``: metres per file unit as the file states it (``UnitScaleFactor`` / 100);
    ``up``: the up axis the file states (``"y"``, ``"z"``, ``"-y"``, ...; "" if none).
    """

    motion: BvhMotion
    take: str
    takes: list[str]
    unit_m: float
    up: str


def read_fbx(path: str | Path, take: str | None = None, rest_only: bool = False) -> FbxMotion:
    """Read an FBX file's skeleton and one take (``take``: its name; None: the first, with a
    warning naming the others when there are several). Raises :class:`InputError` naming the
    file (a damaged or truncated file, no skeleton, no take, an unknown take), and
    :class:`EcsAnimError` when ufbx is not installed.

    ``rest_only``: the skeleton alone, as a rig is read (``export --onto RIG.fbx``): one frame,
    its rest pose (the nodes' own transforms), from a file with or without takes (``take``
    "")."""
    ufbx = _ufbx()
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "no such file" if not path.exists() else "not a file")
    try:
        scene = ufbx.load_file(str(path), ignore_geometry=True, ignore_embedded=True)
    except ufbx.UfbxError as exc:
        what = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(path, f"not a readable FBX file ({what}; damaged or truncated?)") from None
    held = _Elements()
    try:
        return _read_scene(ufbx, scene, held, path, take, rest_only)
    except (ufbx.UfbxError, ValueError, RuntimeError) as exc:
        raise InputError(path, f"cannot read the FBX scene: {exc}") from None
    finally:
        held.release()
        del scene


def _read_scene(ufbx: Any, scene: Any, held: _Elements, path: Path,
                take: str | None, rest_only: bool) -> FbxMotion:
    settings = scene.settings
    fps = float(settings.frames_per_second)
    unit_m = float(settings.unit_meters)
    up_code = int(settings.axes.up)
    up = _AXES[up_code] if 0 <= up_code < len(_AXES) else ""
    stacks_list = scene.anim_stacks
    stacks = [held(stacks_list[i]) for i in range(len(stacks_list))]
    names = [str(s.name) for s in stacks]
    if rest_only:
        warnings: list[str] = []
        joint_names, parents, rest, _ = _skeleton(scene, held, path, warnings)
        motion = bvh_motion_from_transforms(joint_names, parents, rest, rest,
                                            1.0 / fps if math.isfinite(fps) and fps > 0 else 1.0 / 30,
                                            str(path), warnings)
        return FbxMotion(motion, "", names, unit_m, up)
    if not stacks:
        raise InputError(path, "no animation in the file (no take, AnimationStack): nothing to "
                               "import")
    warnings = []
    if take is None:
        index = 0
        if len(stacks) > 1:
            warnings.append(f"{path}: {len(stacks)} takes ({listed(quoted(n) for n in names)}); "
                            f"read the first, {quoted(names[0])} (--take NAME reads another)")
    elif take in names:
        index = names.index(take)
    else:
        raise InputError(path, f"no take {quoted(take)}{did_you_mean(take, names, True)}; the "
                               f"file's takes: {listed(quoted(n) for n in names)}")
    stack = stacks[index]
    if not (math.isfinite(fps) and fps > 0):
        raise InputError(path, f"the scene's frame rate is {fps:g} fps: not a positive number")
    begin, end = float(stack.time_begin), float(stack.time_end)
    span = (end - begin) * fps
    if not (math.isfinite(span) and 0 <= span < MAX_FRAMES):
        raise InputError(path, f"take {quoted(names[index])} runs from {begin:g} s to {end:g} s "
                               f"at {fps:g} fps: no frame range that can be read")
    n_frames = math.floor(span + 1e-6) + 1
    joint_names, parents, rest, joint_nodes = _skeleton(scene, held, path, warnings)
    anim = stack.anim
    n_joints = len(joint_nodes)
    translation = np.empty((n_frames, n_joints, 3))
    rotation = np.empty((n_frames, n_joints, 4))
    scale = np.empty((n_frames, n_joints, 3))
    for f in range(n_frames):
        t = begin + f / fps
        for j, node in enumerate(joint_nodes):
            tr = ufbx.evaluate_transform(anim, node, t)
            translation[f, j], rotation[f, j], scale[f, j] = tr.translation, tr.rotation, tr.scale
    motion = bvh_motion_from_transforms(joint_names, parents, rest, (translation, rotation, scale),
                                        1.0 / fps, str(path), warnings)
    return FbxMotion(motion, names[index], names, unit_m, up)


def _skeleton(scene: Any, held: _Elements, path: Path, warnings: list[str]
              ) -> tuple[list[str], NDArray[np.intp], tuple[F64, F64, F64], list[Any]]:
    """The scene's skeleton (:func:`_skeleton_nodes`): its joints' unique names, parents
    (n_joints,), rest transforms (translation, quaternion, scale: (1, n_joints, 3 / 4 / 3),
    each in its parent's frame) and ufbx nodes."""
    node_list = scene.nodes
    nodes = [held(node_list[i]) for i in range(len(node_list))]
    by_id = {int(n.typed_id): k for k, n in enumerate(nodes)}
    parent = []
    for n in nodes:
        p = held(n.parent)
        parent.append(-1 if p is None or bool(p.is_root) else by_id[int(p.typed_id)])
    is_root = [bool(n.is_root) for n in nodes]
    kinds = [int(n.attrib_type) for n in nodes]
    chosen, note = _skeleton_nodes(parent, kinds, is_root, [str(n.name) for n in nodes])
    if not chosen:
        raise InputError(path, "no skeleton in the scene (no bone, LimbNode, nor null node)")
    if note:
        warnings.append(f"{path}: {note}")
    joint_nodes = [nodes[k] for k in chosen]
    slot = {k: i for i, k in enumerate(chosen)}
    parents = np.array([slot.get(parent[k], -1) for k in chosen], dtype=np.intp)
    local = [n.local_transform for n in joint_nodes]
    rest = (np.array([[r.translation for r in local]], dtype=np.float64),
            np.array([[r.rotation for r in local]], dtype=np.float64),
            np.array([[r.scale for r in local]], dtype=np.float64))
    names = _unique([str(n.name) for n in joint_nodes], path, warnings)
    return names, parents, rest, joint_nodes


def _skeleton_nodes(parent: list[int], kinds: list[int], is_root: list[bool],
                    names: list[str]) -> tuple[list[int], str]:
    """The scene nodes that make the skeleton, in topological order (parents first), and a
    note on what was left out ("" if nothing): bone nodes and the nodes above them, under the
    top node with the most bones; with no bone, the null nodes."""
    n = len(parent)
    marked = [kinds[k] == _BONE and not is_root[k] for k in range(n)]
    if not any(marked):
        marked = [kinds[k] == _EMPTY and not is_root[k] for k in range(n)]
    keep = [False] * n
    top = list(range(n))
    for k in range(n):
        if marked[k]:
            j = k
            while j >= 0 and not is_root[j]:
                keep[j] = True
                j = parent[j]
    for k in range(n):
        while parent[top[k]] >= 0:
            top[k] = parent[top[k]]
    bones_under: dict[int, int] = {}
    for k in range(n):
        if marked[k]:
            bones_under[top[k]] = bones_under.get(top[k], 0) + 1
    if not bones_under:
        return [], ""
    best = max(bones_under, key=lambda k: bones_under[k])
    note = ""
    others = [names[k] for k in bones_under if k != best]
    if others:
        note = (f"{len(bones_under)} skeletons in the scene; read the one under "
                f"{quoted(names[best])} ({bones_under[best]} bones), not {listed(quoted(o) for o in others)}")
    children: dict[int, list[int]] = {}
    for k in range(n):
        if keep[k] and top[k] == best and k != best:
            children.setdefault(parent[k], []).append(k)
    order, stack = [], [best]
    while stack:
        k = stack.pop()
        order.append(k)
        stack.extend(reversed(children.get(k, [])))
    return order, note


def _unique(names: list[str], path: Path, warnings: list[str]) -> list[str]:
    """Names made unique as the BVH reader does (``Spine`` again -> ``Spine#2``, warned)."""
    seen: dict[str, int] = {}
    out = []
    for name in names:
        if name in seen:
            seen[name] += 1
            renamed = f"{name}#{seen[name]}"
            warnings.append(f"{path}: node name {quoted(name)} is used again; read as "
                            f"{quoted(renamed)}")
            out.append(renamed)
        else:
            seen[name] = 1
            out.append(name)
    return out


def global_transforms(parents: NDArray[np.intp], translation: F64, quat: F64, scale: F64
                      ) -> tuple[F64, F64]:
    """Joint orientations and positions in the scene from local transforms (FBX's default
    inheritance: a parent's scale scales its children's translations, orientations carry no
    scale).

    ``parents`` (n_joints,), parents first (-1: the scene); ``translation`` (n_frames, n_joints,
    3), ``quat`` (n_frames, n_joints, 4) scalar-last, ``scale`` (n_frames, n_joints, 3): each
    joint in its parent's frame. Returns ``joint2file`` (n_frames, n_joints, 3, 3) and
    ``positions`` (n_frames, n_joints, 3)."""
    local = matrix_from_quat(quat)
    joint2file = np.empty_like(local)
    linear = np.empty_like(local)  # orientation with the scales, for children's translations
    positions = np.empty_like(translation)
    for j, p in enumerate(parents):
        scaled = local[:, j] * scale[:, j, None, :]
        if p < 0:
            joint2file[:, j], linear[:, j], positions[:, j] = local[:, j], scaled, translation[:, j]
            continue
        joint2file[:, j] = joint2file[:, p] @ local[:, j]
        linear[:, j] = linear[:, p] @ scaled
        positions[:, j] = positions[:, p] + np.einsum("fab,fb->fa", linear[:, p], translation[:, j])
    return joint2file, positions


#: A joint's translation counts as animated (it gets position channels) where it leaves its rest
#: OFFSET by more than this fraction of the skeleton's longest OFFSET.
MOVING_FRACTION = 1e-7


def bvh_motion_from_transforms(names: list[str], parents: NDArray[np.intp],
                               rest: tuple[F64, F64, F64], frames: tuple[F64, F64, F64],
                               frame_time_s: float, path: str,
                               warnings: list[str] | None = None) -> BvhMotion:
    """The BVH reader's structure for a skeleton given by local transforms.

    ``rest`` and ``frames``: (translation, quaternion, scale) of each joint in its parent's
    frame, shapes (1 or n_frames, n_joints, 3 / 4 / 3), as :func:`global_transforms` takes them.
    Each joint's OFFSET is its rest position less its parent's; its rotation channels (ZXY) give
    its orientation relative to its rest orientation (``joint2file @ rest_joint2file^T``) in its
    parent's such frame, so every joint is unrotated in the rest pose, as in a BVH. The root,
    and any joint whose translation moves, also get position channels (replacing the OFFSET)."""
    rest_orient, rest_pos = global_transforms(parents, *rest)
    orient, positions = global_transforms(parents, *frames)
    delta = orient @ np.swapaxes(rest_orient, -1, -2)  # (F, n, 3, 3): motion from the rest
    n_frames, n_joints = positions.shape[:2]
    parent_delta = np.where(parents[None, :, None, None] >= 0, delta[:, np.maximum(parents, 0)],
                            np.eye(3))
    local = np.swapaxes(parent_delta, -1, -2) @ delta
    parent_pos = np.where(parents[None, :, None] >= 0, positions[:, np.maximum(parents, 0)], 0.0)
    moved = np.einsum("fjba,fjb->fja", parent_delta, positions - parent_pos)  # (F, n, 3)
    parent_rest = np.where(parents[:, None] >= 0, rest_pos[0, np.maximum(parents, 0)], 0.0)
    offsets = rest_pos[0] - parent_rest
    size = max(float(np.max(np.linalg.norm(offsets, axis=-1))), 1e-12)
    moving = np.max(np.linalg.norm(moved - offsets, axis=-1), axis=0) > MOVING_FRACTION * size
    angles = matrix_to_euler(local, "ZXY")  # (F, n, 3)
    has_child = np.zeros(n_joints, dtype=bool)
    has_child[parents[parents >= 0]] = True
    joints: list[BvhJoint] = []
    columns: list[F64] = []
    for j in range(n_joints):
        p = int(parents[j])
        end_site = p >= 0 and not has_child[j] and not moving[j] and bool(_END_NAME.search(names[j]))
        channels = [] if end_site else ["Zrotation", "Xrotation", "Yrotation"]
        if not end_site and (p < 0 or moving[j]):
            channels = ["Xposition", "Yposition", "Zposition", *channels]
            columns.append(moved[:, j])
        if not end_site:
            columns.append(angles[:, j])
        joints.append(BvhJoint(name=names[j], parent=p, offset=offsets[j], channels=channels,
                               is_end_site=end_site))
    channels_array = np.concatenate(columns, axis=1) if columns else np.zeros((n_frames, 0))
    return BvhMotion(BvhSkeleton(joints, path), channels_array, frame_time_s, warnings or [])


def import_fbx(path: str | Path, map_spec: str | None = None, unit: str | None = None,
               thresholds: ContactThresholds = ContactThresholds(),
               up: str | None = None, trim: FrameRange | None = None,
               stature_m: float | None = None, treadmill: bool = True,
               take: str | None = None) -> NormalizedMotion:
    """Read an FBX file's skeleton and one take (``take``; None: the first) and normalize it,
    as :func:`~ecs_anim.io.importing.import_bvh` does a BVH file (same arguments). The unit is
    the one the file states (``UnitScaleFactor``) where it makes a human leg, else detected from
    the leg as for BVH; ``info.fbx`` records the take, the file's takes and what the file
    states. Raises :class:`EcsAnimError` subclasses on bad input."""
    path = Path(path)
    fbx = read_fbx(path, take)
    normalized = import_canonical(path, lambda: fbx_canonical_clip(fbx, map_spec, unit, up, stature_m),
                                  trim, thresholds, treadmill)
    normalized.info["fbx"] = {"take": fbx.take, "takes": fbx.takes,
                              "stated_unit_m": fbx.unit_m, "stated_up": fbx.up,
                              "joints": len(fbx.motion.skeleton.joints)}
    return normalized


def fbx_canonical_clip(fbx: FbxMotion, map_spec: str | None = None, unit: str | None = None,
                       up: str | None = None, stature_m: float | None = None) -> CanonicalClip:
    """:func:`~ecs_anim.io.importing.canonical_clip` of the FBX motion, in the unit the file
    states where no ``unit`` or ``stature_m`` is given and that unit makes a human leg; the up
    axis detected as for BVH, its reason saying when the file states another."""
    stated = fbx.unit_m
    name = next((n for n, s in UNITS.items() if math.isclose(s, stated, rel_tol=1e-9)),
                f"{stated:.6g}")
    use_stated = unit is None and stature_m is None and math.isfinite(stated) and stated > 0
    clip = canonical_clip(fbx.motion, map_spec, name if use_stated else unit, up, stature_m)
    stated_text = f"the file states {stated:.6g} m per unit (UnitScaleFactor {100 * stated:g})"
    if use_stated:
        leg_m = _rest_leg(fbx.motion.skeleton, clip) * stated
        if PLAUSIBLE_LEG_M[0] <= leg_m <= PLAUSIBLE_LEG_M[1]:
            clip = replace(clip, unit=name, unit_reason=f"{stated_text}: thigh + shank = "
                                                        f"{leg_m:.3f} m")
        else:
            clip = canonical_clip(fbx.motion, map_spec, None, up, None)
            clip = replace(clip, unit_reason=f"{clip.unit_reason} ({stated_text}, which makes "
                                             f"the leg {leg_m:.3g} m: not used)")
    if up is None and fbx.up and clip.up_axis != fbx.up:
        clip = replace(clip, up_reason=f"{clip.up_reason}; the file states {fbx.up.upper()} up")
    return clip


def _rest_leg(skeleton: BvhSkeleton, clip: CanonicalClip) -> float:
    """Thigh + shank in the rest pose, in file units (the mean of both legs)."""
    rest = rest_positions(skeleton)
    src = clip.joint_map.source
    total = 0.0
    for s in "lr":
        hip, knee, ankle = (src[f"{p}_{s}"] for p in ("hip", "knee", "ankle"))
        if hip is None or knee is None or ankle is None:
            return math.nan
        total += float(np.linalg.norm(rest[knee] - rest[hip]) + np.linalg.norm(rest[ankle] - rest[knee]))
    return 0.5 * total
