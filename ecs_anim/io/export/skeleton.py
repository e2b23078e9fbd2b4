"""The export skeleton: the canonical joints as a rigid hierarchy with rest offsets and local
rotations, shared by the BVH and glTF writers.

BVH files follow the format's own convention (DESIGN §8): Y up, the character facing +Z with its
left along +X in the rest pose (a T-pose), metres, one frame per line, three rotation channels
(ZXY) per joint and six on the root. Besides the canonical joints the hierarchy has zero-length
joints where one joint has several children that move independently (``pelvis_l``,
``pelvis_r``, ``lumbar``, ``cervical``, ``clavicle_l``, ``clavicle_r``), so every exported
position is exact, not a best fit.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, InputError, did_you_mean
from ecs_anim.core.morphology import PRESET_SPECS, Morphology, load_morphology_yaml
from ecs_anim.core.normalized import DecodedPose, decode
from ecs_anim.core.rotations import frame_from_axes, rotation_between
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import LENGTH_INDEX, REST_HIP_DIR_LEFT
from ecs_anim.io.bvh import read_bvh
from ecs_anim.io.importing import YUP_TO_ZUP, canonical_clip, source_morphology
from ecs_anim.motion.clip import NormalizedMotion

F64 = NDArray[np.float64]

#: Rest body axes (x forward, y left, z up) -> BVH axes (forward +Z, left +X, up +Y).
BODY_TO_BVH_REST = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
EULER_ORDER = "ZXY"
TOE_TIP_FRACTION = 0.4  # toe End Site length as a fraction of the foot (cosmetic only)


def resolve_morphology(spec: str, motion: NormalizedMotion) -> tuple[Morphology, bool]:
    """``source``, a preset name, a morphology YAML or a BVH skeleton -> (body, is_source)."""
    if spec == "source":
        return motion.source_morphology, True
    if spec in PRESET_SPECS:
        return Morphology.preset(spec), False
    path = Path(spec)
    if path.suffix.lower() in (".yaml", ".yml"):
        if not path.exists():
            raise InputError(path, "no such morphology file")
        return load_morphology_yaml(path), False
    if path.suffix.lower() == ".bvh":
        try:
            clip = canonical_clip(read_bvh(path))
            return source_morphology(clip.positions, path.stem), False
        except InputError:
            raise
        except (EcsAnimError, ValueError) as exc:  # unmappable, unknown unit, zero-length bone
            raise InputError(path, f"cannot take a morphology from this skeleton: {exc}") from None
    hint = did_you_mean(spec, list(PRESET_SPECS) + ["source"], parenthesized=True)
    raise EcsAnimError(f"--morphology {spec}: not 'source', a preset{hint}, a .yaml or a .bvh file; "
                       f"presets: {', '.join(PRESET_SPECS)}")


def play_on(motion: NormalizedMotion, morph: Morphology, is_source: bool) -> DecodedPose:
    """Decode every frame on ``morph`` (with the source's stretch when it is the source body)."""
    return decode(motion.poses, morph.lengths, use_stretch=is_source)


Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class _ExportJoint:
    """A joint of the exported hierarchy; offsets are (length name or "", rest direction in
    body axes, scale)."""

    name: str
    parent: str | None
    rest_offset: tuple[str, Vec3, float]
    end_site: tuple[str, Vec3, float] | None = None


def _side(s: str) -> float:
    return 1.0 if s == "l" else -1.0


def _axis(axis: int, sign: float = 1.0) -> Vec3:
    v = [0.0, 0.0, 0.0]
    v[axis] = sign
    return (v[0], v[1], v[2])


def _rest_hip(s: str) -> Vec3:
    x, y, z = REST_HIP_DIR_LEFT
    return (x, _side(s) * y, z)


EXPORT_JOINTS: tuple[_ExportJoint, ...] = (
    _ExportJoint("pelvis", None, ("", _axis(2), 0.0)),
    *[j for s in "lr" for j in (
        _ExportJoint(f"pelvis_{s}", "pelvis", ("", _axis(2), 0.0)),
        _ExportJoint(f"hip_{s}", f"pelvis_{s}", (f"pelvis_{s}", _rest_hip(s), 1.0)),
        _ExportJoint(f"knee_{s}", f"hip_{s}", (f"thigh_{s}", _axis(2, -1.0), 1.0)),
        _ExportJoint(f"ankle_{s}", f"knee_{s}", (f"shank_{s}", _axis(2, -1.0), 1.0)),
        _ExportJoint(f"toe_{s}", f"ankle_{s}", (f"foot_{s}", _axis(0), 1.0),
                     end_site=(f"foot_{s}", _axis(0), TOE_TIP_FRACTION)),
    )],
    _ExportJoint("lumbar", "pelvis", ("", _axis(2), 0.0)),
    _ExportJoint("spine_1", "lumbar", ("spine_lower", _axis(2), 1.0)),
    _ExportJoint("spine_2", "spine_1", ("spine_middle", _axis(2), 1.0)),
    _ExportJoint("neck", "spine_2", ("spine_upper", _axis(2), 1.0)),
    _ExportJoint("cervical", "neck", ("", _axis(2), 0.0)),
    _ExportJoint("head", "cervical", ("neck", _axis(2), 1.0), end_site=("head", _axis(2), 1.0)),
    *[j for s in "lr" for j in (
        _ExportJoint(f"clavicle_{s}", "neck", ("", _axis(1), 0.0)),
        _ExportJoint(f"shoulder_{s}", f"clavicle_{s}", (f"clavicle_{s}", _axis(1, _side(s)), 1.0)),
        _ExportJoint(f"elbow_{s}", f"shoulder_{s}", (f"upper_arm_{s}", _axis(1, _side(s)), 1.0)),
        _ExportJoint(f"wrist_{s}", f"elbow_{s}", (f"forearm_{s}", _axis(1, _side(s)), 1.0),
                     end_site=(f"hand_{s}", _axis(1, _side(s)), 1.0)),
    )],
)
EXPORT_NAMES = tuple(j.name for j in EXPORT_JOINTS)


def _offset(spec: tuple[str, Vec3, float], morph: Morphology) -> F64:
    name, direction, scale = spec
    return np.array(direction) * (scale * morph[name] if name else 0.0)


def _swing_from(parent_frame: F64, rest_axis: F64, direction: F64) -> F64:
    """The parent's frame turned by the smallest rotation taking its ``rest_axis`` onto
    ``direction``: a bone's orientation with no twist of its own. (..., 3, 3)."""
    current = np.einsum("...ij,...j->...i", parent_frame, rest_axis)
    return rotation_between(current, direction) @ parent_frame


_SIDE_SIGN = np.array([[1.0], [-1.0]])  # (2, 1): left, right
_REST_HIPS = np.array([_rest_hip("l"), _rest_hip("r")])  # (2, 3)
_E = {n: i for i, n in enumerate(EXPORT_NAMES)}


def _sided(name: str) -> list[int]:
    return [_E[f"{name}_l"], _E[f"{name}_r"]]


def export_rotations(pose: DecodedPose) -> F64:
    """World orientation of every export joint, mapping its rest (body-axes) offsets onto the
    posed bones; both sides of each limb are done in one batched call.

    Returns (*B, len(EXPORT_NAMES), 3, 3) joint2world, in :data:`EXPORT_NAMES` order.
    """
    p = pose.positions
    e = np.eye(3)
    out = np.empty(p.shape[:-2] + (len(EXPORT_NAMES), 3, 3))

    def both(*names: str) -> F64:
        return p[..., [J[f"{n}_{s}"] for n in names for s in "lr"], :].reshape(
            p.shape[:-2] + (len(names), 2, 3))

    hip, knee, ankle, toe = np.moveaxis(both("hip", "knee", "ankle", "toe"), -3, 0)
    sh, el, wr, hd = np.moveaxis(both("shoulder", "elbow", "wrist", "hand"), -3, 0)
    pelvis2world = pose.pelvis2world[..., None, :, :]
    thorax2world = pose.thorax2world[..., None, :, :]
    leg_normal = pose.leg2world[..., :, :, 0]  # half-plane normal = knee hinge axis, (*B, 2, 3)
    arm_normal = pose.arm2world[..., :, :, 0]  # elbow hinge axis
    side_y = np.broadcast_to(pose.pelvis2world[..., None, :, 1], leg_normal.shape)
    side_x = np.broadcast_to(pose.thorax2world[..., None, :, 0], arm_normal.shape)
    out[..., _E["pelvis"], :, :] = pose.pelvis2world
    out[..., _sided("pelvis"), :, :] = _swing_from(pelvis2world, _REST_HIPS,
                                                   hip - p[..., None, J["pelvis"], :])
    out[..., _sided("hip"), :, :] = frame_from_axes(hip - knee, leg_normal, 2, 1)
    out[..., _sided("knee"), :, :] = frame_from_axes(knee - ankle, leg_normal, 2, 1)
    foot = frame_from_axes(toe - ankle, leg_normal, 0, 1, fallback_secondary=side_y)
    out[..., _sided("ankle"), :, :] = foot
    out[..., _sided("toe"), :, :] = foot
    out[..., _sided("clavicle"), :, :] = _swing_from(thorax2world, _SIDE_SIGN * e[1],
                                                     sh - p[..., None, J["neck"], :])
    out[..., _sided("shoulder"), :, :] = frame_from_axes(_SIDE_SIGN * (el - sh),
                                                         -_SIDE_SIGN * arm_normal, 1, 2)
    out[..., _sided("elbow"), :, :] = frame_from_axes(_SIDE_SIGN * (wr - el),
                                                      -_SIDE_SIGN * arm_normal, 1, 2)
    out[..., _sided("wrist"), :, :] = frame_from_axes(_SIDE_SIGN * (hd - wr),
                                                      -_SIDE_SIGN * arm_normal, 1, 2,
                                                      fallback_secondary=side_x)
    lumbar = _swing_from(pose.pelvis2world, e[2], p[..., J["spine_1"], :] - p[..., J["pelvis"], :])
    spine_1 = _swing_from(lumbar, e[2], p[..., J["spine_2"], :] - p[..., J["spine_1"], :])
    out[..., _E["lumbar"], :, :] = lumbar
    out[..., _E["spine_1"], :, :] = spine_1
    out[..., _E["spine_2"], :, :] = _swing_from(spine_1, e[2],
                                                p[..., J["neck"], :] - p[..., J["spine_2"], :])
    out[..., _E["neck"], :, :] = pose.thorax2world
    out[..., _E["cervical"], :, :] = _swing_from(pose.thorax2world, e[2],
                                                 p[..., J["head"], :] - p[..., J["neck"], :])
    out[..., _E["head"], :, :] = _swing_from(pose.head2world, e[2],
                                             p[..., J["head_top"], :] - p[..., J["head"], :])
    return out


EXPORT_PARENTS = np.array([-1 if j.parent is None else EXPORT_NAMES.index(j.parent)
                           for j in EXPORT_JOINTS])


def local_rotations(pose: DecodedPose) -> F64:
    """Local rotation of every export joint relative to its parent, in BVH axes (Y up), as in
    the exported file's channels. Returns (*B, len(EXPORT_NAMES), 3, 3)."""
    world = export_rotations(pose)  # (*B, E, 3, 3) joint2world
    # joint2bvh = world_to_bvh @ joint2world @ bvh_rest2body, for all joints in one product.
    glob = YUP_TO_ZUP.T @ world @ BODY_TO_BVH_REST.T
    parent = glob[..., np.maximum(EXPORT_PARENTS, 0), :, :]
    local: F64 = np.swapaxes(parent, -1, -2) @ glob
    local[..., EXPORT_PARENTS < 0, :, :] = glob[..., EXPORT_PARENTS < 0, :, :]
    return local


def body_frames(local: F64) -> tuple[F64, F64]:
    """The pelvis and thorax frames of export-skeleton local rotations (as
    :func:`local_rotations` gives them): its inverse for those two joints.

    ``local`` (*B, len(EXPORT_NAMES), 3, 3) BVH axes -> ``pelvis2world``, ``thorax2world``
    (*B, 3, 3) in our world axes."""
    joint2bvh = local[..., _E["pelvis"], :, :]
    pelvis2world: F64 = YUP_TO_ZUP @ joint2bvh @ BODY_TO_BVH_REST
    for name in ("lumbar", "spine_1", "spine_2", "neck"):  # the chain from the pelvis to the neck
        joint2bvh = joint2bvh @ local[..., _E[name], :, :]
    thorax2world: F64 = YUP_TO_ZUP @ joint2bvh @ BODY_TO_BVH_REST
    return pelvis2world, thorax2world


def rest_offsets(morph: Morphology) -> tuple[F64, F64]:
    """The export skeleton's rest pose (a T-pose) on ``morph``, in BVH axes, metres: each
    joint's offset from its parent (the root's is zero) and its end site's offset from it (zero
    where it has none). Returns two (len(EXPORT_NAMES), 3) arrays; the BVH and glTF writers
    share them."""
    joint_offsets = np.array([BODY_TO_BVH_REST @ _offset(j.rest_offset, morph)
                              for j in EXPORT_JOINTS])
    end_offsets = np.array([np.zeros(3) if j.end_site is None
                            else BODY_TO_BVH_REST @ _offset(j.end_site, morph)
                            for j in EXPORT_JOINTS])
    return joint_offsets, end_offsets


def _offset_tables() -> tuple[NDArray[np.int64], F64, NDArray[np.int64], F64]:
    """Per export joint: the index in LENGTHS of the length setting its offset and of the one
    setting its end site's (0 where none), and the offset per metre of it in BVH axes (zero
    where none): (E,), (E, 3), (E,), (E, 3)."""
    def table(specs: list[tuple[str, Vec3, float] | None]) -> tuple[NDArray[np.int64], F64]:
        index = np.array([LENGTH_INDEX[s[0]] if s is not None and s[0] else 0 for s in specs])
        per_metre = np.array([np.zeros(3) if s is None or not s[0]
                              else BODY_TO_BVH_REST @ (np.array(s[1]) * s[2]) for s in specs])
        return index, per_metre

    joints = table([j.rest_offset for j in EXPORT_JOINTS])
    ends = table([j.end_site for j in EXPORT_JOINTS])
    return joints[0], joints[1], ends[0], ends[1]


_JOINT_LENGTH, _JOINT_PER_METRE, _END_LENGTH, _END_PER_METRE = _offset_tables()


def rest_offsets_of(lengths: F64) -> tuple[F64, F64]:
    """:func:`rest_offsets` for many bodies at once: ``lengths`` (..., N_LENGTHS) metres (e.g.
    each frame's body, ``store.lengths`` recorded per tick) -> each export joint's offset from
    its parent and its end site's offset from it, (..., len(EXPORT_NAMES), 3) each, BVH axes."""
    joint_offsets: F64 = lengths[..., _JOINT_LENGTH, None] * _JOINT_PER_METRE
    end_offsets: F64 = lengths[..., _END_LENGTH, None] * _END_PER_METRE
    return joint_offsets, end_offsets


def changing_offsets(morph: Morphology, lengths: F64 | None
                     ) -> tuple[F64, F64, NDArray[np.bool_], NDArray[np.bool_]] | None:
    """The export skeleton's offsets on each frame's body, ``lengths`` (frames, N_LENGTHS), and
    which of them differ from ``morph``'s on some frame: (frames, E, 3) joint and end-site
    offsets in BVH axes, (E,) bool each. None when no offset differs (or ``lengths`` is None):
    the body never changed from ``morph``."""
    if lengths is None:
        return None
    frame_joints, frame_ends = rest_offsets_of(np.asarray(lengths, dtype=np.float64))
    rest_joints, rest_ends = rest_offsets_of(morph.lengths)
    joint_moves = np.any(frame_joints != rest_joints, axis=(0, 2))
    end_moves = np.any(frame_ends != rest_ends, axis=(0, 2))
    if not (joint_moves.any() or end_moves.any()):
        return None
    return frame_joints, frame_ends, joint_moves, end_moves

